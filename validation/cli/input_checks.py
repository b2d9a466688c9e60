"""Checks of command-line sizes before any CAD, meshing or solving.

``check_length_mm`` refuses a dimension no flexure hinge has (and CadQuery cannot model:
``--radius-mm 1e300`` used to end in ``Standard_DomainError`` from deep inside OCCT);
``check_elements_through`` bounds the mesh knob. The closed-form range warnings live
with the formulas (``flexcal.model.hinge.closed_form_range_warnings``).
"""

from __future__ import annotations

import math

__all__ = ["MIN_LENGTH_MM", "MAX_LENGTH_MM", "MAX_ELEMENTS_THROUGH", "check_length_mm", "check_elements_through"]

# 10 um: 100 x OCCT's modelling precision (1e-7 m, Precision::Confusion), below any
# machined or eroded flexure; 10 m: beyond the metre-scale mount this toolkit models.
MIN_LENGTH_MM = 0.01
MAX_LENGTH_MM = 10_000.0
# Quadratic tets: 3 through the neck are within 1 % of converged (0.15 % through a leaf,
# REFERENCES.md; -0.27 % fTetWild / -0.64 % mapped for the reference notch,
# docs/reliability.md), so 16 leaves room for convergence studies; a million (the bad
# case) would ask for ~1e18 DOF.
MAX_ELEMENTS_THROUGH = 16.0


def check_length_mm(option: str, value: float | None, *, allow_zero: bool = False) -> None:
    """Raise ValueError naming ``option`` unless ``value`` [mm] is a usable dimension
    (``None`` passes: the option was not given; zero and negative values are left to the
    parameter types, whose messages say what such a value would mean)."""
    if value is None:
        return
    low = "0" if allow_zero else f"{MIN_LENGTH_MM:g}"
    if not math.isfinite(value):
        raise ValueError(f"{option}={value!r} must be a finite number of mm")
    if value <= 0:
        return
    if not MIN_LENGTH_MM <= value <= MAX_LENGTH_MM:
        raise ValueError(f"{option}={value:g} mm is out of range: give {low} to {MAX_LENGTH_MM:g} mm "
                         f"(sizes below {MIN_LENGTH_MM:g} mm are below the CAD kernel's precision, above "
                         f"{MAX_LENGTH_MM:g} mm no flexure hinge)")


def check_elements_through(value: float) -> None:
    """Raise ValueError unless 1 <= ``value`` <= MAX_ELEMENTS_THROUGH."""
    if not (math.isfinite(value) and 1.0 <= value <= MAX_ELEMENTS_THROUGH):
        raise ValueError(f"--elements-through={value:g} is out of range: give 1 to {MAX_ELEMENTS_THROUGH:g} "
                         f"(3 through the neck is within 1 % of converged; more only multiplies time and memory)")
