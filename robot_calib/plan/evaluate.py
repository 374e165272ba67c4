"""What a capture plan promises: the predicted 1-sigma of every free parameter, and the
held-out error of calibrations simulated on random true robots.

- Predicted 1-sigma: sigma^2 (J^T J)^-1 at the design's linearisation point, J the points'
  Jacobian of the plan's poses visited in order (approach directions and times included),
  sigma the tracker noise per coordinate. Default sigma: the world's, as the simulator
  draws it: the tracker and target noise (`sim.measure.stated_accuracy`) plus the robot's
  repeatability (joint_sigma_rad) carried to the target by the joints' lever arms, their
  mean square over the candidates (an isotropic equivalent of pose-dependent noise).
- Expected held-out error: per trial, a random true robot (the world's geometry, random
  geometric deviations of DEVIATION_SIGMA, the model's effects at their simulator default
  magnitudes) measured at the plan's poses (`sim.measure.record_plan`, the world's noise),
  calibrated with the model (`identify.calibrate`, as `robot-calib calibrate` does) and
  scored on random poses above the floor measured on the same robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.export.base import labelled_size
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.identifiability import unit_covariance
from robot_calib.kinematics.frames import Array
from robot_calib.plan.design import DesignProblem, draw_candidates
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points, record_plan, stated_accuracy
from robot_calib.sim.plans import Plan
from robot_calib.sim.world import World, with_effect

#: 1-sigma of the random geometric deviations of a simulated true robot, by unit: 0.1 mm
#: for a length, 0.01 deg for an angle (the size of the seed's Table 3 deviations)
DEVIATION_SIGMA = {"m": 1e-4, "rad": math.radians(0.01)}


@dataclass(frozen=True)
class Prediction:
    """Predicted 1-sigma of a plan's calibration.

    names, units : (p,) the free parameters and their SI units.
    std : shape (p,), predicted 1-sigma of each [its unit].
    rms_m : shape (p,), the rms point error over the candidates that a 1-sigma error of
        each causes [m]: comparable across units, the basis of `worst`.
    noise_m : the tracker noise per coordinate assumed [m].
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    std: Array
    rms_m: Array
    noise_m: float

    @property
    def worst(self) -> int:
        """Index of the parameter whose 1-sigma moves the points most (`rms_m`)."""
        return int(np.argmax(self.rms_m))

    def worst_of_unit(self, unit: str) -> int | None:
        """Index of the largest 1-sigma among the parameters in `unit` (None: none)."""
        rows = [k for k, u in enumerate(self.units) if u == unit]
        return max(rows, key=lambda k: self.std[k]) if rows else None

    def line(self, k: int) -> str:
        """'theta2 0.91 urad (0.52 um rms over the workspace)' for parameter k."""
        return (
            f"{self.names[k]} {human(float(self.std[k]), self.units[k])} "
            f"({self.rms_m[k] * 1e3:.5f} mm rms over the workspace)"
        )


def human(value: float, unit: str) -> str:
    """A 1-sigma in SI `unit` labelled for people: mm, urad (with deg), other units as is."""
    text = labelled_size(unit, value, mm_digits=5, urad_digits=2)
    return f"{text} ({math.degrees(value):.6f} deg)" if unit == "rad" else text


def world_noise_m(world: World, problem: DesignProblem) -> float:
    """Isotropic equivalent of the world's measurement noise per coordinate [m] over the
    problem's candidates: tracker and target noise plus joint repeatability x lever arm."""
    model, params, q = problem.model, problem.params, problem.candidates
    points, jac = model.jacobian(params, Poses.from_readings(q))
    tracker = stated_accuracy(world.noise, points)[:, 0]
    n_joints = model.robot.n_joints
    theta = jac[:, :, [params.index(f"theta{j}") for j in range(1, n_joints + 1)]]
    mapping = model.robot.reading_matrix
    per_reading = theta if mapping is None else theta @ mapping  # d point / d reading
    joint = world.noise.joint_sigma_rad**2 * np.sum(per_reading**2, axis=(1, 2)) / 3.0
    return float(np.sqrt(np.mean(tracker**2 + joint)))


def predict(problem: DesignProblem, plan: Plan, noise_m: float) -> Prediction:
    """Predicted 1-sigma of every free parameter of `problem` calibrated from `plan`'s
    poses (visited in order) with `noise_m` [m] per coordinate."""
    jac = problem.jacobian(plan)
    p = jac.shape[2]
    std = noise_m * np.sqrt(np.maximum(np.diag(unit_covariance(jac.reshape(-1, p))), 0.0))
    free = [par for par in problem.params.parameters if par.free]
    return Prediction(
        tuple(par.name for par in free),
        tuple(par.unit for par in free),
        std,
        std * problem.scale,
        noise_m,
    )


@dataclass(frozen=True)
class HoldoutScore:
    """Held-out error of simulated calibrations, averaged over `trials` random true robots:
    abs_rms_mm the rms distance of measured and predicted points [mm], pairwise_mean_mm the
    seed's criterion mean [mm], on `n_poses` random poses each; model_rms_mm the rms distance
    of the predicted points from the true (noise-free) ones [mm]: the model's own error,
    which the plan governs (the measured figures add the held-out points' noise)."""

    abs_rms_mm: float
    pairwise_mean_mm: float
    model_rms_mm: float
    trials: int
    n_poses: int


def random_true_world(world: World, problem: DesignProblem, rng: np.random.Generator) -> World:
    """`world` with the problem's model effects switched on (simulator default magnitudes)
    and random deviations (DEVIATION_SIGMA) of every free geometric parameter."""
    for effect in problem.model.effects:
        if effect not in world.model.effects:
            world = with_effect(world, effect)
    structural = problem.model.parameters()
    deviations = {
        p.name: world.truth[p.name] + rng.normal(0.0, DEVIATION_SIGMA[p.unit])
        for p in structural.parameters
        if p.free and p.group == "geometric" and p.unit in DEVIATION_SIGMA
    }
    return replace(world, truth=world.truth.with_values(deviations))


def simulated_holdout(
    world: World,
    problem: DesignProblem,
    model_spec: str,
    plan: Plan,
    rng: np.random.Generator,
    trials: int = 1,
    n_holdout: int = 200,
    floor_z_m: float = 0.0,
    ecc_order: int = 1,
) -> HoldoutScore:
    """Calibrate `model_spec` from `plan` on `trials` random true robots and score each on
    `n_holdout` random poses above `floor_z_m` (see the module's docstring)."""
    rms, pairwise, model = [], [], []
    for _ in range(trials):
        truth = random_true_world(world, problem, rng)
        holdout_q = draw_candidates(problem.model, problem.params, n_holdout, rng, floor_z_m)
        recording = record_plan(truth, plan, rng)
        held = record_plan(truth, problem.plan(holdout_q, "holdout"), rng)
        cal = calibrate(recording, problem.model.robot, model_spec, ecc_order)
        predicted = cal.predict(held.poses)
        score = accuracy(held.points, predicted)
        exact = physical_points(truth, held.poses, rng, noisy=False)
        rms.append(score.absolute_rms_mm)
        pairwise.append(score.pairwise_mean_mm)
        model.append(accuracy(exact, predicted).absolute_rms_mm)
    return HoldoutScore(
        float(np.mean(rms)), float(np.mean(pairwise)), float(np.mean(model)), trials, n_holdout
    )
