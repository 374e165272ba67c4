"""What `rc.diagnose` returns: a Diagnosis that can write its reports (the ladder and the
measurements behind it kept with it, not part of DIAGNOSIS.json)."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from robot_calib.diagnosis.diagnosis import Diagnosis
from robot_calib.diagnosis.ladder import Ladder
from robot_calib.errors import InputError
from robot_calib.flows.diagnose import html_report_path, write_diagnosis
from robot_calib.measurements import Recording


class ReportableDiagnosis(Diagnosis):
    """A Diagnosis that can write its reports (what `rc.diagnose` returns): the ladder and
    the measurements behind it are kept with it (not part of DIAGNOSIS.json)."""

    @classmethod
    def of(cls, diagnosis: Diagnosis, ladder: Ladder, recording: Recording) -> ReportableDiagnosis:
        """`diagnosis` with the `ladder` it was climbed on and its `recording`."""
        out = cls(**{f.name: getattr(diagnosis, f.name) for f in fields(Diagnosis)})
        object.__setattr__(out, "_behind", (ladder, recording))  # frozen: not a field
        return out

    def report(self, output: str | Path, *, force: bool = False) -> Path:
        """Write DIAGNOSIS.json at `output` with the Markdown and HTML reports (+ plots) and
        the best model's PARAMS.json beside it, as `robot-calib diagnose -o output` does
        (`write_diagnosis`; an existing file is replaced only with `force`): the HTML
        report's path."""
        behind: tuple[Ladder, Recording] | None = getattr(self, "_behind", None)
        if behind is None:  # a copy (dataclasses.replace) has lost what was behind it
            raise InputError("this diagnosis has no ladder behind it: diagnose again")
        ladder, recording = behind
        write_diagnosis(self, ladder, recording, output, force)
        return html_report_path(output)
