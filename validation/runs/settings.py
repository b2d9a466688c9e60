"""The settings of a calibration run (``VerifySettings``) and of the diagnosis baseline
(``BaselineSettings``), in a module light enough for the command line to read its defaults
at start-up (``cli.options.CALIBRATION_DEFAULTS``, ``cli.diagnose``): the one place these
defaults are set."""

from __future__ import annotations

from dataclasses import dataclass, field

from flexcal.calibration.pso_settings import PSOSettings

__all__ = ["VerifySettings", "BaselineSettings"]


@dataclass(frozen=True, kw_only=True)
class VerifySettings:
    """sobol_n: Sobol base sample N (power of two); sobol_threshold: total index [-] from
    which a source is identified; pso: PSO settings (paper defaults); polish: run the
    least-squares polish; seed: one seed for the Sobol sample and the PSO;
    remove_offset: subtract each leg's return offset first (paper Sec. 4.2);
    noise_urad: the sensor noise level [urad] (the paper method's identifiability; the
    noise floor of the fit-RMS goal; None: from the fit); method: "map", "free" or "paper";
    prior_scale: the MAP prior scale (None: cross-validated); sources: identify only these
    (the others at nominal; with "paper" instead of the Sobol selection; ``flexcal identify``);
    profile: widen the map/free bars of the base combinations not identified alone by their
    profile likelihood (``calibration.profile_bars``); start: values (45,) [SI] every map/free fit
    starts from (None: the prior mean); model_threads: the model's threads per batch of
    candidates (None: every usable core; 1 where the caller runs identifications side by side,
    a sweep's designs; the results are the same bits at any count, ``model.forward``)."""

    sobol_n: int = 512
    sobol_threshold: float = 0.01
    pso: PSOSettings = field(default_factory=PSOSettings)
    polish: bool = True
    seed: int = 0
    remove_offset: bool = False
    noise_urad: float | None = None
    method: str = "map"
    prior_scale: float | None = None
    sources: tuple[str, ...] | None = None
    profile: bool = False
    start: tuple[float, ...] | None = None
    model_threads: int | None = None

    def __post_init__(self) -> None:
        if self.model_threads is not None:  # None: every usable core
            from flexcal.calibration.problem import check_thread_count  # (the model: not at start-up)

            check_thread_count(self.model_threads, "model_threads")
        if self.method not in ("map", "free", "paper"):
            raise ValueError(f"method={self.method!r} must be 'map', 'free' or 'paper'")
        if self.sources is not None and not self.sources:
            raise ValueError("sources=() names no source to identify")


@dataclass(frozen=True, kw_only=True)
class BaselineSettings:
    """particles, iterations: PSO on the nine drive sources; starts: independent PSO runs,
    each polished on the nine and then (polish_all) over all 45, the one with the smallest
    final sum of squares kept; polish_all: polish all 45 sources (False: only the nine);
    prior_sd: ridge prior [unit box] of the linear correction in the term fits (0.3: a
    source may move by ~a third of its range).

    Why several starts: one 80 x 60 swarm plus the polishes ends in a false clearance mode
    (a 50-100 urad spike at a stroke end instead of ~2 urad at most) on 6 of 36 (file, seed)
    pairs of ``none`` benchmark files; six starts, the best kept after the 45-source polish,
    on 0 of the same 36 (measured 2026-11-22, docs/diagnosis.md), ~10 s per baseline."""

    particles: int = 80
    iterations: int = 60
    starts: int = 6
    polish_all: bool = True
    prior_sd: float = 0.3
