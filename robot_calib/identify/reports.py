"""The records a calibration carries into its PARAMS.json besides its parameters: how the
solver found them (`SolverReport`, made by `identify.fit`) and the measurements left out
of the fit (`Outlier`, flagged by `identify.outliers`). Plain records, so that reading a
PARAMS.json (`Calibration.load`, `robot-calib predict`) loads no solver.
"""

from __future__ import annotations

from dataclasses import dataclass

from robot_calib.records import Record

ROBOT = "robot"  # Outlier.kind of a pose whose targets are all off together


@dataclass(frozen=True)
class SolverReport(Record):
    """How the parameters were found: the PARAMS.json `solver` section.

    method : the algorithm; objective : what it minimised (None for closed forms such as
    CPA); the rest is scipy `least_squares`'s result (None where no solver ran):
    status : its termination code (> 0 converged, 0 max evaluations, -1 bad input);
    message : its reason in words; success : status > 0; nfev, njev : function and
    Jacobian evaluations it made; optimality : first-order optimality (gradient
    infinity-norm at the solution); cost_m2 : half the sum of squared residuals [m^2];
    evaluations : model evaluations of ours (residuals and Jacobian together);
    time_s : wall time of the fit [s].
    """

    method: str
    objective: str | None = None
    status: int | None = None
    message: str | None = None
    success: bool | None = None
    nfev: int | None = None
    njev: int | None = None
    optimality: float | None = None
    cost_m2: float | None = None
    evaluations: int | None = None
    time_s: float | None = None

    def line(self) -> str:
        """One human line, e.g. 'solver: `ftol` ... (12 evaluations, 0.081 s)'."""
        if self.time_s is None:
            return f"solver: {self.method}"
        return f"solver: {self.message} ({self.evaluations} evaluations, {self.time_s:.3f} s)"


@dataclass(frozen=True)
class Outlier(Record):
    """A flagged measurement: its source (bag), the 0-based index of its tracker-point
    message there, its header stamp [ns] (None when the source had none), how far it is
    from the model's prediction [m] and in which direction (unit vector, tracker frame,
    measured minus predicted), in robust sigmas of the residual."""

    bag: str
    index: int
    stamp_ns: int | None
    size_m: float
    direction: list[float]
    sigmas: float
    # the measured target's point topic where there are several ('' with one target, and in
    # documents written before it was recorded)
    target: str = ""
    # 'tracker': a blunder of the tracker (a lost beam, a reseated target); 'robot': every
    # target of its pose off together, as one rigid tool (`ROBOT`): the robot (or the whole
    # set-up) was not where the model puts it there, not the tracker, a place where the
    # model misses. Both are left out of the fit (they would pull every other pose).
    kind: str = "tracker"
    # how far the reference reflectors read with its pose lay from the tracker's drift
    # [m] (msgs_doc/references.md); None: no reference read there
    references_m: float | None = None

    def line(self) -> str:
        """One human line, e.g. 'run.mcap point 17 (stamp ...): 5.002 mm off (+x ...)'."""
        stamp = "" if self.stamp_ns is None else f", stamp {self.stamp_ns * 1e-9:.3f} s"
        target = f" (target {self.target})" if self.target else ""
        d = ", ".join(f"{c:+.2f}" for c in self.direction)
        refs = (
            ""
            if self.references_m is None
            else f" while the reference reflectors stayed within {self.references_m * 1e3:.3f} mm"
        )
        if self.kind == ROBOT:
            why = (
                f"; the pose's targets moved as one rigid tool{refs}: the robot (or the "
                "whole set-up) there, not a tracker blunder: a place where the model misses"
            )
        elif self.references_m is not None and self.references_m > 0.5 * self.size_m:
            why = (
                f"; the reference reflectors read with it were off by "
                f"{self.references_m * 1e3:.3f} mm too: the tracker's frame moved there"
            )
        elif self.references_m is not None and not self.target:
            why = (
                f"; the reference reflectors read with it stayed within "
                f"{self.references_m * 1e3:.3f} mm: the tracker's frame did not move; the "
                "robot there, or this target's SMR (one target cannot tell)"
            )
        else:
            why = ""
        return (
            f"{self.bag} point {self.index}{target}{stamp}: {self.size_m * 1e3:.3f} mm off the "
            f"model ({self.sigmas:.0f} sigma; direction {d}{why})"
        )
