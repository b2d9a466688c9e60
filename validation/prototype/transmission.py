"""Actuator transmission of the virtual prototype: screw, contact stiffness, play with
friction memory.

Per driving chain i (docs/prototype.md, "Transmission"):

- the screw sits at ``s_i = x_cmd,i + x0_i`` [m] along the chain axis (positive from A
  to B), ``x0_i`` the unknown initial position;
- the nut is held in a play of width ``CL_i``; its offset ``g_i`` in [0, CL_i] is
  measured from the flank it bears on under compression, so the contact point (anchor)
  is at ``s_i + g_i``;
- between anchor and nut acts the axial contact stiffness ``k_a`` (ball screw +
  coupling, ``MechanismParams.actuator_stiffness``);
- the offset follows the paper's idea of a hysteresis coefficient: the nut takes up the
  fraction ``mu_i`` of the displacement that would release the chain's axial tension.
  With ``N_i`` the tension [N] and ``k_i`` the true axial stiffness [N/m] seen from the
  anchor (contact spring in series with the whole mechanism, from the equilibrium's
  tangent), that displacement measured from the compression flank is
  ``r_i = g_i + N_i / k_i`` and the rest offset is ``mu_i r_i``;
- friction holds the nut until the rest offset has moved more than the breakaway band
  ``delta_b,i = F_breakaway,i / k_i`` away; then the nut follows at ``delta_b,i`` behind
  (a rate-independent play/backlash operator with memory along the trajectory), and
  the play's walls clip the result: ``g_i = clip(play(g_prev, mu_i r_i, delta_b), 0, CL_i)``.

With ``F_breakaway = 0`` this is the memoryless ``g = clip(mu N/k, 0, CL)`` (the paper's
Eq. 7 form with the true nonlinear mechanism instead of its linear model).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ActuatorTransmission",
    "play_operator",
    "nut_offset",
    "point_class",
    "DEFAULT_BREAKAWAY_FORCE",
]

# Default breakaway (static friction) force of a nut in its play [N]: small against the
# ~1 kN chain loads, large enough to leave a visible memory of a few nm at k ~ 1e8 N/m.
DEFAULT_BREAKAWAY_FORCE = 2.0


@dataclass(frozen=True, kw_only=True)
class ActuatorTransmission:
    """One driving chain's transmission.

    initial_position x0 [m] (screw position at zero command, along the chain axis,
    positive A -> B); clearance CL [m] (play width, >= 0); hysteresis mu [-] in [0, 1]
    (fraction of the release displacement the nut takes up); breakaway_force [N] (>= 0,
    friction that holds the nut inside its play).
    """

    initial_position: float = 0.0
    clearance: float = 0.0
    hysteresis: float = 1.0
    breakaway_force: float = DEFAULT_BREAKAWAY_FORCE

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(float(value))):
                raise ValueError(f"transmission {f.name}={value!r} must be a finite number")
        if self.clearance < 0:
            raise ValueError(f"transmission clearance={self.clearance * 1e3:.6g} mm must be >= 0")
        if not 0.0 <= self.hysteresis <= 1.0:
            raise ValueError(f"transmission hysteresis={self.hysteresis!r} must be in [0, 1]")
        if self.breakaway_force < 0:
            raise ValueError(f"transmission breakaway_force={self.breakaway_force!r} N must be >= 0")


def play_operator(previous: np.ndarray | None, target: np.ndarray, band: np.ndarray) -> np.ndarray:
    """Play (backlash) operator with half-width ``band`` (...,) [m], elementwise.

    Returns ``previous`` if ``|target - previous| <= band``, else ``target -+ band``
    (following at ``band`` behind). ``previous=None`` (no history) returns ``target``.
    """
    target = np.asarray(target, dtype=float)
    if previous is None:
        return target.copy()
    previous = np.asarray(previous, dtype=float)
    band = np.asarray(band, dtype=float)
    return np.clip(previous, target - band, target + band)


def nut_offset(previous: np.ndarray | None, tension: np.ndarray, stiffness: np.ndarray, offset: np.ndarray,
               hysteresis: np.ndarray, clearance: np.ndarray, breakaway_force: np.ndarray) -> np.ndarray:
    """New nut offsets g (...,) [m] from the current equilibrium (module docstring).

    previous: offsets at the previous trajectory point (None: no memory); tension N [N]
    (positive = tension); stiffness k [N/m] seen from the anchor; offset: the offsets g
    [m] the equilibrium was solved with; hysteresis mu; clearance CL [m];
    breakaway_force [N].
    """
    stiffness = np.asarray(stiffness, dtype=float)
    release = np.asarray(offset, dtype=float) + np.asarray(tension, dtype=float) / stiffness
    rest = np.asarray(hysteresis, dtype=float) * release
    followed = play_operator(previous, rest, np.asarray(breakaway_force, dtype=float) / stiffness)
    return np.clip(followed, 0.0, np.asarray(clearance, dtype=float))


def point_class(driving_tension: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """State class per point, the model's definitions (DESIGN.md, paper Fig. 12).

    driving_tension (..., 3) [N] (positive = tension), offsets (..., 3) [m] ->
    (...,) array of "S1" (all three driving chains compressed, on their flanks),
    "S2" (some driving chain off its compression flank, g > 0) or "S3" (otherwise:
    mixed tension/compression without a gap).
    """
    tension = np.asarray(driving_tension, dtype=float)
    gap = np.any(np.asarray(offsets, dtype=float) > 0.0, axis=-1)
    compressed = np.all(tension < 0.0, axis=-1)
    return np.where(gap, "S2", np.where(compressed, "S1", "S3"))
