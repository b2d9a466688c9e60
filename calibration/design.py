"""Designed calibration measurements: D-optimal postures for the MAP identification.

The standard trajectory drives one actuator at a time; its Jacobian has rank 22 of 45 and
it never unloads the tip/tilt drives. Here the postures are chosen to make the sources
identifiable, before anything is measured:

- candidates: ``n_candidates`` postures drawn uniformly inside the angular workspace
  (+-1, +-5, +-3 mrad; ``model.trajectory.WORKSPACE``), mapped to actuator inputs by the
  nominal linear gain, so every combination of the three actuators is available;
- each candidate's Jacobian ``J_c`` (3, d) of the model angles with respect to the unit-box
  sources, at the design point (the prior mean: every source mid-range), divided by the
  noise: rows in noise units per range;
- the prior-weighted information matrix ``M = diag(prior precision) + sum_c J_c^T J_c``; the
  D-criterion ``log det M`` (the log volume of the posterior confidence ellipsoid, negated)
  is maximized by greedy selection (rank-3 updates: ``log det(I + J_c M^-1 J_c^T)``) and then
  Fedorov exchange passes until no swap improves it; a posture may be chosen twice
  (replication is a legitimate optimum);
- the chosen postures are put in a nearest-neighbour tour from the zero posture, so that each
  actuator reverses many times and both travel directions occur (the model used here does
  not depend on the direction, the hardware's backlash does), cut into legs of
  ``points_per_leg`` for held-out cross-validation.

- what the model cannot do: with an ``inadequacy`` (the model's expected error at each
  candidate, e.g. against a richer virtual prototype) the postures weigh by
  sqrt(noise^2 + delta^2), and with ``max_inadequacy`` the candidates whose expected error
  exceeds it (on any angle) are not offered at all: the CLI sets it to the upper quartile of
  the expected error over the standard trajectory's own postures, so a design never measures
  where the model is known to be worse than on most of the standard trajectory. A model-form error
  there is not noise that averages out: the fit absorbs it into the sources (a bias the
  information matrix does not see), so the D-criterion alone seeks exactly those postures
  (largest signatures at the workspace corners, where the model is worst);
- other criteria, by the same greedy + exchange: "I" (trace M^-1 A, A the mean information of
  postures to be predicted) and "drives" (A diagonal: (range / figure)^2 on chosen sources, e.g.
  the drive sources and their paper Table 1 figures: ``figure_weights``; the sum of their expected
  variances in units of their figures, A-optimality);

The design is local (at one parameter point) like any nonlinear D-optimal design; the
report gives the criterion, sigma_min, the condition number and the expected standard
error of every source against the standard trajectory at the same point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["candidate_postures", "candidate_inputs", "REGIONS", "CRITERIA", "d_criterion", "i_criterion",
           "greedy_d_optimal", "greedy_i_optimal", "figure_weights", "order_postures", "DesignQuality",
           "design_quality", "Design", "design_trajectory"]

REGIONS = ("workspace", "box", "hull")  # where candidates are drawn (candidate_inputs)
CRITERIA = ("D", "I", "drives")  # design_trajectory's criteria


def candidate_postures(angle_gain: np.ndarray, workspace: np.ndarray, n_candidates: int,
                       rng: np.random.Generator | int | None = None) -> np.ndarray:
    """(n_candidates, 3) actuator inputs [m] whose nominal linear angles fall uniformly inside
    the box +-workspace (3,) [rad]; angle_gain (3 angles, 3 actuators) [rad/m]."""
    if n_candidates < 1:
        raise ValueError(f"n_candidates={n_candidates} must be >= 1")
    rng = np.random.default_rng(rng)
    angles = rng.uniform(-1.0, 1.0, size=(n_candidates, 3)) * np.asarray(workspace, float)
    return np.linalg.solve(np.asarray(angle_gain, float), angles.T).T


def candidate_inputs(box: np.ndarray, n_candidates: int, region: str = "box",
                     rng: np.random.Generator | int | None = None) -> np.ndarray:
    """(n_candidates, 3) actuator inputs [m] drawn uniformly in the input box +-box (3,) [m]
    (``region`` "box": every combination of the three strokes) or in its inscribed octahedron
    sum_i |x_i / box_i| <= 1 ("hull": the convex hull of postures that move one actuator at a
    time up to +-box_i, as the standard trajectory does)."""
    if n_candidates < 1:
        raise ValueError(f"n_candidates={n_candidates} must be >= 1")
    if region not in ("box", "hull"):
        raise ValueError(f"region={region!r} must be 'box' or 'hull'")
    rng = np.random.default_rng(rng)
    box = np.asarray(box, float)
    if region == "box":
        return rng.uniform(-1.0, 1.0, size=(n_candidates, 3)) * box
    # uniform in the L1 ball: Dirichlet(1,1,1,1) weights (the 4th the slack), random signs
    weights = rng.dirichlet(np.ones(4), size=n_candidates)[:, :3]
    signs = rng.choice((-1.0, 1.0), size=(n_candidates, 3))
    return weights * signs * box


def d_criterion(J: np.ndarray, prior_precision: np.ndarray) -> float:
    """log det(J^T J + diag(prior_precision)); J (m, d) in noise units per range."""
    sign, value = np.linalg.slogdet(J.T @ J + np.diag(prior_precision))
    return float(value) if sign > 0 else -np.inf


def i_criterion(J: np.ndarray, prior_precision: np.ndarray, A: np.ndarray) -> float:
    """trace(M^-1 A), M = J^T J + diag(prior_precision): the mean prediction variance [noise^2]
    over the postures whose mean information is A (d, d) (I-optimality; lower is better)."""
    M = J.T @ J + np.diag(prior_precision)
    return float(np.trace(np.linalg.solve(M, A)))


def figure_weights(names, spans: np.ndarray, figures: dict[str, float]) -> np.ndarray:
    """A (d, d) for ``i_criterion`` / ``greedy_i_optimal`` that makes trace(M^-1 A) the sum, over the
    sources named in ``figures``, of (expected standard error / that source's figure)^2 (A-optimality
    on those sources, each in units of its own figure): diagonal, (span / figure)^2 at each named
    source's place in ``names`` (d,), zero elsewhere. spans (d,) [SI] the sources' ranges (upper -
    lower: M is in unit-box coordinates, so a unit-box variance is multiplied by span^2); figures
    {name: figure [SI] > 0}, every name among ``names``."""
    names = list(names)
    spans = np.asarray(spans, float)
    if spans.shape != (len(names),):
        raise ValueError(f"spans {spans.shape} must be ({len(names)},), one per name")
    missing = [n for n in figures if n not in names]
    if missing:
        raise ValueError(f"sources {missing} of the figures are not among the design's sources")
    weights = np.zeros(len(names))
    for name, figure in figures.items():
        if not figure > 0:
            raise ValueError(f"the figure of {name} must be > 0, got {figure!r}")
        i = names.index(name)
        weights[i] = (spans[i] / figure) ** 2
    return np.diag(weights)


def _i_gains(J_candidates: np.ndarray, M_inverse: np.ndarray, A: np.ndarray) -> np.ndarray:
    """The decrease of trace(M^-1 A) from adding each candidate (rank-3 Woodbury update), (n,):
    trace((I + J_c M^-1 J_c^T)^-1 J_c M^-1 A M^-1 J_c^T)."""
    JM = J_candidates @ M_inverse  # (n, k, d)
    S = JM @ J_candidates.transpose(0, 2, 1) + np.eye(J_candidates.shape[1])
    G = (JM @ A) @ JM.transpose(0, 2, 1)
    return np.trace(np.linalg.solve(S, G), axis1=1, axis2=2)


def greedy_i_optimal(J_candidates: np.ndarray, prior_precision: np.ndarray, n_select: int, A: np.ndarray, *,
                     fixed: np.ndarray | None = None, max_passes: int = 10,
                     progress: Callable[[str], None] | None = None) -> tuple[np.ndarray, float]:
    """Indices (n_select,) of candidates minimizing trace(M^-1 A) (``i_criterion``), and that
    value; the arguments and the greedy + Fedorov exchange passes as ``greedy_d_optimal``."""
    # a swap must lower the (positive) criterion by a relative 1e-9 (+1e-12 near zero)
    chosen, M = _greedy_exchange(J_candidates, prior_precision, n_select, lambda J, M_inv: _i_gains(J, M_inv, A),
                                 lambda new, old: new > old * (1 + 1e-9) + 1e-12, fixed=fixed, max_passes=max_passes,
                                 progress=progress, criterion="an I-optimal")
    return chosen, float(np.trace(np.linalg.solve(M, A)))


def _gains(J_candidates: np.ndarray, M_inverse: np.ndarray) -> np.ndarray:
    """log det(I_3 + J_c M^-1 J_c^T) for every candidate, (n,)."""
    S = (J_candidates @ M_inverse) @ J_candidates.transpose(0, 2, 1)  # batched BLAS, not a 4-index einsum
    S += np.eye(J_candidates.shape[1])
    sign, value = np.linalg.slogdet(S)
    return np.where(sign > 0, value, -np.inf)


def greedy_d_optimal(J_candidates: np.ndarray, prior_precision: np.ndarray, n_select: int, *,
                     fixed: np.ndarray | None = None, max_passes: int = 10,
                     progress: Callable[[str], None] | None = None) -> tuple[np.ndarray, float]:
    """Indices (n_select,) of candidates maximizing log det M, and that value.

    J_candidates (n, k, d) [noise units per range]: k rows per candidate posture;
    prior_precision (d,) [1/range^2 in unit-box units, > 0 keeps M invertible]; fixed
    (k', d): rows always measured (e.g. the start posture). Greedy forward selection, then
    Fedorov exchange passes (each selected posture swapped for the best candidate when that
    raises log det M by more than 1e-9) until a pass changes nothing or ``max_passes``.
    """
    chosen, M = _greedy_exchange(J_candidates, prior_precision, n_select, _gains, lambda new, old: new > old + 1e-9,
                                 fixed=fixed, max_passes=max_passes, progress=progress, criterion="a D-optimal")
    sign, value = np.linalg.slogdet(M)
    return chosen, float(value)


def _greedy_exchange(J_candidates: np.ndarray, prior_precision: np.ndarray, n_select: int,
                     gains: Callable[[np.ndarray, np.ndarray], np.ndarray], better: Callable[[float, float], bool], *,
                     fixed: np.ndarray | None, max_passes: int, progress: Callable[[str], None] | None,
                     criterion: str) -> tuple[np.ndarray, np.ndarray]:
    """The selection both criteria share: greedy forward selection of the candidate with the
    largest ``gains(J_candidates, M^-1)``, then Fedorov exchange passes (a selected posture is
    swapped for the best candidate when ``better(its gain, the selected one's)``) until a pass
    changes nothing or ``max_passes``. Returns the indices (n_select,) and M (d, d)."""
    J_candidates = np.asarray(J_candidates, float)
    n, _, d = J_candidates.shape
    if n_select < 1:
        raise ValueError(f"n_select={n_select} must be >= 1")
    precision = np.asarray(prior_precision, float)
    if precision.shape != (d,) or np.any(precision <= 0):
        raise ValueError(f"prior_precision must be (d,) and > 0 ({criterion} design needs an invertible start)")
    M = np.diag(precision)
    if fixed is not None:
        M = M + fixed.T @ fixed
    contributions = J_candidates.transpose(0, 2, 1) @ J_candidates  # (n, d, d)
    chosen = []
    for _ in range(n_select):
        best = int(np.argmax(gains(J_candidates, np.linalg.inv(M))))
        chosen.append(best)
        M = M + contributions[best]
    chosen = np.array(chosen)
    for pass_number in range(max_passes):
        swaps = 0
        for position in range(n_select):
            M_without = M - contributions[chosen[position]]
            gain = gains(J_candidates, np.linalg.inv(M_without))
            best = int(np.argmax(gain))
            if best != chosen[position] and better(gain[best], gain[chosen[position]]):
                chosen[position] = best
                M = M_without + contributions[best]
                swaps += 1
        if progress is not None:
            progress(f"exchange pass {pass_number + 1}: {swaps} swaps")
        if swaps == 0:
            break
    return chosen, M


def order_postures(inputs: np.ndarray, scale: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
    """Visiting order (n,) of the postures inputs (n, 3) [m]: a nearest-neighbour tour (in
    inputs divided by ``scale`` (3,) [m]) from ``start`` (3,) (default the zero posture)."""
    points = np.asarray(inputs, float) / np.asarray(scale, float)
    current = np.zeros(3) if start is None else np.asarray(start, float) / scale
    left = list(range(points.shape[0]))
    order = []
    while left:
        distance = np.linalg.norm(points[left] - current, axis=1)
        pick = left.pop(int(np.argmin(distance)))
        order.append(pick)
        current = points[pick]
    return np.array(order, dtype=int)


@dataclass(frozen=True, kw_only=True)
class DesignQuality:
    """Of one trajectory at the design point: d_criterion log det M; d_efficiency
    det(M)^(1/d); sigma_min, condition_number of the data-only Jacobian W (noise units per
    range; inf when rank-deficient); rank of W (relative threshold 1e-6, as in
    ``identifiability``); expected_std (d,) [fraction of range] sqrt(diag M^-1) with the prior."""

    d_criterion: float
    d_efficiency: float
    sigma_min: float
    condition_number: float
    rank: int
    expected_std: np.ndarray


def design_quality(W: np.ndarray, prior_precision: np.ndarray) -> DesignQuality:
    """Quality figures of a trajectory whose data Jacobian is W (m, d) [noise units per range]."""
    W = np.asarray(W, float)
    d = W.shape[1]
    M = W.T @ W + np.diag(prior_precision)
    s = np.linalg.svd(W, compute_uv=False)
    s_full = np.zeros(d)
    s_full[: s.size] = s
    rank = int(np.sum(s_full > 1e-6 * max(s_full[0], 1e-300)))
    value = d_criterion(W, prior_precision)
    return DesignQuality(d_criterion=value, d_efficiency=float(np.exp(value / d)), sigma_min=float(s_full[-1]),
                         condition_number=float(s_full[0] / s_full[-1]) if s_full[-1] > 0 else float("inf"),
                         rank=rank, expected_std=np.sqrt(np.diag(np.linalg.inv(M))))


@dataclass(frozen=True, kw_only=True)
class Design:
    """A designed trajectory: inputs (n, 3) [m] in visiting order (the zero posture first);
    leg (n,) legs of ``points_per_leg`` (held-out folds); candidates (n_c, 3) [m]; chosen
    (n - 1,) indices into them (visiting order); quality and reference_quality: the
    ``DesignQuality`` of this trajectory and of the reference one (the standard trajectory)
    at the same design point, noise and prior; noise [rad]; prior_scale; inadequacy (n_c, 3)
    [rad] or None: the model's expected error at each candidate, added to the noise; avoided
    (n_c,) bool or None: candidates not offered because their expected error exceeds
    max_inadequacy [rad]."""

    inputs: np.ndarray
    leg: np.ndarray
    candidates: np.ndarray
    chosen: np.ndarray
    quality: DesignQuality
    reference_quality: DesignQuality
    noise: float
    prior_scale: float
    inadequacy: np.ndarray | None
    avoided: np.ndarray | None = None
    max_inadequacy: float | None = None


def design_trajectory(jacobian: Callable[[np.ndarray], np.ndarray], angle_gain: np.ndarray, workspace: np.ndarray,
                      reference_inputs: np.ndarray, *, n_points: int = 77, n_candidates: int = 2000,
                      noise: float = 0.5e-6, prior_precision: np.ndarray, prior_scale: float = 1.0,
                      points_per_leg: int = 11, inadequacy: Callable[[np.ndarray], np.ndarray] | None = None,
                      max_inadequacy: float | None = None, rng: np.random.Generator | int | None = 0,
                      progress: Callable[[str], None] | None = None, region: str = "workspace",
                      box: np.ndarray | None = None, criterion: str = "D",
                      prediction_inputs: np.ndarray | None = None, variance_weights: np.ndarray | None = None,
                      fixed_inputs: np.ndarray | None = None, fixed_leg: np.ndarray | None = None) -> Design:
    """D-optimal trajectory of ``n_points`` postures (the zero posture first, then n - 1 chosen).

    jacobian(inputs (k, 3) [m]) -> (3 k, d) [rad per unit box] the model's angle Jacobian at
    the design point, points major; angle_gain (3, 3) [rad/m]; workspace (3,) [rad];
    reference_inputs (k, 3) [m] the trajectory to compare with; noise [rad] per channel;
    prior_precision (d,) [1/unit box^2]; inadequacy(inputs) -> (k, 3) [rad] the model's
    expected error there (None: none), combined with the noise as sqrt(noise^2 + delta^2) so
    that postures where the model is known to be off weigh less; max_inadequacy [rad]: with an
    inadequacy, candidates whose expected error exceeds it on any angle are avoided (never
    chosen; ValueError when fewer than n_points - 1 remain: draw more candidates or raise it).
    region: "workspace" (candidates uniform in the angular workspace) or "box" / "hull" (in the
    actuator-input box +-box (3,) [m] or its octahedron: ``candidate_inputs``); criterion "D"
    (log det M) or "I" (trace M^-1 A, A the mean information of ``prediction_inputs`` (k, 3)
    [m], the postures to be predicted) or "drives" (trace M^-1 A with A = ``variance_weights`` (d, d),
    e.g. ``figure_weights`` of the drive sources and their paper figures: A-optimal on their error
    bars, the same exchange as "I"); fixed_inputs (k, 3) [m]: postures always measured, first
    and in their order (they replace the zero posture, so they should start with it), the design
    choosing n_points - k more; fixed_leg (k,) their legs (default all one leg).
    """
    if n_points < 2:
        raise ValueError(f"n_points={n_points} must be >= 2 (the zero posture and at least one more)")
    if not noise > 0:
        raise ValueError(f"noise={noise} rad must be > 0")
    if points_per_leg < 1:
        raise ValueError(f"points_per_leg={points_per_leg} must be >= 1")
    say = progress or (lambda _: None)
    if region == "workspace":
        candidates = candidate_postures(angle_gain, workspace, n_candidates, rng)
    else:
        if box is None:
            raise ValueError(f"region={region!r} needs the input box (3,) [m]")
        candidates = candidate_inputs(box, n_candidates, region, rng)
    if criterion not in CRITERIA:
        raise ValueError(f"criterion={criterion!r} must be one of {CRITERIA}")
    if criterion == "I" and prediction_inputs is None:
        raise ValueError("criterion 'I' needs prediction_inputs (the postures to be predicted)")
    if criterion == "drives" and variance_weights is None:
        raise ValueError("criterion 'drives' needs variance_weights (d, d): the A of trace(M^-1 A)")
    start_inputs = np.zeros((1, 3)) if fixed_inputs is None else np.asarray(fixed_inputs, float).reshape(-1, 3)
    n_choose = n_points - start_inputs.shape[0]
    if n_choose < 1:
        raise ValueError(f"{start_inputs.shape[0]} fixed postures leave none of n_points={n_points} to choose")
    J = np.asarray(jacobian(candidates), float).reshape(n_candidates, 3, -1)
    delta, avoided = None, None
    sigma = np.full((n_candidates, 3), float(noise))
    offered = np.arange(n_candidates)
    if inadequacy is not None:
        say("model inadequacy at the candidates")
        delta = np.asarray(inadequacy(candidates), float)
        sigma = np.sqrt(sigma ** 2 + delta ** 2)
        if max_inadequacy is not None:
            avoided = np.max(np.abs(delta), axis=1) > max_inadequacy
            offered = np.flatnonzero(~avoided)
            if offered.size < n_choose:
                raise ValueError(f"only {offered.size} of {n_candidates} candidates have an expected model error <= "
                                 f"{max_inadequacy * 1e6:.3g} urad, fewer than the {n_choose} postures to choose: "
                                 f"draw more candidates or allow a larger model error")
    start = np.asarray(jacobian(start_inputs), float) / noise
    if criterion == "D":
        say(f"greedy D-optimal selection of {n_choose} of {offered.size} postures")
        picked, _ = greedy_d_optimal(J[offered] / sigma[offered, :, None], prior_precision, n_choose, fixed=start,
                                     progress=say)
    else:
        if criterion == "I":
            P = np.asarray(jacobian(np.asarray(prediction_inputs, float)), float) / noise
            A = P.T @ P / len(prediction_inputs)
            say(f"greedy I-optimal selection of {n_choose} of {offered.size} postures ({len(prediction_inputs)} to "
                "predict)")
        else:
            A = np.asarray(variance_weights, float)
            say(f"greedy A-optimal selection of {n_choose} of {offered.size} postures ({np.count_nonzero(np.diag(A))} "
                "sources weighed)")
        picked, _ = greedy_i_optimal(J[offered] / sigma[offered, :, None], prior_precision, n_choose, A, fixed=start,
                                     progress=say)
    chosen = offered[picked]
    scale = np.abs(np.linalg.solve(angle_gain, workspace)) if box is None else np.asarray(box, float)
    order = order_postures(candidates[chosen], scale, start=start_inputs[-1])
    chosen = chosen[order]
    inputs = np.vstack([start_inputs, candidates[chosen]])
    if fixed_inputs is None:
        leg = np.concatenate([[0], 1 + np.arange(n_points - 1) // points_per_leg])
    else:  # the fixed postures' legs (default one leg: the held-out folds), then legs of points_per_leg
        first = np.ones(start_inputs.shape[0], int) if fixed_leg is None else np.asarray(fixed_leg, int)
        leg = np.concatenate([first, first.max() + 1 + np.arange(n_choose) // points_per_leg])
    W = np.vstack([start, J[chosen].reshape(-1, J.shape[-1]) / noise])
    W_reference = np.asarray(jacobian(np.asarray(reference_inputs, float)), float) / noise
    return Design(inputs=inputs, leg=leg, candidates=candidates, chosen=chosen,
                  quality=design_quality(W, prior_precision),
                  reference_quality=design_quality(W_reference, prior_precision), noise=float(noise),
                  prior_scale=float(prior_scale), inadequacy=delta, avoided=avoided,
                  max_inadequacy=None if avoided is None else float(max_inadequacy))
