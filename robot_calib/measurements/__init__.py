"""The measurement model (msgs_doc/specification.md section 1), free of file formats: paired
measurements (`Recording`), pairing by stamp, approach directions and circle sweeps."""

from robot_calib.measurements.recording import (
    PAIR_TOLERANCE_S,
    Recording,
    recording_from_arrays,
    recording_from_stream,
)
from robot_calib.measurements.sweeps import Sweep, find_sweeps

__all__ = [
    "PAIR_TOLERANCE_S",
    "Recording",
    "Sweep",
    "find_sweeps",
    "recording_from_arrays",
    "recording_from_stream",
]
