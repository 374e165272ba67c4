"""Export a calibration to the formats robots and their software read, one module per format.

Every format is an `Exporter` (`base.py`): a name, a default file suffix, a one-line
description and `render(cal, source) -> str`, the file's whole text. The registry
`FORMATS` maps the names `robot-calib export --format` accepts to them; a new format is one
new module here, listed in `_MODULES`.
"""

from __future__ import annotations

import importlib

from robot_calib.export.base import Exporter

_MODULES = ("urdf", "dh", "ur", "json_params")


def _registry() -> dict[str, Exporter]:
    formats: dict[str, Exporter] = {}
    for module in _MODULES:
        exporter: Exporter = importlib.import_module(f"{__name__}.{module}").EXPORTER
        formats[exporter.name] = exporter
    return formats


FORMATS: dict[str, Exporter] = _registry()

__all__ = ["FORMATS", "Exporter"]
