"""The paper's three checks of the Sobol indices (Sec. 3.1).

1. ``sobol_convergence``: indices over growing N. One SALib sample at the largest N is
   drawn and evaluated once; the scrambled Sobol sequence is nested, so its first
   N (d + 2) rows are exactly SALib's sample at N and each smaller N costs no runs.
2. ``check_index_properties``: S_T >= S_1 >= 0 within the bootstrap confidence.
3. ``cross_validate``: the same indices from an independently generated sample, either
   with another scheme (``scipy.stats.sobol_indices``: its own A/B matrices, a
   mean-centred Saltelli-2010 / Jansen estimator) or SALib with another seed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from flexcal.calibration.sensitivity import (
    Evaluate,
    SobolResult,
    check_n_base,
    _evaluate_batched,
    _seed_of,
    analyze_outputs,
    make_problem,
    sobol_indices,
)

__all__ = [
    "ConvergenceReport",
    "sobol_convergence",
    "IndexViolation",
    "check_index_properties",
    "CrossValidation",
    "cross_validate",
]


@dataclass(frozen=True, kw_only=True)
class ConvergenceReport:
    """Indices at growing base sizes.

    n_values: (n_N,) base sizes; results: one ``SobolResult`` per N (the last is the
    full analysis); max_change: (n_N - 1,) max over outputs and parameters of
    |ST(N_i) - ST(N_{i-1})| [-]; tolerance: the accepted last change; converged:
    max_change[-1] <= tolerance; n_evaluations: runs of the model (= those of the largest N).
    """

    n_values: tuple[int, ...]
    results: tuple[SobolResult, ...]
    max_change: np.ndarray
    tolerance: float
    converged: bool
    n_evaluations: int

    @property
    def final(self) -> SobolResult:
        return self.results[-1]


def sobol_convergence(evaluate: Evaluate, problem_or_bounds, n_values: Sequence[int] = (64, 128, 256, 512), *,
                      seed, names: Sequence[str] | None = None, outputs: Sequence[str] | None = None,
                      tolerance: float = 0.02, chunk_size: int | None = None,
                      num_resamples: int = 100) -> ConvergenceReport:
    """Sobol indices at each N of ``n_values`` (powers of two, increasing) from one sample.

    tolerance: largest accepted change of any ST between the last two N [-]; 0.02 is
    about the 95 % confidence half-width of a total index at N = 512 for a smooth model
    (check ``final.ST_conf`` for yours).
    """
    from SALib.sample import sobol as sobol_sample

    n_values = tuple(int(n) for n in n_values)
    if len(n_values) < 2 or any(b <= a for a, b in zip(n_values, n_values[1:])):
        raise ValueError(f"n_values={n_values} must hold at least two increasing base sizes")
    for n in n_values:
        check_n_base(n)
    problem = make_problem(problem_or_bounds, names)
    seed = _seed_of(seed)
    d = problem["num_vars"]
    X = sobol_sample.sample(problem, n_values[-1], calc_second_order=False, scramble=True, seed=seed)
    Y = _evaluate_batched(evaluate, X, chunk_size)
    if outputs is None:
        outputs = ("y",) if Y.shape[1] == 1 else tuple(f"y{k + 1}" for k in range(Y.shape[1]))
    results = tuple(analyze_outputs(problem, Y[:n * (d + 2)], outputs=tuple(outputs), n_base=n, seed=seed,
                                    num_resamples=num_resamples) for n in n_values)
    change = np.array([np.max(np.abs(b.ST - a.ST)) for a, b in zip(results, results[1:])])
    return ConvergenceReport(n_values=n_values, results=results, max_change=change, tolerance=tolerance,
                             converged=bool(change[-1] <= tolerance), n_evaluations=X.shape[0])


@dataclass(frozen=True, kw_only=True)
class IndexViolation:
    """One breach of S_T >= S_1 >= 0 beyond the confidence half-widths.

    kind: "ST<0", "S1<0" or "S1>ST"; excess: by how much the bound is broken beyond
    the confidence [-].
    """

    output: str
    name: str
    kind: str
    excess: float


def check_index_properties(result: SobolResult, *, conf_factor: float = 1.0) -> tuple[IndexViolation, ...]:
    """Violations of S_T >= S_1 >= 0 beyond ``conf_factor`` x the 95 % half-widths.

    ST < -f ST_conf, S1 < -f S1_conf, S1 - ST > f (S1_conf + ST_conf). Empty = passed.
    """
    found = []
    for k, output in enumerate(result.outputs):
        for j, name in enumerate(result.names):
            s1, st = result.S1[k, j], result.ST[k, j]
            c1, ct = conf_factor * result.S1_conf[k, j], conf_factor * result.ST_conf[k, j]
            for kind, excess in (("ST<0", -st - ct), ("S1<0", -s1 - c1), ("S1>ST", s1 - st - c1 - ct)):
                if excess > 0:
                    found.append(IndexViolation(output=output, name=name, kind=kind, excess=float(excess)))
    return tuple(found)


@dataclass(frozen=True, kw_only=True)
class CrossValidation:
    """Indices of an independent sample against a reference.

    scheme: "scipy" or "salib"; ST_other: (k, d); abs_difference: (k, d) |ST - ST_other|;
    max_abs_difference; n_outside: how many |dST| exceed sqrt(2) x the reference's
    95 % half-width (two independent estimates of similar spread; about 5 % of the
    entries do by chance); n_evaluations: runs of the new sample.
    """

    scheme: str
    ST_other: np.ndarray
    S1_other: np.ndarray
    abs_difference: np.ndarray
    max_abs_difference: float
    n_outside: int
    n_evaluations: int


def cross_validate(evaluate: Evaluate, problem_or_bounds, reference: SobolResult, *, seed, scheme: str = "scipy",
                   names: Sequence[str] | None = None, chunk_size: int | None = None) -> CrossValidation:
    """Recompute ``reference``'s indices from an independent sample of the same size.

    scheme "scipy": ``scipy.stats.sobol_indices`` with uniform distributions on the
    bounds (a different sampler layout and estimator); "salib": SALib with ``seed``
    (must differ from the reference's). Costs another N (d + 2) runs.
    """
    problem = make_problem(problem_or_bounds, names)
    d, k = problem["num_vars"], len(reference.outputs)
    n = reference.n_base
    if scheme == "salib":
        seed = _seed_of(seed)
        if seed == reference.seed:
            raise ValueError(f"cross-validation seed {seed} equals the reference's: pass another seed")
        other = sobol_indices(evaluate, problem, n, seed=seed, outputs=reference.outputs, chunk_size=chunk_size)
        st, s1, n_eval = other.ST, other.S1, other.n_evaluations
    elif scheme == "scipy":
        from scipy import stats

        bounds = np.asarray(problem["bounds"], float)
        dists = [stats.uniform(loc=lo, scale=hi - lo) for lo, hi in bounds]
        counter = [0]

        def func(x):  # scipy passes (d, n) and wants (k, n)
            counter[0] += x.shape[1]
            return _evaluate_batched(evaluate, np.ascontiguousarray(x.T), chunk_size).T

        res = stats.sobol_indices(func=func, n=n, dists=dists, rng=np.random.default_rng(seed))
        st = np.asarray(res.total_order, float).reshape(k, d)
        s1 = np.asarray(res.first_order, float).reshape(k, d)
        n_eval = counter[0]
    else:
        raise ValueError(f"scheme={scheme!r} must be 'scipy' or 'salib'")
    diff = np.abs(reference.ST - st)
    outside = diff > np.sqrt(2.0) * reference.ST_conf
    return CrossValidation(scheme=scheme, ST_other=st, S1_other=s1, abs_difference=diff,
                           max_abs_difference=float(diff.max()), n_outside=int(outside.sum()), n_evaluations=n_eval)
