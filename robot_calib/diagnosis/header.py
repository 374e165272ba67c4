"""The header a quality system files a calibration report under (msgs_doc/report.md):
when it was written, which robot (model and serial), which instrument and its stated
accuracy, who ran it, the temperatures the campaign saw, the software and the exact
command. The reports (HTML, Markdown, PDF) print it first; DIAGNOSIS.json keeps it as
`header`."""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robot_calib.measurements import Recording
from robot_calib.records import Record

NOT_GIVEN = "not given"


@dataclass(frozen=True)
class ReportHeader(Record):
    """The report's header (every text as printed; `NOT_GIVEN` where the user gave none).

    written : date and time the report was written, ISO 8601 with the UTC offset
    robot : the robot model (the description's name)
    serial : the robot's serial number (`serial=`)
    instrument : the measuring instrument (`instrument=`)
    stated_accuracy_mm : the instrument's stated 1-sigma per axis [mm], None where not given
    operator : who ran the campaign (`operator=`)
    temperature_c : (lowest, highest) robot temperature of the campaign's recordings
        [deg C], None where none was recorded
    software : robot_calib and its version
    command : the exact command (or call) that wrote the report
    """

    written: str
    robot: str
    serial: str
    instrument: str
    stated_accuracy_mm: float | None
    operator: str
    temperature_c: tuple[float, float] | None
    software: str
    command: str

    def rows(self) -> list[tuple[str, str]]:
        """(label, text) per line of the header, as the reports print it."""
        accuracy = (
            NOT_GIVEN
            if self.stated_accuracy_mm is None
            else f"{self.stated_accuracy_mm:g} mm (1-sigma per axis, as stated)"
        )
        temperature = (
            "not recorded"
            if self.temperature_c is None
            else f"{self.temperature_c[0]:.1f} to {self.temperature_c[1]:.1f} deg C"
        )
        return [
            ("Date and time", self.written),
            ("Robot", f"{self.robot}, serial {self.serial}"),
            ("Instrument", f"{self.instrument}; stated accuracy {accuracy}"),
            ("Operator", self.operator),
            ("Campaign temperature", temperature),
            ("Software", self.software),
            ("Command", self.command),
        ]


@dataclass(frozen=True)
class HeaderFields:
    """What the user says for the header (None: not given) and the command they ran."""

    serial: str | None = None
    operator: str | None = None
    instrument: str | None = None
    command: str = "robot_calib (a Python call)"


def report_header(
    robot: str,
    recordings: Sequence[Recording],
    fields: HeaderFields,
    stated_accuracy_m: float | None,
) -> ReportHeader:
    """The header of a report on `recordings` (their temperature range) of `robot`,
    written now."""
    from robot_calib import __version__

    temperatures = [r.poses.temperature for r in recordings if r.poses.temperature is not None]
    values = np.concatenate(temperatures) if temperatures else np.zeros(0)
    values = values[np.isfinite(values)]
    return ReportHeader(
        written=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        robot=robot,
        serial=fields.serial or NOT_GIVEN,
        instrument=fields.instrument or NOT_GIVEN,
        stated_accuracy_mm=None if stated_accuracy_m is None else stated_accuracy_m * 1e3,
        operator=fields.operator or NOT_GIVEN,
        temperature_c=(float(values.min()), float(values.max())) if values.size else None,
        software=f"robot_calib {__version__}",
        command=fields.command,
    )
