%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE pick_place
    !***********************************************************
    ! Pick and place on the fixture; taught 2026-11-30
    !***********************************************************
    PERS tooldata gripper:=[TRUE,[[0,0,200],[1,0,0,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
    TASK PERS wobjdata fixture:=[FALSE,TRUE,"",[[800,-300,200],[0.98480775,0,0,0.17364818]],[[0,0,0],[1,0,0,0]]];
    CONST jointtarget home:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget pApproach:=[[521.46,368.44,324.93],[0.09195457,0.02501905,0.99524654,0.02006805],[0,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget pPick:=[[438.00,3.85,300.66],[0.04020574,0.33760024,0.93740849,-0.07533186],[-1,-1,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget pVia:=[[386.27,256.97,338.76],[0.00315925,0.20782191,0.97769963,0.03005828],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget pPlace:=[[445.59,607.68,367.12],[0.15180159,-0.17765772,0.97003485,0.06653125],[0,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

    PROC main()
        MoveAbsJ home\NoEOffs, v1000, fine, gripper;
        MoveJ pApproach, v1000, z50, gripper\WObj:=fixture;
        MoveL pPick, v200, fine, gripper\WObj:=fixture; ! grip here
        MoveL Offs(pPick,0,0,50), v200, z10, gripper\WObj:=fixture;
        MoveC pVia, pPlace, v200, fine, gripper\WObj:=fixture;
        MoveAbsJ home\NoEOffs, v1000, fine, gripper;
    ENDPROC
ENDMODULE
