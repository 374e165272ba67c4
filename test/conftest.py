"""Test-process set-up: a private ROS_DOMAIN_ID (claimed with a file lock) and ROS_LOG_DIR.

Two processes on one DDS domain see each other's topics, so every pytest process (and
every xdist worker) claims a free domain before anything imports rclpy.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

from robot_calib import one_blas_thread
from robot_calib.nodes.private_domain import claim

one_blas_thread()  # as the programs start (robot-calib, the nodes): before numpy loads

_held_lock = None


def _claim_domain() -> int:
    global _held_lock
    domain, _held_lock = claim()  # released by the OS when this process exits
    return domain


def pytest_configure(config) -> None:  # noqa: ANN001 - pytest hook signature
    os.environ["ROS_DOMAIN_ID"] = str(_claim_domain())
    log_dir = Path(tempfile.mkdtemp(prefix="robot_calib_roslog_"))
    os.environ["ROS_LOG_DIR"] = str(log_dir)


@pytest.fixture
def context():  # noqa: ANN201 - rclpy is imported lazily, after the domain is claimed
    """A private rclpy context, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


# The test files that take longest, longest first (summed test times of a full run on the
# 2-core machine, 2026-12-07, slow cases left out): xdist (--dist loadfile
# --no-loadscope-reorder, pyproject) hands each worker the next file in this order as it
# frees up, so the long files start first and the two workers end together. The other
# files follow in their usual order.
SLOW_FIRST = (
    "test_diagnose.py",
    "test_faulty_inputs.py",
    "test_stated_accuracy_and_cpa_sigma.py",
    "test_compensate.py",
    "test_effects_outside_vocabulary.py",
    "test_html_report.py",
    "test_import_layers.py",
    "test_implausible_inputs.py",
    "test_capture.py",
    "test_joint_harmonics.py",
    "test_calibrator.py",
    "test_divergence.py",
    "test_plausibility.py",
    "test_targets.py",
    "test_correction.py",
    "test_forked.py",
    "test_files_and_faults.py",
    "test_outside_vocabulary.py",
    "test_urdf.py",
    "test_cli.py",
    "test_numeric_inputs.py",
    "test_outliers.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: k for k, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: files stay whole
