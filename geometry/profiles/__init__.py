"""Hinge profiles: one class per profile, found by its name.

A *profile* is the shape of a single flexure hinge's compliant part: "circular" (right-
circular notch), "leaf" (corner-filleted leaf, paper Fig. 5c), ... Each profile is one
module of this folder holding

- its hinge class (``HingeProfile``): a frozen parameter dataclass [m] validated on
  construction, with the profile's name, its command-line / sweep dimensions and its
  compliant piece (``thin_piece``), and
- its piece class (``ThinPiece``): thickness profile t(x), volume, boundary surfaces,
  CAD solid (CadQuery loaded inside ``solid`` only), feature sizes the CAD kernel must
  resolve and the mesher's sizing hints.

The module names its hinge class in ``HINGE``. The other packages add what they own under
the same name, one module each: ``flexcal.model.profiles.<name>`` (the closed-form
compliance, its source and measured accuracy) and ``flexcal.fem.profiles.<name>`` (the
outline the mapped mesher maps onto). A new profile is those three modules; nothing else
names a profile (docs/architecture.md, "Hinge profiles").
"""

from __future__ import annotations

from .protocol import Dimension, HingeProfile, ThinPiece
from .registry import discover, hinge_type, hinge_types, profile_names

__all__ = ["Dimension", "HingeProfile", "ThinPiece", "discover", "hinge_type", "hinge_types", "profile_names"]
