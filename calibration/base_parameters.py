"""Base parameters: the combinations of error sources that the data identify.

Robot calibration's regrouping (Gautier & Khalil; figaroh's pivoted-QR base parameters):
with the data Jacobian ``W = J / sigma`` [noise units per range] (m, d), QR with column
pivoting ``W P = Q R`` puts first the columns the data see best. The first ``r`` pivots are
the *base* sources, where ``r`` counts the pivots whose conditional standard deviation
``1/|R_kk|`` (that of source k with the earlier pivots known) is at most ``max_std`` of its
range. Every other column is, within the noise, a combination of the base columns,
``W_2 ~ W_1 B`` with ``B = R_11^-1 R_12``, so the data see only

    beta_k = x_k + sum_j B_kj x_j          (k base, j regrouped; unit-box coordinates)

and the regrouped ``x_j`` are fixed at their prior. The pivoting is our own modified
Gram-Schmidt so that ties (columns whose remaining norms agree to ``tie_rtol``) go to the
lower index, in the parameter space's order: the same data give the same base on every
machine (LAPACK's pivoting breaks ties by rounding).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["BaseParameters", "base_parameters", "pivoted_qr"]


def pivoted_qr(W: np.ndarray, *, tie_rtol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Q (m, d'), R (d', d), pivots (d,)) with ``W[:, pivots] = Q R``, d' = min(m, d).

    Greedy column pivoting on the remaining norms; a column whose norm is within
    ``tie_rtol`` (relative) of the largest is preferred when its index is lower.
    """
    A = np.array(W, float)
    m, d = A.shape
    k_max = min(m, d)
    pivots = np.arange(d)
    Q = np.zeros((m, k_max))
    R = np.zeros((k_max, d))
    for k in range(k_max):
        norms = np.linalg.norm(A[:, k:], axis=0)
        top = norms.max()
        # lowest original index among the (near-)largest remaining columns
        near = np.flatnonzero(norms >= top * (1.0 - tie_rtol))
        j = k + near[np.argmin(pivots[k + near])]
        A[:, [k, j]], R[:, [k, j]], pivots[[k, j]] = A[:, [j, k]], R[:, [j, k]], pivots[[j, k]]
        if top <= 0.0:
            break
        q = A[:, k] / norms[j - k]
        Q[:, k] = q
        R[k, k] = norms[j - k]
        R[k, k + 1:] = q @ A[:, k + 1:]
        A[:, k + 1:] -= np.outer(q, R[k, k + 1:])
        A[:, k] = 0.0
    return Q, R, pivots


@dataclass(frozen=True, kw_only=True)
class BaseParameters:
    """base: names of the base sources (pivot order); regrouped: names of the others;
    coefficients (n_base, n_regrouped): B, beta_k = x_k + sum_j B_kj x_j [unit box];
    conditional_std (n_base,) [fraction of range]: 1/|R_kk|; labels: readable combinations
    ("L1.t1 + 0.8 L1.w"); max_std the threshold used."""

    base: tuple[str, ...]
    regrouped: tuple[str, ...]
    coefficients: np.ndarray
    conditional_std: np.ndarray
    labels: tuple[str, ...]
    max_std: float

    @property
    def n_base(self) -> int:
        return len(self.base)

    def values(self, x: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """beta (..., n_base) [unit box] from x (..., d) over ``names``."""
        x = np.asarray(x, float)
        index = {n: i for i, n in enumerate(names)}
        x_base = x[..., [index[n] for n in self.base]]
        if not self.regrouped:
            return x_base
        return x_base + x[..., [index[n] for n in self.regrouped]] @ self.coefficients.T

    def combinations(self, names: Sequence[str]) -> np.ndarray:
        """C (n_base, d) over ``names``: beta = C x [unit box] (1 at the base source, B at the
        regrouped ones)."""
        index = {n: i for i, n in enumerate(names)}
        C = np.zeros((self.n_base, len(names)))
        for k, name in enumerate(self.base):
            C[k, index[name]] = 1.0
            for j, other in enumerate(self.regrouped):
                C[k, index[other]] = self.coefficients[k, j]
        return C

    def reported_combinations(self, names: Sequence[str], min_coefficient: float = 0.05) -> np.ndarray:
        """C (n_base, d) as the reports give the base parameters: a source identified alone
        (``pure``) is the source itself (its row 1 at the source, 0 elsewhere), so that it has
        one value and one error bar, the same as in the sources' table (its regrouped terms
        are below ``min_coefficient`` and its label names it alone); the others as
        ``combinations``."""
        C = self.combinations(names)
        index = {n: i for i, n in enumerate(names)}
        for k, name in enumerate(self.base):
            if name in self.pure(min_coefficient):
                C[k] = 0.0
                C[k, index[name]] = 1.0
        return C

    def pure(self, min_coefficient: float = 0.05) -> tuple[str, ...]:
        """Base sources identified alone: no regrouped source enters their combination with a
        coefficient of ``min_coefficient`` or more (range units): their own value is meaningful."""
        if not self.regrouped:
            return self.base
        small = np.all(np.abs(self.coefficients) < min_coefficient, axis=1)
        return tuple(n for n, ok in zip(self.base, small) if ok)

    def as_dict(self) -> dict:
        return {"base": list(self.base), "regrouped": list(self.regrouped), "labels": list(self.labels),
                "conditional_std_of_range": self.conditional_std.tolist(), "max_std_of_range": self.max_std,
                "coefficients_unit_box": self.coefficients.tolist()}


def _label(name: str, coefficients: np.ndarray, regrouped: Sequence[str], min_coefficient: float) -> str:
    terms = [name]
    order = np.argsort(-np.abs(coefficients), kind="stable")
    for j in order:
        c = coefficients[j]
        if abs(c) < min_coefficient:
            break
        terms.append(f"{'-' if c < 0 else '+'} {abs(c):.2g} {regrouped[j]}")
    return " ".join(terms)


def base_parameters(W: np.ndarray, names: Sequence[str], *, max_std: float = 0.01, min_coefficient: float = 0.05,
                    tie_rtol: float = 1e-9) -> BaseParameters:
    """Base sources and regrouping coefficients of the data Jacobian W (m, d) [noise units per
    range] (rows divided by the noise, columns by the ranges: ``J / sigma`` on the unit box).

    max_std [fraction of range]: a pivot is a base source when the data alone pin it to this
    (1 % of a range: the threshold of ``identifiability``); min_coefficient: terms of a label
    smaller than this (in unit-box units) are left out of the label (never out of B).
    """
    W = np.asarray(W, float)
    names = tuple(names)
    if W.ndim != 2 or W.shape[1] != len(names):
        raise ValueError(f"W must be (m, {len(names)}), got {W.shape}")
    if not np.all(np.isfinite(W)):
        raise ValueError("the Jacobian has non-finite entries")
    _, R, pivots = pivoted_qr(W, tie_rtol=tie_rtol)
    diagonal = np.abs(np.diag(R))
    with np.errstate(divide="ignore"):
        conditional = np.where(diagonal > 0, 1.0 / diagonal, np.inf)
    # pivots come in decreasing remaining norm, so the base is a prefix
    r = int(np.argmax(conditional > max_std)) if np.any(conditional > max_std) else diagonal.size
    base_index, other_index = pivots[:r], pivots[r:]
    if r and other_index.size:
        from scipy.linalg import solve_triangular

        B = solve_triangular(R[:r, :r], R[:r, r:])
    else:
        B = np.zeros((r, other_index.size))
    regrouped = tuple(names[j] for j in other_index)
    labels = tuple(_label(names[i], B[k], regrouped, min_coefficient) for k, i in enumerate(base_index))
    return BaseParameters(base=tuple(names[i] for i in base_index), regrouped=regrouped, coefficients=B,
                          conditional_std=conditional[:r], labels=labels, max_std=max_std)
