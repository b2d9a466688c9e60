"""Where a consistent model's fits start: at the second-order model's estimate on the same data.

The consistent model (``--model consistent``: the chains' measured shortening solved with the
clearance's play state) is nearly exact against the FEM prototype, but its least-squares
surface has more than one basin. Fitted from the prior mean on the README's noise-free main
job (session 20, merged FEM truth) it ended in a worse minimum (fit 0.0064 urad RMS, D3.x0
2.33 um off, base z RMS 72.9), where the same fit started at the second-order model's estimate
reached 0.0016 urad and x0 <= 0.63 um (docs/model.md "Session 20"). The second-order model
differs from it only in the terms that are small (the shortening and the play state), its
surface has the one basin the prior mean finds, and its estimate lies in the consistent
model's good basin: so the identification of a consistent space first fits the second-order
form of the same space (``second_order_form``) and starts there (``identify_all``, docs/model.md
"Session 21").
"""

from __future__ import annotations

import dataclasses

from flexcal.model.parameters import ParameterSpace

__all__ = ["is_consistent", "second_order_form"]


def is_consistent(space: ParameterSpace) -> bool:
    """Whether ``space`` evaluates the consistent model (its chains' shortening is set)."""
    return bool(space.chain_shortening)


def second_order_form(space: ParameterSpace) -> ParameterSpace:
    """The second-order model on the same mount, active sources and chain factors as the
    consistent ``space``: without the chains' shortening and its slopes, the factors' slopes
    and curvatures, and the play state (Eq. 7's memoryless clip): what ``--model
    second-order`` builds for that mount."""
    return dataclasses.replace(space, second_order=True, chain_shortening=(), shortening_slopes=(),
                               compliance_slopes=(), compliance_curvatures=(), breakaway_force=None)
