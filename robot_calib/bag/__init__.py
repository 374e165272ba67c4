"""Bags: MCAP files as `ros2 bag record -s mcap` (Jazzy) writes them; ROS-free file I/O.

`BagWriter` writes raw CDR messages with their receive times; `BagReader` reads them back
(also from a bag whose recorder was killed); `read.read_recording` turns bags into the
measurement model's `Recording`; `repair.repair_bag` copies what a killed writer left
into a new, complete bag. Nothing is imported until used (PEP 562), so importing
`robot_calib.bag` costs nothing and the core never pulls in `mcap` by accident.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from robot_calib import lazy_exports

_EXPORTS = {
    "BagMessage": "robot_calib.bag.mcap_reader",
    "BagReader": "robot_calib.bag.mcap_reader",
    "TopicInfo": "robot_calib.bag.mcap_reader",
    "BagWriter": "robot_calib.bag.mcap_writer",
    "QosProfile": "robot_calib.bag.ros2_formats",
    "message_definition": "robot_calib.bag.ros2_formats",
    "type_description_hash": "robot_calib.bag.ros2_formats",
    "read_recording": "robot_calib.bag.read",
    "RepairReport": "robot_calib.bag.repair",
    "repair_bag": "robot_calib.bag.repair",
}


__getattr__: Callable[[str], Any] = lazy_exports(__name__, _EXPORTS)


__all__ = sorted(_EXPORTS)
