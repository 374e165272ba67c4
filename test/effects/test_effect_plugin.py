"""A new effect is one new module: a module file dropped into the effects package is
discovered and registered; `CosineOffset` below exists only in the test suite, yet once
registered the simulator, the world files, the model names, PARAMS.json, the diagnosis
ladder and the blind harness all know it, and the checks every effect gets
(test_effects.py) pass for it, without any edit outside this file.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from test_effects import (
    check_jacobian,
    check_params_round_trip,
    check_simulator_defaults,
    check_text_and_file_forms,
)

import robot_calib.effects
from robot_calib.effects import EFFECTS, Effect, discover_effects, registered, vocabulary
from robot_calib.effects.base import JointOffsetEffect
from robot_calib.flows.blind import run_case
from robot_calib.identify.calibrate import parse_model
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses
from robot_calib.sim.blind import classes
from robot_calib.sim.world import build_world


class CosineOffset(JointOffsetEffect):
    """theta_j += c_j cos(q_k), k the next joint (joint 1 after the last): a joint-angle
    error that follows another joint's reading (a coupling nobody declared), which no
    effect of the vocabulary (functions of the joint's own reading, or gravity) forms."""

    name = "cosine_offset"
    unit = "rad"
    default_magnitude = 4e-4
    draw_range = (3e-4, 6e-4)
    draw_signed = True

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        return np.cos(np.roll(poses.q, -1, axis=1))


@pytest.fixture
def plugin() -> Iterator[type[Effect]]:
    with registered(CosineOffset) as cls:
        yield cls
    assert CosineOffset.name not in EFFECTS  # gone again for the other tests


def test_the_checks_every_effect_gets_pass_for_a_new_one(
    plugin: type[Effect], tmp_path: Path
) -> None:
    check_jacobian(plugin, 0)
    check_text_and_file_forms(plugin)
    check_params_round_trip(plugin, tmp_path)
    check_simulator_defaults(plugin)


def test_world_files_and_model_names_know_a_new_effect(plugin: type[Effect]) -> None:
    assert plugin.name in vocabulary()
    world = build_world({"effects": [{"name": "cosine_offset", "joints": [2]}]}, "test world")
    assert world.truth["cosine_offset2"] == CosineOffset.default_magnitude
    _, effects = parse_model("geometric+cosine_offset:2,5", world.model.robot)
    assert effects == [CosineOffset(joints=(2, 5))]


def test_the_ladder_and_the_blind_harness_find_a_new_effect(plugin: type[Effect]) -> None:
    """The blind harness draws a case of the new class (registry loop), and the diagnosis,
    told nothing, names it and its joint and reaches the noise floor."""
    assert plugin.name in classes()
    verdict = run_case(plugin.name, 3)
    assert verdict["answer"] == {"effect": "cosine_offset", "joints": verdict["joints"]}
    assert verdict["hit"], verdict


MODULE = """
import numpy as np

from robot_calib.effects.base import JointOffsetEffect, register_effect


@register_effect
class Wobble(JointOffsetEffect):
    name = "wobble"
    unit = "rad"
    default_magnitude = 1e-4
    draw_range = (1e-4, 2e-4)

    def signal(self, robot, poses):
        return np.sin(2.0 * poses.q)
"""


def test_a_module_file_in_the_effects_package_is_discovered(tmp_path: Path) -> None:
    """Drop `wobble.py` into a folder of the package's path: discovery registers it, and
    the model parser and the ladder know it, with no other file touched."""
    (tmp_path / "wobble.py").write_text(MODULE)
    robot_calib.effects.__path__.append(str(tmp_path))
    try:
        assert "wobble" in discover_effects()
        _, effects = parse_model("geometric+wobble:3", build_world({}, "default").model.robot)
        assert [e.spec for e in effects] == ["wobble:3"]
        check_text_and_file_forms(EFFECTS["wobble"])
    finally:
        robot_calib.effects.__path__.remove(str(tmp_path))
        EFFECTS.pop("wobble", None)
        sys.modules.pop("robot_calib.effects.wobble", None)
    assert "wobble" not in discover_effects()
