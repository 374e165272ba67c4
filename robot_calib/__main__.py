"""`python -m robot_calib` = the `robot-calib` console script."""

import sys

from robot_calib.cli import main

sys.exit(main())
