"""Effects of the measurement chain itself (issue #28): the sensor's own dynamics and the
air between sensor and frame. Injectors for the virtual prototype (hooks in
``effects.hooks``) and model terms for the diagnosis (``effects.terms``), docs/effects.md.

``SensorSettling``: a first-order sensor (time constant tau) read at the end of each
dwell, optionally averaged over an integration window before the reading. The frame jumps
from theta_{k-1} to theta_k at the start of the dwell t_k - t_{k-1}; the sensor state s
settles towards theta_k: s_k = theta_k + (s_{k-1} - theta_k) q_k, q_k = exp(-dwell_k/tau).
It needs the time stamps the measurement carries (``EffectContext.past_times``).

``AirTurbulence``: low-frequency refraction noise of the air path, an AR(1) process in time
(correlation time tau_c, stationary standard deviation per channel) added to the angles.
It is noise, not a function of the posture: drawn from its seed, different in every run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .injectors import _Injector
from .terms import _term

__all__ = ["SensorSettling", "AirTurbulence", "settling_error", "ar1_series", "CHAIN_TERMS",
           "TERM_SETTLING_TIME", "REFERENCE_DWELL", "TURBULENCE_MODES", "NOISE_EFFECTS"]

TERM_SETTLING_TIME = 0.5  # [s] the settling term's time constant at zero log parameter (free: x exp(l))
SETTLING_LOG_TAU_LIMIT = 4.0  # [-] |ln(tau / TERM_SETTLING_TIME)| clipped: tau in 0.01..27 s, no overflow
REFERENCE_DWELL = 2.0  # [s] the scenarios' default dwell: the settling amplitude is the lag left after it
# effects that are random in time, not functions of the posture or the path: the diagnosis also tests for them
# with a test of the noise itself (correlated in time, not repeated: diagnosis.correlated), since their held-out
# term cannot predict a random process over a held-out leg (docs/diagnosis.md, "Correlated noise")
NOISE_EFFECTS = ("air_turbulence",)
TURBULENCE_MODES = 8  # cosine modes in time per channel of the turbulence term: periods 2 T / 9 .. T of a run T


def settling_error(angles: np.ndarray, time: np.ndarray, time_constant, integration_time: float = 0.0
                   ) -> np.ndarray:
    """(n, 3) [rad] reading minus true angle of a first-order sensor (module docstring).

    angles (n, 3) [rad] true angles at the points; time (n,) [s]; time_constant [s] (one or
    (3,) per channel); integration_time [s] the reading's averaging window (<= every dwell;
    0: read at the instant). The sensor starts settled (error 0 at the first point)."""
    from ._recurrences import settling

    theta = np.ascontiguousarray(angles, dtype=float)
    tau = np.ascontiguousarray(np.broadcast_to(np.asarray(time_constant, dtype=float), (3,)))
    dwell = np.diff(np.asarray(time, dtype=float))
    # the state s_k - theta_k at the end of dwell k decays by q over it, from the error
    # state_{k-1} + theta_{k-1} - theta_k when the frame has jumped (a compiled loop)
    q = np.exp(-dwell[:, None] / tau[None, :])
    averaged = integration_time > 0
    if not averaged:
        return settling(theta, q, tau, dwell, q, False)  # read at the instant: window and tail unread
    window = np.minimum(integration_time, dwell)
    # the mean of start exp(-u / tau) over u in [dwell - window, dwell]
    tail = np.exp(-(dwell - window)[:, None] / tau[None, :]) - q
    return settling(theta, q, tau, window, tail, True)


def ar1_series(time: np.ndarray, correlation_time: float, seed: int, channels: int = 3) -> np.ndarray:
    """(n, channels) [-] a stationary unit-variance AR(1) (Ornstein-Uhlenbeck) series sampled at
    ``time`` (n,) [s]: x_k = phi_k x_{k-1} + sqrt(1 - phi_k^2) e_k, phi_k = exp(-dt_k / tau_c),
    e from ``seed``. The first n values do not depend on later times (causal), so a
    point-by-point hook and a whole-run call agree."""
    t = np.asarray(time, dtype=float)
    rng = np.random.default_rng([int(seed), 28])
    out = np.empty((t.size, channels))
    for k in range(t.size):
        e = rng.normal(size=channels)
        if k == 0:
            out[k] = e
        else:
            phi = np.exp(-(t[k] - t[k - 1]) / correlation_time)
            out[k] = phi * out[k - 1] + np.sqrt(1.0 - phi**2) * e
    return out


@dataclass(frozen=True, kw_only=True)
class SensorSettling(_Injector):
    """First-order sensor dynamics: time_constant (3,) [s] per channel (0: ideal), read at the
    end of each dwell, averaged over integration_time [s] (0: at the instant). measured =
    true + ``settling_error`` of the true angles of the points so far."""

    time_constant: tuple = (0.0, 0.0, 0.0)
    integration_time: float = 0.0
    name: str = "sensor_settling"
    _vectors = {"time_constant": 3}

    def __post_init__(self) -> None:
        super().__post_init__()
        if min(self.time_constant) < 0 or not self.integration_time >= 0:
            raise ValueError("sensor_settling: time_constant and integration_time must be >= 0 s")

    def measure(self, angles, context):
        if not context.history or max(self.time_constant) <= 0:
            return angles
        tau = np.maximum(np.asarray(self.time_constant), 1e-9)  # 0 s: settled at once (no division by 0)
        past = np.array([r.angles for r in context.history] + [np.asarray(angles, float)])
        return angles + settling_error(past, context.past_times, tau, self.integration_time)[-1]


@dataclass(frozen=True, kw_only=True)
class AirTurbulence(_Injector):
    """Correlated air-turbulence noise: an AR(1) series in time (``ar1_series``) of
    correlation_time [s] and standard deviation sd (3,) [rad] per channel, drawn from seed,
    added to the angles."""

    sd: tuple = (0.0, 0.0, 0.0)
    correlation_time: float = 60.0
    seed: int = 0
    name: str = "air_turbulence"
    _vectors = {"sd": 3}

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.correlation_time > 0:
            raise ValueError("air_turbulence: correlation_time must be > 0 s")

    def measure(self, angles, context):
        series = ar1_series(context.past_times, self.correlation_time, self.seed)
        return angles + np.asarray(self.sd) * series[-1]


# ---------------------------------------------------------------- terms

def _settling(p, data):  # lag fraction a_c left after the reference dwell (3) [-]; ln(tau / 0.5 s) (1)
    """a_c times the first-order settling error of the model angles with tau = 0.5 s exp(l),
    divided by the step's remaining fraction at the reference dwell exp(-2 s / tau): a_c is
    the share of a jump still missing after a 2 s dwell. Uses the measurement's time stamps
    (dwell per point); nonlinear in l (variable projection, as creep)."""
    tau = TERM_SETTLING_TIME * np.exp(np.clip(p[3], -SETTLING_LOG_TAU_LIMIT, SETTLING_LOG_TAU_LIMIT))
    reference = np.exp(-REFERENCE_DWELL / tau)
    return p[:3] * settling_error(data.model_angles, data.time, tau) / max(reference, 1e-300)


def _turbulence(p, data):  # cosine amplitudes [rad] (3 x TURBULENCE_MODES): slow noise, smooth in time
    """Low-frequency part of the air path's noise: per channel a sum of cosines
    cos(pi j (t - t0) / T), j = 2..TURBULENCE_MODES + 1, T the run's length. A smooth function of
    time, not of the posture; held-out legs are predicted from the time around them."""
    t = np.asarray(data.time, dtype=float)
    span = max(t[-1] - t[0], 1e-9)
    # from j = 2: the half cosine j = 1 holds 0.985 of a ramp in time, i.e. drift's rate, and with it the term
    # out-closed drift on drift's own data (10x, standard trajectory x2): drift owns the ramp
    basis = np.cos(np.pi * np.outer((t - t[0]) / span, np.arange(2, TURBULENCE_MODES + 2)))  # (n, modes)
    return basis @ p.reshape(3, TURBULENCE_MODES).T


_XYZ = ("x", "y", "z")
CHAIN_TERMS = {t.id: t for t in (
    # ln(tau/0.5 s) at +-1 scale (the fit's extra starts) is tau = 0.18 s and 1.4 s: injectors draw 0.3-1.2 s
    _term("sensor_settling", [f"lag_{c}" for c in _XYZ] + ["log_time_constant"], ["-"] * 3 + ["ln(tau/0.5 s)"],
          [1e-3] * 3 + [1.0], _settling),
    _term("air_turbulence", [f"cos{j}_{c}" for c in _XYZ for j in range(2, TURBULENCE_MODES + 2)],
          ["rad"] * (3 * TURBULENCE_MODES), [1e-6] * (3 * TURBULENCE_MODES), _turbulence),
)}
