"""Sobol global sensitivity screening (paper Sec. 3.1, Eq. 9-12) through SALib.

``sobol_indices`` draws SALib's Saltelli/Sobol sample (first and total order only:
``calc_second_order=False`` is passed to both sampler and analyzer, whose default is
True), evaluates it in one batched call (or a few chunks), and runs one SALib analysis
per output (the overall fitness and, e.g., one per angle). The paper's three checks
(convergence over N, S_T >= S_1 >= 0 within confidence, cross-validation on an
independent sample) live in ``flexcal.calibration.sensitivity_checks``; the ranked
table, the Fig. 5-like figure and the choice of parameters to identify are here.

The problem is a SALib problem dict (``num_vars``, ``names``, ``bounds``) or a bounds
array (d, 2) plus ``names``; ``evaluate`` receives samples in those bounds' units.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

__all__ = [
    "SobolResult",
    "make_problem",
    "sobol_indices",
    "analyze_outputs",
    "ranked_table",
    "format_ranked_table",
    "select_parameters",
    "check_n_base",
]

Evaluate = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True, kw_only=True)
class SobolResult:
    """First-order and total Sobol indices of several outputs.

    names: (d,) parameter names; outputs: (k,) output names; S1, S1_conf, ST, ST_conf:
    (k, d) indices and the half-widths of their 95 % bootstrap confidence intervals
    (SALib, 100 resamples) [-]; n_base: N; n_evaluations: N (d + 2); seed: the sampler's.
    """

    names: tuple[str, ...]
    outputs: tuple[str, ...]
    S1: np.ndarray
    S1_conf: np.ndarray
    ST: np.ndarray
    ST_conf: np.ndarray
    n_base: int
    n_evaluations: int
    seed: int

    def output_index(self, output: str | int) -> int:
        """Row of ``output`` (name or index) in the (k, d) arrays."""
        if isinstance(output, (int, np.integer)):
            if not -len(self.outputs) <= output < len(self.outputs):
                raise ValueError(f"output index {output} out of range for {len(self.outputs)} outputs")
            return int(output) % len(self.outputs)
        if output not in self.outputs:
            raise ValueError(f"unknown output {output!r}; choose one of {list(self.outputs)}")
        return self.outputs.index(output)

    def normalized_ST(self) -> np.ndarray:
        """(k, d) total indices divided by their sum per output (paper Fig. 5) [-];
        negative estimates count as 0."""
        st = np.clip(self.ST, 0.0, None)
        total = st.sum(axis=1, keepdims=True)
        return np.divide(st, total, out=np.zeros_like(st), where=total > 0)


def make_problem(problem_or_bounds, names: Sequence[str] | None = None) -> dict:
    """A SALib problem dict from a dict (checked) or a (d, 2) bounds array + names."""
    if isinstance(problem_or_bounds, dict):
        problem = dict(problem_or_bounds)
        bounds = np.asarray(problem.get("bounds"), float)
        names = problem.get("names", names)
    else:
        bounds = np.asarray(problem_or_bounds, float)
    if bounds.ndim != 2 or bounds.shape[1] != 2 or bounds.shape[0] < 1:
        raise ValueError(f"bounds must have shape (d, 2), got {bounds.shape}")
    if not np.all(np.isfinite(bounds)) or np.any(bounds[:, 1] <= bounds[:, 0]):
        bad = np.flatnonzero(~(bounds[:, 1] > bounds[:, 0]))
        raise ValueError(f"bounds rows {bad.tolist()} must be finite with lower < upper")
    d = bounds.shape[0]
    names = tuple(names) if names is not None else tuple(f"x{i + 1}" for i in range(d))
    if len(names) != d or len(set(names)) != d:
        raise ValueError(f"need {d} distinct parameter names, got {len(names)} ({len(set(names))} distinct)")
    return {"num_vars": d, "names": list(names), "bounds": bounds.tolist()}


def check_n_base(n_base: int, *, name: str = "n_base") -> None:
    """The one rule on Sobol's base sample N (``sobol_indices``, ``--sobol-n``, a sweep's
    ``[identification] sobol_n``): a power of two >= 2, else one ValueError naming ``name``
    and the next power of two."""
    if n_base < 2 or n_base & (n_base - 1):
        suggestion = 1 << (max(n_base, 2) - 1).bit_length()
        raise ValueError(f"{name}={n_base} must be a power of two (e.g. {suggestion}): "
                         "the Sobol sequence loses its balance otherwise")


def _seed_of(seed) -> int:
    """A positive int seed (SALib's analyzer ignores a seed of 0 and falls back to the
    global numpy state, so 0 is never returned)."""
    if isinstance(seed, (int, np.integer)) and seed > 0:
        return int(seed)
    return int(np.random.default_rng(seed).integers(1, 2**31 - 1))


def _evaluate_batched(evaluate: Evaluate, X: np.ndarray, chunk_size: int | None) -> np.ndarray:
    """Y (n, k) from one call (or ceil(n / chunk_size) calls) of ``evaluate``."""
    n = X.shape[0]
    step = n if not chunk_size else int(chunk_size)
    parts = []
    for start in range(0, n, step):
        y = np.asarray(evaluate(X[start:start + step]), float)
        if y.shape[:1] != (min(step, n - start),):
            raise ValueError(f"evaluate returned shape {y.shape} for {min(step, n - start)} samples; "
                             "expected (n,) or (n, n_outputs)")
        parts.append(y.reshape(y.shape[0], -1))
    Y = np.concatenate(parts, axis=0)
    if not np.all(np.isfinite(Y)):
        rows = np.flatnonzero(~np.all(np.isfinite(Y), axis=1))
        raise ValueError(f"evaluate returned non-finite values for {rows.size} samples (first: row {rows[0]}, "
                         f"x = {X[rows[0]].tolist()}); fix the model or narrow the bounds")
    return Y


def analyze_outputs(problem: dict, Y: np.ndarray, *, outputs: Sequence[str], n_base: int, seed: int,
                    num_resamples: int = 100) -> SobolResult:
    """One SALib Sobol analysis per column of Y (n_base (d + 2), k) -> ``SobolResult``."""
    from SALib.analyze import sobol as sobol_analyze

    d = problem["num_vars"]
    if Y.shape != (n_base * (d + 2), len(outputs)):
        raise ValueError(f"Y has shape {Y.shape}, expected ({n_base * (d + 2)}, {len(outputs)})")
    fields = {key: np.zeros((len(outputs), d)) for key in ("S1", "S1_conf", "ST", "ST_conf")}
    for k in range(len(outputs)):
        if np.ptp(Y[:, k]) == 0.0:  # constant output: no variance to apportion
            continue
        res = sobol_analyze.analyze(problem, Y[:, k], calc_second_order=False, num_resamples=num_resamples,
                                    conf_level=0.95, seed=seed)
        for key in fields:
            fields[key][k] = res[key]
    return SobolResult(names=tuple(problem["names"]), outputs=tuple(outputs), n_base=n_base,
                       n_evaluations=n_base * (d + 2), seed=seed, **fields)


def sobol_indices(evaluate: Evaluate, problem_or_bounds, n_base: int = 512, *, seed,
                  names: Sequence[str] | None = None, outputs: Sequence[str] | None = None,
                  chunk_size: int | None = None, num_resamples: int = 100) -> SobolResult:
    """Total and first-order Sobol indices of every output of ``evaluate``.

    evaluate: ``X (n, d) -> Y (n,) or (n, k)``, X in the problem's bounds (units of the
    bounds); one call for the whole N (d + 2) sample unless ``chunk_size`` is given.
    problem_or_bounds: SALib problem dict or (d, 2) bounds (then ``names`` optional).
    n_base: N, a power of two (the paper's 500 -> 512: 512 * 47 = 24,064 runs for d = 45).
    seed: int / Generator / None -> the scrambled Sobol sequence and the bootstrap.
    outputs: names of the k output columns (default "y" or "y1".."yk").
    """
    from SALib.sample import sobol as sobol_sample

    check_n_base(n_base)
    problem = make_problem(problem_or_bounds, names)
    seed = _seed_of(seed)
    X = sobol_sample.sample(problem, n_base, calc_second_order=False, scramble=True, seed=seed)
    Y = _evaluate_batched(evaluate, X, chunk_size)
    if outputs is None:
        outputs = ("y",) if Y.shape[1] == 1 else tuple(f"y{k + 1}" for k in range(Y.shape[1]))
    outputs = tuple(outputs)
    if len(outputs) != Y.shape[1]:
        raise ValueError(f"evaluate returned {Y.shape[1]} outputs but {len(outputs)} names were given")
    return analyze_outputs(problem, Y, outputs=outputs, n_base=n_base, seed=seed, num_resamples=num_resamples)


def ranked_table(result: SobolResult, output: str | int = 0) -> list[dict]:
    """Parameters ranked by total index of ``output``, most sensitive first.

    Rows: ``{rank, name, ST, ST_conf, S1, S1_conf, ST_normalized}`` plus ``ST_<output>``
    of every output, for the report.
    """
    k = result.output_index(output)
    order = np.argsort(-result.ST[k], kind="stable")
    norm = result.normalized_ST()
    rows = []
    for rank, j in enumerate(order, start=1):
        row = {"rank": rank, "name": result.names[j], "ST": float(result.ST[k, j]),
               "ST_conf": float(result.ST_conf[k, j]), "S1": float(result.S1[k, j]),
               "S1_conf": float(result.S1_conf[k, j]), "ST_normalized": float(norm[k, j])}
        for kk, name in enumerate(result.outputs):
            row[f"ST_{name}"] = float(result.ST[kk, j])
        rows.append(row)
    return rows


def format_ranked_table(result: SobolResult, output: str | int = 0, max_rows: int | None = None) -> str:
    """The ranked table as Markdown (ST +- conf of the chosen output, then ST per output)."""
    rows = ranked_table(result, output)[:max_rows]
    head = ["rank", "parameter", "ST", "+-", "S1", "+-", "ST norm."] + [f"ST {o}" for o in result.outputs]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [str(r["rank"]), r["name"], f"{r['ST']:.4f}", f"{r['ST_conf']:.4f}", f"{r['S1']:.4f}",
                 f"{r['S1_conf']:.4f}", f"{r['ST_normalized']:.4f}"]
        cells += [f"{r[f'ST_{o}']:.4f}" for o in result.outputs]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def select_parameters(result: SobolResult, *, threshold: float = 0.01, cumulative: float | None = None,
                      outputs: Sequence[str | int] | None = None, always: Sequence[str] = (),
                      never: Sequence[str] = ()) -> tuple[str, ...]:
    """Names of the parameters worth identifying, in the problem's order.

    A parameter is kept if, for any of ``outputs`` (default: all), either
    - its total index ST >= ``threshold`` (an absolute share of that output's variance;
      0.01 = it explains at least 1 % of the variance alone or through interactions), or
    - ``cumulative`` is set and it is among the fewest top-ranked parameters whose
      normalized ST sum to at least ``cumulative`` (e.g. 0.95).
    Names in ``always`` are added (e.g. initial positions, which must be identified
    whatever their index); names in ``never`` removed.
    """
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"threshold={threshold} must be in [0, 1]")
    if cumulative is not None and not 0.0 < cumulative <= 1.0:
        raise ValueError(f"cumulative={cumulative} must be in (0, 1]")
    unknown = [n for n in (*always, *never) if n not in result.names]
    if unknown:
        raise ValueError(f"unknown parameter names {unknown}; known: {list(result.names)}")
    rows = [result.output_index(o) for o in (outputs if outputs is not None else range(len(result.outputs)))]
    keep = np.zeros(len(result.names), bool)
    norm = result.normalized_ST()
    for k in rows:
        keep |= result.ST[k] >= threshold
        if cumulative is not None:
            order = np.argsort(-norm[k], kind="stable")
            n_top = int(np.searchsorted(np.cumsum(norm[k, order]), cumulative - 1e-12) + 1)
            keep[order[:n_top]] = True
    for name in always:
        keep[result.names.index(name)] = True
    for name in never:
        keep[result.names.index(name)] = False
    return tuple(n for n, k in zip(result.names, keep) if k)
