"""robot_calib: laser-tracker calibration of 6-axis robots and sim-to-real gap diagnosis.

Flow (one package per step): sim -> bag -> identify (CPA, geometric, effects) -> diagnose.
The core imports numpy/scipy only; ROS lives in `robot_calib.nodes`.
"""

import os

# The linear algebra here is many small solves (thousands of rows, tens of columns): one
# BLAS thread is fastest, and threaded OpenBLAS next to another busy process slows them down
# 50-fold (measured: a diagnosis 1.1 s vs 59 s on 2 cores). Effective when robot_calib is
# imported before numpy (the console scripts, the nodes); set it yourself to override.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
