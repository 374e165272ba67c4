"""`python -m robot_calib` = the `robot-calib` console script."""

from robot_calib.cli import run

run()
