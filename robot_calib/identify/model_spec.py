"""A model's name as a value: its base model and its effect terms, parsed in one place.

'geometric+backlash:4+thermal_drift' is the base 'geometric' and the terms 'backlash:4' and
'thermal_drift' (msgs_doc/effects.md); `str()` gives the name back. Which bases and effects
exist, and what a term's options mean, is `identify.calibrate.parse_model`'s business (it
needs the robot); here only the text's structure.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ModelSpec:
    """`base` ('nominal', 'cpa', 'geometric', ...) and the effect `terms` in the order
    written, each 'EFFECT[:joints][:options]'."""

    base: str
    terms: tuple[str, ...] = ()

    @classmethod
    def parse(cls, text: str) -> ModelSpec:
        """'geometric+backlash:4' -> ModelSpec('geometric', ('backlash:4',))."""
        base, *terms = text.split("+")
        return cls(base, tuple(terms))

    def __str__(self) -> str:
        return "+".join((self.base, *self.terms))

    @property
    def effect_names(self) -> tuple[str, ...]:
        """Each term's effect name (the text before its first ':')."""
        return tuple(self.term_parts(term)[0] for term in self.terms)

    @staticmethod
    def term_parts(term: str) -> tuple[str, tuple[str, ...]]:
        """A term's effect name and its ':'-separated parts after it (joints, options):
        'joint_harmonics:2:orders=11' -> ('joint_harmonics', ('2', 'orders=11'))."""
        name, *parts = term.split(":")
        return name, tuple(parts)

    def added_to(self, simpler: ModelSpec) -> str:
        """The terms this model has beyond `simpler`, joined with '+' ('' when none)."""
        return "+".join(t for t in self.terms if t not in simpler.terms)
