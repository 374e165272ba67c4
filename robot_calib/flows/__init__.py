"""The flows of the verbs as typed functions, one module per flow: what `robot-calib VERB`
does once its arguments are parsed, also called by the nodes, the scripts and the tests.

- `simulate`: a world (`simulation_world`), a simulated bag and its world file
  (`simulate`, `simulate_stream`); `plan` uses its world too.
- `bags`: the paired measurements of bags (`read_bags`), each bag and measurement once.
- `calibrate`: a model identified from a recording or bags (`calibrate_recording`,
  `calibrate_bags`, `calibrate_stream_bag`).
- `diagnose`: the sim-to-real gap diagnosis of bags (`diagnose_bags`) and its files
  (`write_diagnosis`: DIAGNOSIS.json, the Markdown and HTML reports, the best model).
- `run`: the main job (simulate -> calibrate -> score -> diagnose) on built-in defaults.

The overwrite policy of every output (`output_path`) lives in `robot_calib.atomic`. The
command line (`robot_calib.cli`, one module per verb) parses, calls these, prints; nothing
here imports it. Heavy modules (scipy, mcap, rclpy) are imported inside the function that
needs them, so a caller pays only for what it runs.

The defaults every flow and caller shares (the CLI, the nodes) are written once, here, in
the package's light `__init__` (importing it loads nothing else).
"""

from collections.abc import Callable

Progress = Callable[[str, int, int], None]  # (plan, poses done, poses in all)

DEFAULT_ROBOT = "kr5_sixx_r650"  # the seed's robot
RUN_PLAN = "paper-test2"  # the main job's calibration plan (seed Test 2)
DEFAULT_PLAN = RUN_PLAN  # `simulate` without --plan: the same as the main job
RUN_HOLDOUT_POSES = 200
RUN_MODELS = ("nominal", "cpa", "geometric")
N_RANDOM_POSES = 200  # poses of the `random` plan
