"""Which unmodelled effect: term fits, leave-leg-out cross-validation, information
criteria, collinearity groups, ranking and the closure ratio (issue #7, docs/diagnosis.md).

The residual of the calibrated baseline, whitened by the per-channel noise floor, is
explained by ``J d + sum_t T_t(p_t)``: ``J`` the baseline's linearized Jacobian (its
correction ``d`` under a ridge prior, so every cross-validation fold refits the
baseline on its own training legs) and the candidate terms ``T_t`` of the effect library.
Terms that are linear in their parameters (checked numerically) are solved in closed
form; others by variable projection (``scipy.optimize.least_squares`` over the term
parameters, the linear part solved inside).

Held-out scoring leaves out whole trajectory legs (``leg_folds``), never single points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["FitProblem", "TermFit", "make_problem", "fit_terms", "leg_folds", "aicc", "bic", "cross_validate",
           "term_columns", "is_linear", "principal_cosines", "Candidate", "score_candidates", "CriterionSettings"]

LINEARITY_RTOL = 1e-6  # a term is linear if T(2 s) = 2 T(s) and T(s1+s2) = T(s1)+T(s2) to this relative error
TERM_PRIOR = 100.0  # weak ridge on term parameters [multiples of the term's scale]: only stops rank defects
# a term's own starting points (ModelTerm.starts) refined by least squares: the lowest-cost few,
# beside the five fixed starts (each refinement costs about one fixed start)
REFINED_TERM_STARTS = 3


def aicc(rss: float, n: int, k: int) -> float:
    """Corrected Akaike criterion of a Gaussian least-squares fit with unknown variance:
    n ln(RSS/n) + 2k + 2k(k+1)/(n-k-1) (Hurvich & Tsai 1989). rss: residual sum of squares,
    n: residuals, k: parameters."""
    if n - k - 1 <= 0:
        raise ValueError(f"AICc needs n - k - 1 > 0, got n={n}, k={k}")
    return n * np.log(rss / n) + 2 * k + 2 * k * (k + 1) / (n - k - 1)


def bic(rss: float, n: int, k: int) -> float:
    """Bayesian (Schwarz) criterion of the same fit: n ln(RSS/n) + k ln n."""
    return n * np.log(rss / n) + k * np.log(n)


def leg_folds(leg: np.ndarray, inputs: np.ndarray, direction: np.ndarray) -> tuple[list[np.ndarray], str]:
    """Held-out folds (list of (n,) bool masks, the points left out) and their unit.

    Unit "leg": every leg >= 1 is one fold (leg 0, the start point, is never left out).
    If leaving some leg out would leave an actuator that moves in it without any motion in
    the training legs (e.g. one cycle of the standard trajectory, one leg per actuator),
    the unit falls back to "stroke": contiguous runs between travel reversals, still never
    single points."""
    leg = np.asarray(leg)
    moving = np.abs(np.diff(inputs, axis=0, prepend=inputs[:1])) > 1e-9  # (n, 3) [m] moves of >1 nm
    folds = [leg == k for k in np.unique(leg) if k != 0]
    covered = all(not np.any(moving[f].any(axis=0) & ~moving[~f].any(axis=0)) for f in folds)
    if len(folds) >= 2 and covered:
        return folds, "leg"
    flips = np.any(np.diff(direction, axis=0) != 0, axis=1) | (np.diff(leg) != 0)
    run = np.concatenate([[0], np.cumsum(flips)])
    folds = [run == k for k in np.unique(run) if np.count_nonzero(run == k) >= 2]
    if len(folds) < 2:
        raise ValueError("the trajectory has fewer than two legs or strokes to leave out; held-out scoring "
                         "needs at least two (number the legs in the 'leg' column)")
    return folds, "stroke"


def term_columns(term, data, n_params: int | None = None) -> np.ndarray:
    """Linearized signature (n, 3, k) [rad per unit of term.scale] at zero parameters,
    by differences with the step ``term.scale``."""
    k = term.n_params if n_params is None else n_params
    base = term.evaluate(np.zeros(k), data)
    cols = [(term.evaluate(np.eye(k)[j] * term.scale, data) - base) for j in range(k)]
    return np.stack(cols, axis=-1)


def is_linear(term, data, columns: np.ndarray) -> bool:
    """True if the term is linear in its parameters (two numerical checks, LINEARITY_RTOL)."""
    k = term.n_params
    rng = np.random.default_rng(0)
    u = rng.normal(size=k)
    value = term.evaluate(u * term.scale, data)
    expected = columns @ u
    scale = max(np.abs(expected).max(), 1e-300)
    doubled = term.evaluate(2 * u * term.scale, data)
    return bool(np.abs(value - expected).max() <= LINEARITY_RTOL * scale
                and np.abs(doubled - 2 * expected).max() <= 2 * LINEARITY_RTOL * scale)


@dataclass(frozen=True, kw_only=True, eq=False)
class FitProblem:
    """The whitened data of the term fits (n points, m = 3 n rows).

    residual (n, 3) [rad] measured - baseline; sigma (3,) [rad] noise floor per channel;
    baseline (n, 3, p) [rad per unit box] linearized baseline; prior_sd (p,) [unit box];
    data: the ``TermData``; terms: {id: ModelTerm}; columns {id: (n, 3, k)} and linear {id: bool}
    (filled by ``make_problem``)."""

    residual: np.ndarray
    sigma: np.ndarray
    baseline: np.ndarray
    prior_sd: np.ndarray
    data: object
    terms: dict
    columns: dict
    linear: dict


def make_problem(residual, sigma, baseline_jacobian, prior_sd, data, terms: Sequence) -> FitProblem:
    columns, linear = {}, {}
    for term in terms:
        columns[term.id] = term_columns(term, data)
        linear[term.id] = is_linear(term, data, columns[term.id])
    return FitProblem(residual=np.asarray(residual, float), sigma=np.asarray(sigma, float),
                      baseline=np.asarray(baseline_jacobian, float), prior_sd=np.asarray(prior_sd, float),
                      data=data, terms={t.id: t for t in terms}, columns=columns, linear=linear)


@dataclass(frozen=True, kw_only=True, eq=False)
class TermFit:
    """params {id: (k,) [term units]}; correction (p,) [unit box]; explained (n, 3) [rad]:
    the fitted baseline correction plus terms at every point; terms_only (n, 3) [rad];
    chi2: whitened residual sum of squares over the training rows [-]; n_rows: rows."""

    params: dict
    correction: np.ndarray
    explained: np.ndarray
    terms_only: np.ndarray
    chi2: float
    n_rows: int


def _ridge_solver(A: np.ndarray, prior: np.ndarray):
    """b -> argmin ||A x - b||^2 + ||x / prior||^2 (ridge through an augmented least squares),
    for many b: the augmented matrix [A; diag(1/prior)] has full column rank (its ridge
    rows), so its QR factorization, made once, solves each b with one product and one
    triangular solve (the variable projection calls this ~100 times per fit: an SVD per
    call was ~80 % of a diagnosis)."""
    from scipy.linalg import get_lapack_funcs

    q, r = np.linalg.qr(np.vstack([A, np.diag(1.0 / prior)]))
    q_top = q[:A.shape[0]]  # the rows of [b; 0] that are not zero
    # LAPACK's triangular solve as scipy.linalg.solve_triangular(r, c) calls it (the same bits),
    # without its per-call checks and batching wrapper: ~1/4 of this solve's ~280,000 calls a
    # blind case takes (session 35)
    trtrs, = get_lapack_funcs(("trtrs",), (r,))
    a, lower, trans = (r, False, 0) if r.flags.f_contiguous else (r.T, True, 1)

    def solve(b):
        x, info = trtrs(a, q_top.T @ b, lower=lower, trans=trans)
        if info != 0:
            raise np.linalg.LinAlgError(f"the ridge solve failed (LAPACK trtrs info {info})")
        return x
    return solve


def fit_terms(problem: FitProblem, ids: Sequence[str], train: np.ndarray | None = None) -> TermFit:
    """Fit the baseline correction and the terms ``ids`` on the points ``train`` (n,) bool
    (all by default); predictions cover every point."""
    n = problem.residual.shape[0]
    train = np.ones(n, bool) if train is None else np.asarray(train, bool)
    w = 1.0 / problem.sigma  # whitening per channel
    J = problem.baseline * w[None, :, None]
    p = J.shape[-1]
    y = problem.residual * w
    lin = [i for i in ids if problem.linear[i]]
    nonlin = [i for i in ids if not problem.linear[i]]
    G = np.concatenate([problem.columns[i] * w[None, :, None] for i in lin], axis=-1) if lin else np.zeros((n, 3, 0))
    A = np.concatenate([J, G], axis=-1)
    prior = np.concatenate([problem.prior_sd, np.full(G.shape[-1], TERM_PRIOR)])

    def nonlinear_part(u_all):
        out, start = np.zeros((n, 3)), 0
        for i in nonlin:
            term = problem.terms[i]
            out += term.evaluate(u_all[start:start + term.n_params] * term.scale, problem.data)
            start += term.n_params
        return out

    A_train = A[train].reshape(-1, A.shape[-1])
    solve_ridge = _ridge_solver(A_train, prior)

    def solve(u_all):
        rhs = (y - nonlinear_part(u_all) * w)[train].reshape(-1)
        x = solve_ridge(rhs)
        return x, rhs - A_train @ x, x / prior

    u = np.zeros(sum(problem.terms[i].n_params for i in nonlin))
    if nonlin:
        from scipy.optimize import least_squares

        # zero (effect absent) is often a saddle of a nonlinear term (amplitude 0 hides the
        # rate), so start also from +-1 scale and two seeded draws, keep the best
        starts = [u, u + 1.0, u - 1.0, *np.random.default_rng(0).normal(size=(2, u.size))]

        def cost(v):
            return np.concatenate([*solve(v)[1:], v / TERM_PRIOR])

        starts += _term_starts(problem, nonlin, lambda v: float(np.sum(cost(v) ** 2)))
        fits = [least_squares(cost, s0, method="trf") for s0 in starts]
        u = min(fits, key=lambda f: f.cost).x
    x, res, _ = solve(u)
    params, start_lin, start_non = {}, p, 0
    for i in ids:
        term = problem.terms[i]
        if problem.linear[i]:
            params[i] = x[start_lin:start_lin + term.n_params] * term.scale
            start_lin += term.n_params
        else:
            params[i] = u[start_non:start_non + term.n_params] * term.scale
            start_non += term.n_params
    terms_only = (G @ x[p:]) / w + nonlinear_part(u)
    explained = (J @ x[:p]) / w + terms_only
    return TermFit(params=params, correction=x[:p], explained=explained, terms_only=terms_only,
                   chi2=float(res @ res), n_rows=int(res.size))


def _term_starts(problem: FitProblem, nonlin: Sequence[str], cost) -> list[np.ndarray]:
    """The ``REFINED_TERM_STARTS`` lowest-``cost`` starts (vectors over the parameters of all
    of ``nonlin``, in units of scale) among the terms' own (``ModelTerm.starts``; the other
    terms' parameters at zero)."""
    sizes = [problem.terms[i].n_params for i in nonlin]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    candidates = []
    for i, start in zip(nonlin, offsets[:-1]):
        term = problem.terms[i]
        if term.starts is None:
            continue
        for row in np.asarray(term.starts(problem.data), float):
            u = np.zeros(offsets[-1])
            u[start:start + term.n_params] = row
            candidates.append(u)
    if not candidates:
        return []
    costs = [cost(u) for u in candidates]
    return [candidates[j] for j in np.argsort(costs, kind="stable")[:REFINED_TERM_STARTS]]


def cross_validate(problem: FitProblem, ids: Sequence[str], folds: Sequence[np.ndarray]) -> np.ndarray:
    """Held-out residuals (n, 3) [rad]: each fold's points predicted by the fit on the others
    (points in no fold keep NaN)."""
    out = np.full(problem.residual.shape, np.nan)
    for fold in folds:
        fit = fit_terms(problem, ids, train=~fold)
        out[fold] = problem.residual[fold] - fit.explained[fold]
    return out


def principal_cosines(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Cosines of the principal angles between the column spaces of A (m, a) and B (m, b),
    largest first (1 = a shared direction)."""
    A = A[:, np.linalg.norm(A, axis=0) > 0]  # a zero column (a parameter with no effect at zero) spans nothing
    B = B[:, np.linalg.norm(B, axis=0) > 0]
    qa = np.linalg.qr(A)[0] if A.shape[1] else np.zeros((A.shape[0], 0))
    qb = np.linalg.qr(B)[0] if B.shape[1] else np.zeros((B.shape[0], 0))
    if qa.shape[1] == 0 or qb.shape[1] == 0:
        return np.zeros(0)
    return np.clip(np.linalg.svd(qa.T @ qb, compute_uv=False), 0.0, 1.0)


@dataclass(frozen=True, kw_only=True)
class CriterionSettings:
    """When a term earns its parameters: BIC lower by ``min_delta_bic`` [-] than without it,
    held-out closure >= ``min_closure`` [-] and held-out mean square lower by
    ``min_gain_noise`` noise variances [-] (all three; calibrated on ``none`` data,
    docs/diagnosis.md). group_ratio [-]: a term that explains this share of the winner's
    in-sample and held-out gain is reported in the winner's group. confident_closure [-]:
    a winner is claimed with confidence only if it closes this share of the held-out gap."""

    min_delta_bic: float = 10.0
    min_closure: float = 0.25
    min_gain_noise: float = 1.0
    group_ratio: float = 0.9
    confident_closure: float = 0.7


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """The evidence on one term added to ``accepted``. Mean squares per angle [rad^2]."""

    id: str
    n_params: int
    chi2: float
    delta_aicc: float
    delta_bic: float
    heldout_ms_before: np.ndarray
    heldout_ms_after: np.ndarray
    closure: float
    gain_noise: float
    significant: bool


def _closure(before: np.ndarray, after: np.ndarray, sigma: np.ndarray) -> float:
    gap = np.sum(np.maximum(before - sigma**2, 0.0))
    return float((np.sum(before) - np.sum(after)) / gap) if gap > 0 else 0.0


def score_candidates(problem: FitProblem, accepted: Sequence[str], candidates: Sequence[str],
                     folds: Sequence[np.ndarray], settings: CriterionSettings,
                     k_baseline: float, min_gain: dict | None = None) -> tuple[list[Candidate], np.ndarray]:
    """Score each candidate added to ``accepted``; returns (candidates best first by held-out
    closure, held-out mean square (3,) [rad^2] of ``accepted`` alone). min_gain {id: noise
    variances}: a term's own gain threshold (the trajectory's null, ``diagnosis.null``),
    ``settings.min_gain_noise`` for the others."""
    min_gain = min_gain or {}
    n = problem.residual.size
    base_fit = fit_terms(problem, accepted)
    k0 = k_baseline + sum(problem.terms[i].n_params for i in accepted)
    cv0 = cross_validate(problem, accepted, folds)
    ms0 = np.nanmean(cv0**2, axis=0)
    out = []
    for cid in candidates:
        fit = fit_terms(problem, [*accepted, cid])
        k = problem.terms[cid].n_params
        cv = cross_validate(problem, [*accepted, cid], folds)
        ms = np.nanmean(cv**2, axis=0)
        d_aicc = aicc(fit.chi2, n, int(round(k0 + k))) - aicc(base_fit.chi2, n, int(round(k0)))
        d_bic = bic(fit.chi2, n, int(round(k0 + k))) - bic(base_fit.chi2, n, int(round(k0)))
        closure = _closure(ms0, ms, problem.sigma)
        gain = float(np.sum(ms0 - ms) / np.mean(problem.sigma**2))
        significant = bool(d_bic <= -settings.min_delta_bic and closure >= settings.min_closure
                           and gain >= min_gain.get(cid, settings.min_gain_noise))
        out.append(Candidate(id=cid, n_params=k, chi2=fit.chi2, delta_aicc=float(d_aicc), delta_bic=float(d_bic),
                             heldout_ms_before=ms0, heldout_ms_after=ms, closure=closure, gain_noise=gain,
                             significant=significant))
    out.sort(key=lambda c: (-c.closure, c.delta_bic))
    return out, ms0
