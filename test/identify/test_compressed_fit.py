"""The lean least-squares fit: Levenberg-Marquardt runs on the R of [J | r]
(`identify.fit._Problem` with `compressed`), folded block by block, instead of the (3n, p)
rows. Both present MINPACK the same J^T J, J^T r and |r| at every x, so the fit takes the
same steps: known answers are that the invariants agree at any x (weights, 6-DoF
orientation rows and the weak prior included, over several blocks) and that whole fits
end at the same parameters, 1-sigma and identifiability figures as the row-by-row path."""

from __future__ import annotations

import numpy as np
import pytest
from six_dof_world import WORLD as SIX_DOF_WORLD
from six_dof_world import as_recording, measured

from robot_calib.identify import fit
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.objectives import AbsoluteObjective
from robot_calib.model import KinematicModel
from robot_calib.sim.scenarios import ur10_random


def problems(monkeypatch: pytest.MonkeyPatch) -> tuple[fit._Problem, fit._Problem, np.ndarray]:
    """A 6-DoF probe's problem (points and orientation rows, all parameters free), compressed
    and as rows, in blocks of 40 poses, and a start 1e-4 away from the nominal values."""
    monkeypatch.setattr(fit, "BLOCK_POSES", 40)  # several blocks from 150 poses
    poses, points = measured(n=150)
    recording = as_recording(poses, points)
    model = KinematicModel(
        SIX_DOF_WORLD.model.robot,
        targets=recording.target_names,
        oriented=recording.oriented_targets,
    )
    assert model.oriented
    start = model.parameters()
    args = (model, start, recording.poses, recording.points, AbsoluteObjective())
    x = start.pack() + np.random.default_rng(0).normal(0, 1e-4, int(start.free.sum()))
    return fit._Problem(*args, compressed=True), fit._Problem(*args), x


def test_the_compressed_rows_have_the_rows_normal_equations(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    compressed, rows, x = problems(monkeypatch)
    assert len(rows.rows6) > 0 and len(rows.prior_cols) > 0  # orientation and prior rows
    f, jac = compressed.evaluate(x)
    r, full = rows.evaluate(x)
    assert jac.shape == (jac.shape[1] + 1, jac.shape[1]) and len(r) > 10 * len(f)
    scale = np.linalg.norm(full, axis=0)
    np.testing.assert_allclose(f @ f, r @ r, rtol=1e-10)
    np.testing.assert_allclose((jac.T @ f) / scale, (full.T @ r) / scale, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(
        (jac.T @ jac) / np.outer(scale, scale),
        (full.T @ full) / np.outer(scale, scale),
        atol=1e-10,
    )
    # the data's rows alone (the prior's left out) as the identifiability analysis sees them
    rc, jc, mc = compressed.data_rows(x)
    rr, jr, mr = rows.data_rows(x)
    assert mc == mr == len(rr)
    np.testing.assert_allclose(rc @ rc, rr @ rr, rtol=1e-10)
    np.testing.assert_allclose(compressed.data_rms(x), rows.data_rms(x), rtol=1e-12)
    np.testing.assert_allclose(compressed.predicted, rows.predicted, rtol=0, atol=1e-15)


class _Rows(fit._Problem):
    """The row-by-row problem whatever fit_model asks for (the reference path)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs["compressed"] = False
        super().__init__(*args[:7], **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "model", ["geometric", "geometric+transmission_error:2:order=4", "geometric+compliance:2,3"]
)
def test_a_compressed_fit_ends_where_the_rows_fit_ends(
    monkeypatch: pytest.MonkeyPatch, model: str
) -> None:
    scenario = ur10_random(seed=2, n=600)
    robot = scenario.world.model.robot
    lean = calibrate(scenario.calibration, robot, model)
    monkeypatch.setattr(fit, "_Problem", _Rows)
    reference = calibrate(scenario.calibration, robot, model)
    assert lean.parameters.free_names == reference.parameters.free_names
    free = lean.parameters.free
    scale = np.maximum(np.abs(reference.parameters.values), 1e-3)
    assert np.max(np.abs(lean.parameters.values - reference.parameters.values) / scale) < 1e-7
    np.testing.assert_allclose(lean.std[free], reference.std[free], rtol=1e-6)
    np.testing.assert_allclose(lean.residuals, reference.residuals, rtol=0, atol=1e-10)
    np.testing.assert_allclose(
        lean.identifiability.condition_number,
        reference.identifiability.condition_number,
        rtol=1e-6,
    )
