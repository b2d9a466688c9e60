"""The closed-form compliance of each hinge profile, found by the profile's name.

One module per profile, named as the profile (``flexcal.geometry.profiles``), each with
``CLOSED_FORM``: a ``ClosedForm`` holding the 6 x 6 compliance of the compliant part, the
published source, the accuracy measured against the FEM and the profile's own validity
checks. ``model.hinge`` and ``model.chain`` reach it through ``closed_form_of(hinge)``; a
new profile adds its module here and nothing else in the model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from flexcal.geometry.profiles import discover

__all__ = ["ClosedForm", "closed_form_of", "closed_forms"]


@dataclass(frozen=True, kw_only=True, eq=False)
class ClosedForm:
    """The closed form of one profile.

    compliance(hinge, material) -> (6, 6): at the centre of the compliant part's free end
    (x = +length/2, hinge frame), its fixed end (x = -length/2) clamped; DOF order
    ux, uy, uz, rx, ry, rz, SI (m/N, 1/N, rad/(N m)).
    range_warnings(hinge) -> list[str]: one sentence per validity range of the working
    rotation the hinge leaves (the torsion range, common to all, is ``model.hinge``'s).
    source: where the formulas come from; accuracy: FEM / closed form as measured.
    """

    compliance: Callable[[Any, Any], np.ndarray]
    range_warnings: Callable[[Any], list[str]]
    source: str
    accuracy: str


def closed_forms() -> dict[str, ClosedForm]:
    """``{profile name: ClosedForm}`` of every profile with a model module."""
    return discover("flexcal.model.profiles", "CLOSED_FORM")


def closed_form_of(hinge) -> ClosedForm:
    """The ``ClosedForm`` of ``hinge``'s profile; ``ValueError`` when there is none."""
    name = getattr(hinge, "profile_name", None)
    forms = closed_forms()
    if name not in forms:
        raise ValueError(f"no closed-form compliance for a {type(hinge).__name__}; the hinge profiles with one are "
                         f"{', '.join(forms)}")
    return forms[name]
