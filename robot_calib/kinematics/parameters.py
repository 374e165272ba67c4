"""One named parameter vector: names, units, nominal values, current values, free flags.

The solver sees only the flat vector of free values (`pack` / `unpack`); everything else
(reports, files, effects) addresses parameters by name. Objects are immutable: every
change returns a new vector, so residual functions never mutate shared state.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from robot_calib.errors import ParameterError
from robot_calib.kinematics.frames import Array


@dataclass(frozen=True)
class Parameter:
    """One model parameter. `unit` is SI ("m", "rad", "1", "1/s", "rad/(N m)", ...)."""

    name: str
    unit: str
    nominal: float
    free: bool = True
    fixed_reason: str = ""
    group: str = "geometric"


class ParameterVector:
    """An ordered set of named parameters with current values.

    values : shape (P,), SI units as `Parameter.unit`.
    """

    def __init__(self, parameters: Sequence[Parameter], values: Iterable[float] | None = None):
        self.parameters: tuple[Parameter, ...] = tuple(parameters)
        self.names: tuple[str, ...] = tuple(p.name for p in self.parameters)
        if len(set(self.names)) != len(self.names):
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ParameterError(f"duplicate parameter names: {dup}")
        self._index = {n: i for i, n in enumerate(self.names)}
        self.nominal: Array = np.array([p.nominal for p in self.parameters], dtype=float)
        vals = self.nominal.copy() if values is None else np.array(list(values), dtype=float)
        if vals.shape != self.nominal.shape:
            raise ParameterError(f"expected {len(self.names)} values, got shape {vals.shape}")
        vals.setflags(write=False)
        self.values: Array = vals
        self.free: Array = np.array([p.free for p in self.parameters], dtype=bool)

    def __len__(self) -> int:
        return len(self.parameters)

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.index(name)])

    def index(self, name: str) -> int:
        """Position of `name` in the full vector."""
        try:
            return self._index[name]
        except KeyError:
            raise ParameterError(f"unknown parameter {name!r}") from None

    def get(self, name: str, default: float) -> float:
        """Value of `name`, or `default` where the vector has no such parameter."""
        return self[name] if name in self._index else default

    @property
    def free_names(self) -> tuple[str, ...]:
        return tuple(n for n, f in zip(self.names, self.free) if f)

    @property
    def deviations(self) -> Array:
        """values - nominal, shape (P,)."""
        return self.values - self.nominal

    def pack(self) -> Array:
        """The free values as the flat vector a solver sees, shape (n_free,)."""
        return self.values[self.free].copy()

    def unpack(self, x: Array) -> ParameterVector:
        """A copy whose free values are `x` (shape (n_free,)); fixed values unchanged."""
        x = np.asarray(x, dtype=float)
        if x.shape != (int(self.free.sum()),):
            raise ParameterError(f"expected {int(self.free.sum())} free values, got {x.shape}")
        vals = self.values.copy()
        vals[self.free] = x
        return ParameterVector(self.parameters, vals)

    def with_values(self, updates: Mapping[str, float]) -> ParameterVector:
        """A copy with the named values replaced."""
        vals = self.values.copy()
        for name, v in updates.items():
            vals[self.index(name)] = float(v)
        return ParameterVector(self.parameters, vals)

    def fixed(self, names: Iterable[str], reason: str) -> ParameterVector:
        """A copy with `names` fixed at their current values, recording `reason`."""
        idx = {self.index(n) for n in names}
        params = [
            Parameter(p.name, p.unit, p.nominal, False, reason, p.group) if i in idx else p
            for i, p in enumerate(self.parameters)
        ]
        return ParameterVector(params, self.values)

    def freed(self, names: Iterable[str]) -> ParameterVector:
        """A copy with `names` free."""
        idx = {self.index(n) for n in names}
        params = [
            Parameter(p.name, p.unit, p.nominal, True, "", p.group) if i in idx else p
            for i, p in enumerate(self.parameters)
        ]
        return ParameterVector(params, self.values)

    def to_dict(self) -> list[dict[str, object]]:
        """JSON-ready records, one per parameter, in vector order."""
        return [
            {
                "name": p.name,
                "unit": p.unit,
                "group": p.group,
                "nominal": p.nominal,
                "value": float(v),
                "free": p.free,
                **({"fixed_reason": p.fixed_reason} if not p.free else {}),
            }
            for p, v in zip(self.parameters, self.values)
        ]

    @classmethod
    def from_dict(cls, records: Sequence[Mapping[str, Any]]) -> ParameterVector:
        """Inverse of `to_dict`."""
        try:
            params = [
                Parameter(
                    str(r["name"]),
                    str(r["unit"]),
                    float(r["nominal"]),
                    bool(r["free"]),
                    str(r.get("fixed_reason", "")),
                    str(r.get("group", "geometric")),
                )
                for r in records
            ]
            values = [float(r["value"]) for r in records]
        except (KeyError, TypeError, ValueError) as exc:
            raise ParameterError(f"malformed parameter record: {exc}") from None
        return cls(params, values)

    def concat(self, other: ParameterVector) -> ParameterVector:
        """This vector followed by `other` (names must not clash)."""
        return ParameterVector(
            self.parameters + other.parameters, np.concatenate([self.values, other.values])
        )
