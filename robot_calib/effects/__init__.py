"""Effects: additions to the kinematic model, one module per contract name.

`make_effect(name, joints, **options)` builds one from its contract name.
"""

from __future__ import annotations

from typing import Any

from robot_calib.effects.backlash import Backlash
from robot_calib.effects.base import Contribution, Effect
from robot_calib.effects.compliance import Compliance
from robot_calib.effects.eccentricity import Eccentricity
from robot_calib.effects.encoder_scale import EncoderScale
from robot_calib.effects.ripple import JointRipple
from robot_calib.effects.thermal_drift import ThermalDrift
from robot_calib.errors import InputError

EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (Eccentricity, Backlash, Compliance, EncoderScale, ThermalDrift, JointRipple)
}
VOCABULARY = tuple(name for name, cls in EFFECTS.items() if cls.in_vocabulary)


def make_effect(name: str, joints: tuple[int, ...] | list[int] = (), **options: Any) -> Effect:
    """The effect called `name` (contract vocabulary or simulator-only) on `joints` (1-based)."""
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    joints = tuple(int(j) for j in joints)
    order = options.get("order", 1)
    if not isinstance(order, int) or order < 1:
        raise InputError(f"effect {name!r}: order must be an integer >= 1, got {order!r}")
    if name == "thermal_drift" and joints:
        raise InputError("thermal_drift belongs to no joint: give joints: []")
    try:
        return EFFECTS[name](joints=joints, **options)  # type: ignore[call-arg]
    except TypeError as exc:
        raise InputError(f"effect {name!r}: bad options {options} ({exc})") from None


__all__ = ["EFFECTS", "VOCABULARY", "Contribution", "Effect", "make_effect"]
