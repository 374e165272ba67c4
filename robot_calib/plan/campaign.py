"""The `robot-calib plan` flow: design a D-optimal plan for a model, evaluate it (predicted
1-sigma, simulated held-out error) and the same figures for random poses at equal N, and
the PLAN.yaml document of the result."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from robot_calib.errors import InputError, param
from robot_calib.identify import DEFAULT_ECC_ORDER
from robot_calib.identify.calibrate import parse_model
from robot_calib.log import Log
from robot_calib.model import KinematicModel

if TYPE_CHECKING:
    from robot_calib.effects.base import Effect
    from robot_calib.kinematics.description import RobotDescription
from robot_calib.plan.design import (
    DEFAULT_CANDIDATES,
    DEFAULT_FLOOR_Z_M,
    DesignProblem,
    d_optimal,
    design_problem,
)
from robot_calib.plan.evaluate import (
    DEVIATION_SIGMA,
    HoldoutScore,
    Prediction,
    predict,
    simulated_holdout,
    world_noise_m,
)
from robot_calib.plan.plan_file import plan_text
from robot_calib.sim.plans import Plan, plan_times
from robot_calib.sim.world import World

DEFAULT_TRIALS = 1
DEFAULT_HOLDOUT = 200


@dataclass(frozen=True)
class PlanFigures:
    """One plan and what it promises: `prediction` (1-sigma of every free parameter),
    `holdout` (simulated held-out error; None when not simulated), `hours` the campaign's
    robot time (moves, settling, measuring) [h]."""

    plan: Plan
    prediction: Prediction
    holdout: HoldoutScore | None
    hours: float


@dataclass(frozen=True)
class Campaign:
    """A planned campaign: the model, the design problem, the D-optimal plan and random
    poses at equal N (each with its figures), the seed and the time the design took [s]."""

    model: str
    problem: DesignProblem
    planned: PlanFigures
    random: PlanFigures
    seed: int
    design_seconds: float


def plan_effects(
    model_spec: str, robot: RobotDescription, ecc_order: int = DEFAULT_ECC_ORDER
) -> tuple[Effect, ...]:
    """The effects of `model_spec` when it is a model a plan is made for (geometric plus
    effects); InputError naming `model` otherwise."""
    base, effects = parse_model(model_spec, robot, ecc_order)
    if base != "geometric":
        raise InputError(
            f"{param('model', model_spec)}: plans are made for geometric[+EFFECT...] models (cpa "
            "needs circle sweeps: the paper-test plans; nominal fits only the frames)"
        )
    return tuple(effects)


def planning_problem(
    world: World,
    model_spec: str,
    n_candidates: int = DEFAULT_CANDIDATES,
    rng: np.random.Generator | None = None,
    floor_z_m: float = DEFAULT_FLOOR_Z_M,
    ecc_order: int = DEFAULT_ECC_ORDER,
) -> DesignProblem:
    """The design problem of `model_spec` (a geometric model of the ladder) on `world`'s
    robot with its tracker pose and target offset; InputError for other models."""
    robot = world.model.robot
    model = KinematicModel(robot, plan_effects(model_spec, robot, ecc_order))
    generator = rng if rng is not None else np.random.default_rng(0)
    return design_problem(model, world.truth, n_candidates, generator, world.timing, floor_z_m)


def plan_figures(
    world: World,
    problem: DesignProblem,
    model_spec: str,
    plan: Plan,
    noise_m: float,
    rng: np.random.Generator,
    trials: int = DEFAULT_TRIALS,
    n_holdout: int = DEFAULT_HOLDOUT,
    floor_z_m: float = DEFAULT_FLOOR_Z_M,
    ecc_order: int = DEFAULT_ECC_ORDER,
) -> PlanFigures:
    """The figures of `plan`: predicted 1-sigma with `noise_m` [m], and the held-out error
    of `trials` simulated calibrations (none when trials is 0)."""
    holdout = None
    if trials:
        holdout = simulated_holdout(
            world, problem, model_spec, plan, rng, trials, n_holdout, floor_z_m, ecc_order
        )
    hours = float(plan_times(plan, world.timing)[-1]) / 3600.0
    return PlanFigures(plan, predict(problem, plan, noise_m), holdout, hours)


def plan_campaign(
    world: World,
    model_spec: str,
    n_poses: int,
    n_candidates: int = DEFAULT_CANDIDATES,
    seed: int = 0,
    floor_z_m: float = DEFAULT_FLOOR_Z_M,
    noise_m: float | None = None,
    ecc_order: int = DEFAULT_ECC_ORDER,
    trials: int = DEFAULT_TRIALS,
    n_holdout: int = DEFAULT_HOLDOUT,
    progress: Log | None = None,
) -> Campaign:
    """Plan `n_poses` of `n_candidates` for `model_spec` in `world` and evaluate the plan
    and `n_poses` random candidates (the first drawn) the same way; `noise_m` [m] per
    coordinate (None: the world's, `evaluate.world_noise_m`)."""
    say = progress or (lambda _m: None)
    rng = np.random.default_rng(seed)
    started = time.perf_counter()
    plan_effects(model_spec, world.model.robot, ecc_order)  # a bad model: before any work
    say(f"plan: {n_candidates} candidate poses, identifiability of {model_spec}")
    problem = planning_problem(world, model_spec, n_candidates, rng, floor_z_m, ecc_order)
    say(f"plan: D-optimal choice of {n_poses} poses ({len(problem.scale)} free parameters)")
    q = d_optimal(problem, n_poses, say)
    seconds = time.perf_counter() - started
    noise = world_noise_m(world, problem) if noise_m is None else noise_m
    out = []
    for name, rows in (("planned", q), ("random", problem.candidates[:n_poses])):
        say(f"plan: {name} poses: predicted 1-sigma, {trials} simulated calibration(s)")
        out.append(
            plan_figures(
                world,
                problem,
                model_spec,
                problem.plan(rows, name),
                noise,
                rng,
                trials,
                n_holdout,
                floor_z_m,
                ecc_order,
            )
        )
    return Campaign(model_spec, problem, out[0], out[1], seed, seconds)


def _prediction_dict(figures: PlanFigures) -> dict[str, Any]:
    pred = figures.prediction
    worst = pred.worst
    doc: dict[str, Any] = {
        "noise_m": pred.noise_m,
        "worst": {
            "name": pred.names[worst],
            "unit": pred.units[worst],
            "std": float(pred.std[worst]),
            "rms_m": float(pred.rms_m[worst]),
        },
        "parameters": [
            {"name": n, "unit": u, "std": float(s), "rms_m": float(r)}
            for n, u, s, r in zip(pred.names, pred.units, pred.std, pred.rms_m)
        ],
        "campaign_hours": round(figures.hours, 4),
    }
    if figures.holdout is not None:
        doc["holdout"] = {
            "abs_rms_mm": figures.holdout.abs_rms_mm,
            "pairwise_mean_mm": figures.holdout.pairwise_mean_mm,
            "model_rms_mm": figures.holdout.model_rms_mm,
            "trials": figures.holdout.trials,
            "poses": figures.holdout.n_poses,
        }
    return doc


def campaign_yaml(campaign: Campaign, floor_z_m: float) -> str:
    """The PLAN.yaml text of `campaign` (msgs_doc/plan.md)."""
    problem = campaign.problem
    design = {
        "criterion": "D-optimal (greedy + exchange on log det J^T J), then an exchange for "
        "the worst scaled 1-sigma",
        "visiting_order": "greedy order (approach directions scored)"
        if problem.sequential
        else "nearest-neighbour tour in move time",
        "candidates": len(problem.candidates),
        "floor_z_m": floor_z_m,
        "seed": campaign.seed,
        "fixed": [{"name": n, "reason": r} for n, r in problem.fixed],
        "simulated_deviation_sigma": dict(DEVIATION_SIGMA),
    }
    predicted = _prediction_dict(campaign.planned)
    predicted["random_same_n"] = {
        k: v for k, v in _prediction_dict(campaign.random).items() if k != "parameters"
    }
    return plan_text(
        problem.model.robot,
        campaign.model,
        campaign.planned.plan.q,
        problem.speed_fraction,
        design,
        predicted,
    )
