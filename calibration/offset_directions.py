"""Mount offsets whose direction the data do not determine (issue #28 item 1).

The paper's sources give a chain's mount offset in polar coordinates: magnitude ``X.d`` and
direction ``X.phi`` (model/parameters.py). The estimator's bars are linear at the estimate,
where phi's bar is the offset's sideways uncertainty over d_hat. Where d_hat is within a few of
its own standard errors of zero, the region the bars describe reaches the origin, where phi is
undefined: there a linear bar on phi (or on a base combination led by it) does not describe
the error. Measured (docs/calibration.md "Session 22"): `paper` seed 2 designed, L3's true
offset 0.254 mm, estimate 0.918 +- 0.522 mm; L3.phi 4.16 +- 0.35 rad against the true 1.67 (z 7.2,
the combination led by it z 13.8), while the same estimate errs by 2.1 standard errors along the
offset and 0.5 across it in Cartesian components. Over session 21's twelve two-stage fits this
rule marks five combinations, which hold the three largest designed base z-scores (13.8, 5.2,
4.5) and two ordinary ones (0.85, -0.20).

The rule is blind (the estimate and its bars only): a direction is undetermined when
d_hat < ``UNDETERMINED_SIGMAS`` sigma_d, i.e. the data do not tell the offset from zero at
two standard errors.

Since session 23 the estimator works in the offsets' Cartesian components
(``calibration.offset_chart``), so no base combination holds a direction any more; the rule
now marks only the direction's own row in the sources' table (its polar bar, by the delta
method, is what it is at the estimate and no more).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["undetermined_directions", "UNDETERMINED_SIGMAS"]

# the usual two-sided 95 % reading of "not distinguishable from zero": an offset whose magnitude is
# less than two of its standard errors could be zero, and with it any direction
UNDETERMINED_SIGMAS = 2.0


def undetermined_directions(names: Sequence[str], values: np.ndarray, std: np.ndarray,
                            sigmas: float = UNDETERMINED_SIGMAS) -> dict[str, str]:
    """{"X.phi": why} for every offset pair (X.d, X.phi) in ``names`` whose identified magnitude
    values[X.d] [m] is below ``sigmas`` x its standard error std[X.d] [m] (values, std aligned
    with names; a magnitude without a finite positive bar is not judged)."""
    index = {n: i for i, n in enumerate(names)}
    out = {}
    for name in names:
        if not name.endswith(".phi"):
            continue
        magnitude = name[: -len(".phi")] + ".d"
        if magnitude not in index:
            continue
        d, s = float(values[index[magnitude]]), float(std[index[magnitude]])
        if np.isfinite(s) and s > 0 and d < sigmas * s:
            out[name] = (f"direction undetermined: {magnitude} = {d * 1e3:.3g} +- {s * 1e3:.3g} mm is within {sigmas:g} "
                         f"standard errors of zero, where {name} is undefined, so its linear bar does not hold")
    return out
