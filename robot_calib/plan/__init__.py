"""Capture planning: which poses to measure, before anything is measured.

- `plan_file`: the PLAN.yaml format (msgs_doc/plan.md): its writer and its one loader, which
  `simulate --plan`, `run --plan` and the capture node read (light: numpy and yaml only);
- `design`: candidate poses within the joint limits and above a floor, and the D-optimal
  choice of N of them for a model (greedy + exchange on log det J^T J, rank-3 updates);
- `evaluate`: what a plan promises: predicted 1-sigma of every free parameter, and the
  held-out error of calibrations simulated on random true robots;
- `campaign`: the `robot-calib plan` verb's flow (design, evaluate, compare with random
  poses at equal N).

Data flow: plan -> sim -> bag -> identify; `plan_file` imports nothing of the simulator.
"""
