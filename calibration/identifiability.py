"""What the data can tell apart: local identifiability at an identified solution.

The Jacobian of the residuals with respect to the unit-box parameters is, by the
chain rule, the physical Jacobian with each column multiplied by its parameter's
range (the column scaling); dividing each row by its noise standard deviation makes
the singular values read in "noise units per full range". Then:

- singular values s_1 >= ... >= s_d, the numerical rank (s_i > rank_rtol s_1) and the
  condition number s_1 / s_d (< 100 is robotics' rule of thumb for a well-posed
  calibration);
- QR with column pivoting picks an identifiable subset of ``rank`` parameters (each
  pivot is the column least explained by those already picked);
- weak directions: right singular vectors with s_i <= rank_rtol s_1 (numerically null)
  or, when the noise is given, with 1/s_i > max_std (the data pin that combination
  down worse than ``max_std`` of a range). Parameters whose unit vector projects onto
  the weak subspace by at least ``participation`` (squared norm) are confounded, and
  confounded parameters linked through that projection form the groups the data
  cannot tell apart;
- with noise, the joint standard deviation of every parameter, sqrt(diag (J^T J)^+)
  [fraction of its range].

A parameter is *meaningful* when it is in no confounded group (and, with noise, its
standard deviation is at most ``max_std``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from flexcal.calibration.polish import batched_jacobian_fd

__all__ = ["IdentifiabilityReport", "identifiability", "analyze_jacobian"]


@dataclass(frozen=True, kw_only=True)
class IdentifiabilityReport:
    """Identifiability of d parameters at one point (see module doc).

    names (d,); jacobian (m, d) scaled; singular_values (min(m, d),); rank;
    rank_rtol; condition_number s_1 / s_d (inf if d > m or s_d = 0);
    condition_number_subset: that of the pivoted identifiable subset; identifiable:
    the pivoted subset (rank names, in pivot order); groups: tuples of confounded names;
    parameter_std (d,) [fraction of range] (None without noise; inf in a null
    direction); meaningful (d,) bool; column_norms (d,): each parameter's sensitivity
    alone [residual (noise) units per range]; max_cosine (d,): largest |cos| between a
    column and any other (1 = duplicated).
    """

    names: tuple[str, ...]
    jacobian: np.ndarray
    singular_values: np.ndarray
    rank: int
    rank_rtol: float
    condition_number: float
    condition_number_subset: float
    identifiable: tuple[str, ...]
    groups: tuple[tuple[str, ...], ...]
    parameter_std: np.ndarray | None
    meaningful: np.ndarray
    column_norms: np.ndarray
    max_cosine: np.ndarray

    @property
    def meaningful_names(self) -> tuple[str, ...]:
        return tuple(n for n, ok in zip(self.names, self.meaningful) if ok)

    def summary(self) -> str:
        """A few lines for a report."""
        lines = [f"rank {self.rank} of {len(self.names)} (rtol {self.rank_rtol:g}), condition number "
                 f"{self.condition_number:.3g} (identifiable subset: {self.condition_number_subset:.3g})"]
        for group in self.groups:
            lines.append("cannot tell apart: " + ", ".join(group))
        lines.append(f"meaningful: {', '.join(self.meaningful_names) or '(none)'}")
        return "\n".join(lines)


def _condition(s: np.ndarray, d: int) -> float:
    if d == 0 or s.size < d or s[-1] <= 0.0:  # d = 0: rank 0, no subset to condition (was an IndexError)
        return float("inf")
    return float(s[0] / s[-1])


def analyze_jacobian(J: np.ndarray, names: Sequence[str], *, noise: np.ndarray | float | None = None,
                     rank_rtol: float = 1e-6, max_std: float = 0.01,
                     participation: float = 0.05) -> IdentifiabilityReport:
    """Identifiability from a Jacobian J (m, d) w.r.t. unit-box parameters.

    noise: residual standard deviation, scalar or (m,) [residual units] (rows are
    divided by it). rank_rtol: relative singular-value threshold of the numerical rank;
    1e-6 sits 100x above the relative error of a finite-difference Jacobian (~1e-8 for
    forward steps of 1.5e-8, less for central) and far below any direction the data
    can resolve. max_std [fraction of range]: with noise, the largest acceptable
    standard deviation of a parameter or combination. participation: squared share of
    a parameter's direction in the weak subspace above which it counts as confounded.
    """
    J = np.asarray(J, float)
    m, d = J.shape
    names = tuple(names)
    if len(names) != d:
        raise ValueError(f"{len(names)} names for a Jacobian with {d} columns")
    if not np.all(np.isfinite(J)):
        raise ValueError("the Jacobian has non-finite entries: check the residuals near the solution")
    if noise is not None:
        sigma = np.broadcast_to(np.asarray(noise, float), (m,))
        if np.any(sigma <= 0):
            raise ValueError("noise standard deviations must be > 0")
        J = J / sigma[:, None]
    from scipy.linalg import qr

    # thin SVD: U is never used and a full one is (m, m) -- 26.8 GiB for a 20,000-posture file;
    # V must be square, which the thin form gives when m >= d (else the full form is small)
    _, s, Vt = np.linalg.svd(J, full_matrices=m < d)
    s_full = np.zeros(d)
    s_full[: s.size] = s
    scale = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > rank_rtol * scale))
    weak = s_full <= rank_rtol * scale
    if noise is not None:
        weak |= s_full < 1.0 / max_std
    V_weak = Vt[weak].T  # (d, n_weak)
    projector = V_weak @ V_weak.T
    confounded = np.diag(projector) >= participation
    groups = _connected_groups(np.abs(projector) >= participation, confounded)
    _, R, pivots = qr(J, mode="economic", pivoting=True)
    subset = pivots[:rank]
    s_sub = np.linalg.svd(J[:, subset], compute_uv=False) if rank else np.zeros(0)
    norms = np.linalg.norm(J, axis=0)
    unit = J / np.where(norms > 0, norms, 1.0)
    cosine = np.abs(unit.T @ unit)
    np.fill_diagonal(cosine, 0.0)
    std = None
    meaningful = ~confounded
    if noise is not None:
        # var_j = sum_k V_jk^2 / s_k^2; a null direction (s_k = 0) makes every parameter
        # that takes part in it (V_jk != 0) unbounded, and leaves the others alone
        weight = Vt.T ** 2
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            inverse = np.where(s_full > 0, 1.0 / s_full**2, np.inf)
            var = np.sum(np.where(weight > 0, weight * inverse, 0.0), axis=1)
        std = np.sqrt(var)
        meaningful &= std <= max_std
    return IdentifiabilityReport(
        names=names, jacobian=J, singular_values=s, rank=rank, rank_rtol=rank_rtol,
        condition_number=_condition(s, d), condition_number_subset=_condition(s_sub, rank),
        identifiable=tuple(names[i] for i in subset), groups=tuple(tuple(names[i] for i in g) for g in groups),
        parameter_std=std, meaningful=meaningful, column_norms=norms,
        max_cosine=cosine.max(axis=1) if d > 1 else np.zeros(d))


def _connected_groups(linked: np.ndarray, members: np.ndarray) -> list[list[int]]:
    """Connected components (size >= 1) among ``members`` of the graph ``linked`` (d, d)."""
    groups, seen = [], set()
    for start in np.flatnonzero(members):
        if start in seen:
            continue
        stack, component = [start], []
        seen.add(start)
        while stack:
            i = stack.pop()
            component.append(int(i))
            for j in np.flatnonzero(linked[i] & members):
                if j not in seen:
                    seen.add(j)
                    stack.append(j)
        groups.append(sorted(component))
    return groups


def identifiability(residuals: Callable[[np.ndarray], np.ndarray], x_unit: np.ndarray, names: Sequence[str], *,
                    noise: np.ndarray | float | None = None, fd_step: float = 1e-5, fd_scheme: str = "central",
                    rank_rtol: float = 1e-6, max_std: float = 0.01,
                    participation: float = 0.05) -> IdentifiabilityReport:
    """Identifiability of the parameters at x_unit (d,) from batched residuals.

    residuals: ``r(X (n, d)) -> (n, m)`` on the unit box. The Jacobian is taken by
    central differences with step ``fd_step`` (one batched call of 2d points; error
    ~ fd_step^2 relative for a smooth model, and a kink inside the step is averaged).
    See ``analyze_jacobian`` for the other arguments.
    """
    x = np.asarray(x_unit, float).reshape(-1)
    J, _ = batched_jacobian_fd(residuals, x, step=fd_step, scheme=fd_scheme)
    return analyze_jacobian(J, names, noise=noise, rank_rtol=rank_rtol, max_std=max_std,
                            participation=participation)
