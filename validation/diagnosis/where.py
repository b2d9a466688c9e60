"""Where the gap lies: the noise floor, stratification of the baseline residual and tests
for structure (issue #7, docs/diagnosis.md).

All residuals are (n, 3) [rad] in trajectory order, channels theta_x, theta_y, theta_z.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["noise_floor_differences", "noise_floor_repeats", "noise_floor", "strata", "concentration",
           "runs_test", "autocorrelation", "periodicity", "structure_tests", "SCREW_LEAD"]

SCREW_LEAD = 1e-3  # [m/rev] ball-screw lead (as the effect library's lead_error term)
# second differences of white noise: e_{k+1} - 2 e_k + e_{k-1} has variance 6 sigma^2;
# the median of |N(0, s)| is 0.67449 s (MAD -> standard deviation)
_MAD_TO_SD = 0.6744897501960817


def noise_floor_differences(residual: np.ndarray, leg: np.ndarray) -> np.ndarray:
    """Noise standard deviation (3,) [rad] per channel from the residual itself: robust
    (median-absolute) scale of second differences along the sequence within each leg,
    divided by sqrt(6). Smooth structure (slowly varying with the input) cancels in second
    differences; isolated jumps (reversals, lost steps) are outliers the median ignores."""
    residual = np.asarray(residual, float)
    leg = np.asarray(leg)
    pieces = []
    for k in np.unique(leg):
        r = residual[leg == k]
        if r.shape[0] >= 3:
            pieces.append(r[2:] - 2 * r[1:-1] + r[:-2])
    if not pieces:
        raise ValueError("the noise floor needs legs of at least 3 points")
    d2 = np.concatenate(pieces)
    return np.median(np.abs(d2), axis=0) / _MAD_TO_SD / math.sqrt(6.0)


def noise_floor_repeats(angles: np.ndarray, inputs: np.ndarray, direction: np.ndarray,
                        atol: float = 1e-9) -> tuple[np.ndarray | None, int]:
    """Noise standard deviation (3,) [rad] from points repeated at the same inputs and travel
    directions (differences of consecutive repeats / sqrt 2, robust scale), and the number of
    repeat pairs; (None, 0) if there are fewer than 10. Drift between repeats inflates it."""
    key = np.round(np.column_stack([inputs / atol, direction])).astype(np.int64)
    seen: dict[tuple, int] = {}
    differences = []
    for k, row in enumerate(map(tuple, key)):
        if row in seen:
            differences.append(angles[k] - angles[seen[row]])
        seen[row] = k
    if len(differences) < 10:
        return None, len(differences)
    d = np.array(differences)
    return np.median(np.abs(d), axis=0) / _MAD_TO_SD / math.sqrt(2.0), len(differences)


def noise_floor(residual, leg, angles, inputs, direction) -> dict[str, Any]:
    """The noise floor used by the diagnosis, per channel: the smaller of the second-difference
    estimate and (when there are >= 10 repeat pairs) the repeat estimate. Both can only be
    inflated by structure -- the first by unsmooth model error (clearance switches), the
    second by drift between repeats -- never deflated, so the smaller is the better bound."""
    sigma = noise_floor_differences(residual, leg)
    repeats, n_pairs = noise_floor_repeats(angles, inputs, direction)
    method = "robust second differences of the residual within legs"
    if repeats is not None:
        sigma = np.minimum(sigma, repeats)
        method += f", or repeats ({n_pairs} pairs) where smaller"
    floor = np.maximum(sigma, 1e-9)  # [rad] 1 nrad: below any real sensor, stops a division by zero
    return {"sigma": floor, "method": method, "sigma_repeats": repeats, "n_repeat_pairs": n_pairs}


def _rms(r: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(r**2, axis=0)) if r.size else np.full(3, np.nan)


def strata(residual: np.ndarray, *, leg, direction, point_class, time, inputs, extras: dict | None = None,
           n_bins: int = 4) -> list[dict[str, Any]]:
    """Residual RMS per stratum: [{"by", "stratum", "n", "rms_urad" (3,)}].

    Strata: trajectory leg; travel direction of each actuator (only where it moves); point
    class S1/S2/S3; time quartiles; position quartiles of each actuator (where it moves);
    screw phase (position modulo the lead, in quarters); temperature quartiles if a
    ``temperature_c`` column is present."""
    residual = np.asarray(residual, float)
    n = residual.shape[0]
    rows: list[dict[str, Any]] = []

    def add(by, label, mask):
        mask = np.asarray(mask, bool)
        if np.count_nonzero(mask) >= 2:
            rows.append({"by": by, "stratum": str(label), "n": int(np.count_nonzero(mask)),
                         "rms_urad": _rms(residual[mask]) * 1e6})

    for k in np.unique(leg):
        add("leg", int(k), leg == k)
    moving = np.abs(inputs) > 1e-9
    for i in range(3):
        for sign, name in ((1, "+"), (-1, "-")):
            add(f"direction D{i + 1}", name, moving[:, i] & (direction[:, i] == sign))
    for c in sorted(set(point_class)):
        add("point class", c, np.array(point_class) == c)

    def quartiles(by, values, mask):
        values = np.asarray(values, float)
        if np.count_nonzero(mask) < 2 * n_bins:
            return
        edges = np.quantile(values[mask], np.linspace(0, 1, n_bins + 1))
        index = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, n_bins - 1)
        for b in range(n_bins):
            add(by, f"{edges[b]:.4g}..{edges[b + 1]:.4g}", mask & (index == b))

    quartiles("time [s]", time, np.ones(n, bool))
    for i in range(3):
        quartiles(f"position D{i + 1} [mm]", inputs[:, i] * 1e3, moving[:, i])
        phase = np.mod(inputs[:, i], SCREW_LEAD) / SCREW_LEAD * 360.0
        for b in range(4):
            add(f"screw phase D{i + 1} [deg]", f"{90 * b}..{90 * (b + 1)}",
                moving[:, i] & (phase >= 90 * b) & (phase < 90 * (b + 1)))
    if extras and "temperature_c" in extras:
        quartiles("temperature [degC]", extras["temperature_c"], np.ones(n, bool))
    return rows


def concentration(rows: list[dict[str, Any]], overall_rms_urad: np.ndarray, sigma_urad: np.ndarray,
                  factor: float = 1.5) -> list[dict[str, Any]]:
    """Strata where the gap is concentrated: a channel's RMS above ``factor`` x the overall
    RMS and above 2 noise floors (so a stratum of pure noise is never named), largest
    excess first."""
    out = []
    for row in rows:
        for c, name in enumerate(("theta_x", "theta_y", "theta_z")):
            value = row["rms_urad"][c]
            if value > factor * overall_rms_urad[c] and value > 2 * sigma_urad[c]:
                out.append({"by": row["by"], "stratum": row["stratum"], "angle": name, "n": row["n"],
                            "rms_urad": float(value), "ratio_to_overall": float(value / overall_rms_urad[c])})
    out.sort(key=lambda r: -r["ratio_to_overall"])
    return out


def runs_test(x: np.ndarray) -> float:
    """Wald-Wolfowitz runs test of the signs of x (n,) about its median: z score (negative:
    fewer runs than chance, i.e. structure). NaN if one sign is missing."""
    s = np.asarray(x) > np.median(x)
    n1, n2 = np.count_nonzero(s), np.count_nonzero(~s)
    if n1 == 0 or n2 == 0:
        return float("nan")
    runs = 1 + np.count_nonzero(s[1:] != s[:-1])
    mean = 2 * n1 * n2 / (n1 + n2) + 1
    var = 2 * n1 * n2 * (2 * n1 * n2 - n1 - n2) / ((n1 + n2) ** 2 * (n1 + n2 - 1))
    return float((runs - mean) / math.sqrt(var)) if var > 0 else float("nan")


def autocorrelation(x: np.ndarray, lag: int = 1) -> float:
    """Sample autocorrelation of x (n,) at ``lag`` (white noise: ~N(0, 1/n))."""
    x = np.asarray(x, float) - np.mean(x)
    denominator = float(x @ x)
    return float(x[lag:] @ x[:-lag] / denominator) if denominator > 0 and len(x) > lag else float("nan")


def periodicity(x: np.ndarray) -> dict[str, float]:
    """Periodogram peak of x (n,) over the sequence: period [points] and Fisher's g
    statistic with its p-value (white noise: g ~ small; p < 0.01 = a significant period)."""
    x = np.asarray(x, float) - np.mean(x)
    power = np.abs(np.fft.rfft(x))[1:] ** 2
    if power.size < 2 or power.sum() <= 0:
        return {"period_points": float("nan"), "fisher_g": float("nan"), "p_value": float("nan")}
    m = power.size
    k = int(np.argmax(power))
    g = float(power[k] / power.sum())
    # Fisher (1929): P(g > x) ~ m (1 - x)^(m - 1) for the first term
    p = float(min(1.0, m * (1 - g) ** (m - 1)))
    return {"period_points": float(len(x) / (k + 1)), "fisher_g": g, "p_value": p}


def structure_tests(residual: np.ndarray) -> list[dict[str, Any]]:
    """Runs z, lag-1 autocorrelation (with its white-noise z = r sqrt n) and periodicity per channel."""
    out = []
    n = residual.shape[0]
    for c, name in enumerate(("theta_x", "theta_y", "theta_z")):
        r1 = autocorrelation(residual[:, c])
        out.append({"angle": name, "runs_z": runs_test(residual[:, c]), "lag1_autocorrelation": r1,
                    "lag1_z": r1 * math.sqrt(n), **periodicity(residual[:, c])})
    return out
