"""The rules every hinge profile shares, written once: ``HingeRules``, a base of each
profile's frozen dataclass (the profile still satisfies ``protocol.HingeProfile``
structurally; this only keeps the common parts in one place)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from ..checks import require, require_finite
from .protocol import Dimension

__all__ = ["HingeRules"]


class HingeRules:
    """Checks, total length, construction from mm and the chain answer of a hinge whose
    fields are its ``dimensions`` (by ``Dimension.field``) plus ``block_length`` [m]."""

    dimensions: ClassVar[tuple[Dimension, ...]]
    #: a hint added to a dimension's "> 0 mm" refusal, by ``Dimension.key``
    refusal_notes: ClassVar[dict[str, str]] = {}

    def __post_init__(self) -> None:
        """Every set field finite; every dimension > 0 (>= 0 where it may be zero) and the
        blocks > 0, refused with the field's name and value in mm (``checks.require``)."""
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is not None:
                require_finite(f.name, value)
        for d in self.dimensions:
            value = getattr(self, d.field)
            note = f" {self.refusal_notes[d.key]}" if d.key in self.refusal_notes else ""
            if d.allow_zero:
                require(value >= 0, d.field, value, f">= 0 mm{note}")
            else:
                require(value > 0, d.field, value, f"> 0 mm{note}")
        require(self.block_length > 0, "block_length", self.block_length, "> 0 mm")

    @property
    def total_length(self) -> float:
        """Length of the whole part including both blocks [m]."""
        return self.length + 2.0 * self.block_length

    @classmethod
    def from_mm(cls, dimensions_mm: dict[str, float], block_mm: float):
        """The hinge from ``{Dimension.key: value [mm]}`` (a missing one: its default) and
        the block length [mm]."""
        mm = 1e-3
        values = {d.field: (dimensions_mm[d.key] if d.key in dimensions_mm or d.default_mm is None
                            else d.default_mm) * mm for d in cls.dimensions}
        return cls(**values, block_length=block_mm * mm)

    def chain_dimensions(self) -> dict[str, float] | None:
        """None: the mount's chains are made of leaves (a leaf profile overrides this)."""
        return None
