/PROG  PICK_PLACE
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "pick and place";
PROG_SIZE	= 1024;
CREATE		= DATE 26-11-30  TIME 10:12:00;
MODIFIED	= DATE 26-11-30  TIME 10:20:00;
FILE_NAME	= ;
VERSION		= 0;
LINE_COUNT	= 9;
MEMORY_SIZE	= 1400;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/MN
   1:  UFRAME_NUM=1 ;
   2:  UTOOL_NUM=1 ;
   3:  !approach ;
   4:J P[1:"approach"] 100% FINE    ;
   5:L P[2] 500mm/sec CNT50    ;
   6:C P[3]    
    :  P[4] 200mm/sec FINE    ;
   7:J PR[1] 50% FINE    ;
   8:J P[5] 100% FINE    ;
/POS
P[1:"approach"]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   583.530  mm,	Y =   315.177  mm,	Z =   398.270  mm,
	W =   168.120 deg,	P =   -16.875 deg,	R =    13.506 deg
};
P[2]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   476.688  mm,	Y =   -66.107  mm,	Z =   450.646  mm,
	W =  -172.294 deg,	P =   -13.800 deg,	R =   -42.026 deg
};
P[3]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   538.275  mm,	Y =   123.337  mm,	Z =   417.203  mm,
	W =   178.474 deg,	P =   -16.933 deg,	R =   -14.773 deg
};
P[4]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   517.430  mm,	Y =   228.588  mm,	Z =   365.219  mm,
	W =   173.626 deg,	P =   -14.972 deg,	R =    -1.125 deg
};
P[5]{
   GP1:
	UF : 1, UT : 1,	
	J1=     0.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=   -90.000 deg,	J6=     0.000 deg
};
/END
