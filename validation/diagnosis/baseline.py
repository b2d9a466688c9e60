"""The baseline of the gap diagnosis: the analytic model calibrated on the measurement,
linearized at its solution.

Design decision (docs/diagnosis.md, "Baseline"): a narrow baseline (the paper's 9 drive
sources) leaves the 36 screened-out sources' errors (table1 draws chain dimensions up to
10 % off) as structured residual for the effect terms to explain, so every ``none`` data
set would look like some effect. The default baseline is therefore broad, on the
second-order model (docs/model.md 8; the first-order model left the exact kinematics'
gap for large_deflection and gravity_sag to pick up on ``none`` data):

1. the improved PSO on the nine drive sources of Table 1 (initial position, clearance,
   hysteresis; the nonlinear part), then the bounded least-squares polish over **all 45**
   sources started from it; several starts, the best kept (``BaselineSettings.starts``);
2. the model linearized there: ``J`` (n, 3, 45) = d(angles)/d(eta) in the unit box, used by
   the term fits as a ridge-regularized linear correction (``prior_sd`` in unit-box units),
   so that each cross-validation fold refits the baseline on its training legs.

Any other callable ``(measurement, rng, progress) -> BaselineFit`` can replace it
(``run_diagnosis(baseline=...)``), e.g. a better model of the chains.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexcal.model.parameters import DRIVE_SOURCE_NAMES, ParameterSpace

from ..measurements import Measurement
from ..runs.settings import BaselineSettings

__all__ = ["BaselineFit", "BaselineSettings", "calibrate_baseline", "Baseline", "input_jacobian"]

POLISH_BUDGET = 1500  # residual evaluations of the 9-source polish after the PSO
WIDE_BUDGET = 4000  # residual evaluations of the 45-source polish (~85 Jacobians)
INPUT_STEP = 1e-7  # [m] finite-difference step of the input Jacobian (0.1 um: << the clearances, >> round-off)


@dataclass(frozen=True, kw_only=True, eq=False)
class BaselineFit:
    """A calibrated baseline at n measured points.

    values (45,) [SI] all sources; names: the sources the linear correction may move;
    model_angles (n, 3) [rad]; axial_loads (n, 6) [N] (tension +); point_class (n,) "S1".."S3";
    input_jacobian (n, 3, 3) [rad/m] [point, angle, actuator]; jacobian (n, 3, p) [rad] per
    unit-box step of each named source; prior_sd (p,) [unit box] ridge prior of the
    correction; description: one line for the report; wall_s [s].
    """

    values: np.ndarray
    names: tuple[str, ...]
    model_angles: np.ndarray
    axial_loads: np.ndarray
    point_class: tuple[str, ...]
    input_jacobian: np.ndarray
    jacobian: np.ndarray
    prior_sd: np.ndarray
    description: str
    wall_s: float = 0.0


Baseline = Callable[..., BaselineFit]


def input_jacobian(values: np.ndarray, inputs: np.ndarray, directions: np.ndarray,
                   space: ParameterSpace) -> np.ndarray:
    """d(angles)/d(inputs) (n, 3, 3) [rad/m] by central differences at fixed travel directions."""
    from flexcal.model.forward import forward

    columns = []
    for k in range(3):
        step = np.zeros(3)
        step[k] = INPUT_STEP
        plus = forward(values, inputs + step, directions, space=space).angles[0]
        minus = forward(values, inputs - step, directions, space=space).angles[0]
        columns.append((plus - minus) / (2 * INPUT_STEP))
    return np.stack(columns, axis=-1)


def calibrate_baseline(measurement: Measurement, rng=None, progress: bool = False,
                       settings: BaselineSettings = BaselineSettings(),
                       space: ParameterSpace | None = None, n_threads: int = 1) -> BaselineFit:
    """The default baseline (module docstring). rng seeds the PSO; space: the model (default
    the closed-form chains with the second-order terms, docs/model.md 8; ``flexcal diagnose``
    passes the FEM-informed one like ``verify``); n_threads: the model's threads per batch of
    candidates (``CalibrationProblem.n_threads``: the same bits at any count; ``flexcal diagnose``
    asks for every usable core, the benchmark's cases, which run side by side, for one each).
    Runs on one BLAS thread (small SVDs are ~100x slower multi-threaded on a loaded machine, see
    blas_threads)."""
    import scipy.linalg  # noqa: F401  (loaded before the limit, which only reaches loaded libraries)
    import scipy.optimize  # noqa: F401

    from ..blas_threads import single_blas_thread

    if space is None:
        from ..runs.model_correction import model_space

        space = model_space("closed-form", second_order=True)
    from flexcal.calibration.problem import check_thread_count

    check_thread_count(n_threads)  # here, before any fit
    with single_blas_thread():
        return _calibrate(measurement, rng, settings, space, n_threads)


def _calibrate(measurement: Measurement, rng, settings: BaselineSettings, space: ParameterSpace,
               n_threads: int) -> BaselineFit:
    from flexcal.calibration.pipeline import identify_swarm
    from flexcal.calibration.polish import batched_jacobian_fd, least_squares_polish
    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.calibration.pso_settings import PSOSettings
    from flexcal.model.forward import CLASS_NAMES, forward
    from flexcal.model.trajectory import travel_directions

    start = time.perf_counter()
    if settings.starts < 1:
        raise ValueError(f"BaselineSettings.starts must be >= 1, got {settings.starts}")
    seeds = np.random.default_rng(rng).integers(2**31, size=settings.starts)
    pso_settings = dataclasses.replace(PSOSettings(), n_particles=settings.particles,
                                       max_iterations=settings.iterations)
    names = space.all_names if settings.polish_all else DRIVE_SOURCE_NAMES

    def polished_start(seed: int):
        """(sum of squares, subspace, unit-box solution) of one start: the identification
        pipeline's PSO on the nine drive sources (``identify_swarm``, without its polish),
        a tight least-squares polish on the nine, then (polish_all) over all 45 from there."""
        found = identify_swarm(space, measurement.inputs, measurement.angles, DRIVE_SOURCE_NAMES, pso_settings,
                               seed=seed, polish=False, n_threads=n_threads)
        drives = found.problem.space
        x = least_squares_polish(found.problem.residuals, found.x_unit, max_evaluations=POLISH_BUDGET, ftol=1e-10,
                                 xtol=1e-10, gtol=1e-10).x
        values = drives.full_values(drives.from_unit(x))
        broad = space.subset(names, fixed=dict(zip(space.all_names, values)))
        wide = CalibrationProblem(space=broad, inputs=measurement.inputs, angles=measurement.angles,
                                  n_threads=n_threads)
        eta = broad.to_unit(values[broad.active_indices])
        if settings.polish_all:
            eta = least_squares_polish(wide.residuals, eta, max_evaluations=WIDE_BUDGET, ftol=1e-10, xtol=1e-10,
                                       gtol=1e-10).x
        return float(np.sum(wide.residuals(eta) ** 2)), wide, eta

    # the best start after the wide polish: the false mode can look as good on the nine alone
    _, wide, eta = min((polished_start(int(seed)) for seed in seeds), key=lambda start: start[0])
    broad = wide.space
    J, _ = batched_jacobian_fd(wide.residuals, eta, scheme="forward", step=1e-4)
    values = broad.full_values(broad.from_unit(eta))
    directions = travel_directions(measurement.inputs)
    result = forward(values, measurement.inputs, directions, space=space)
    n = measurement.n_points
    return BaselineFit(values=values, names=tuple(broad.names), model_angles=result.angles[0],
                       axial_loads=result.axial_loads[0],
                       point_class=tuple(CLASS_NAMES[int(c)] for c in result.point_class[0]),
                       input_jacobian=input_jacobian(values, measurement.inputs, directions, space),
                       jacobian=J.reshape(n, 3, -1), prior_sd=np.full(len(broad.names), settings.prior_sd),
                       description=(f"{'second-order' if space.second_order else 'first-order'} model; PSO "
                                    f"({settings.particles} x {settings.iterations}, best of {settings.starts} starts) "
                                    f"on the 9 drive sources, least-squares polish over {len(broad.names)} sources, "
                                    f"linearized (ridge prior {settings.prior_sd:g} of each range)"),
                       wall_s=time.perf_counter() - start)
