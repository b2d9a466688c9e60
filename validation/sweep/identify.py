"""Identification accuracy of a design (optional sweep column, off by default).

The design's flexure dimensions are given to all six chains of the reference mount (or
the mount of ``settings["mount"]``, a mount file's table: ``flexcal sweep --mount FILE``)
(each chain keeps its length and placement): a leaf design sets every leaf's l, t, w, a
(t1 = t2 = t); a chain design sets every chain's cross-section dimensions. The table1
scenario (or the one named) is built into the virtual prototype of that mount, measured
along the standard trajectory, and identified by ``run_verify`` with small settings.
The record holds the paper's Table 1 figures: largest error of the initial positions
[um], of the clearances [mm], of the hysteresis coefficients [%], the fit [urad] and, beside
it, the model-form floor (``runs.form_floor``: the model at the true values against the
noise-free truth, RMS per angle and max [urad]).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

__all__ = ["mount_with_design", "identification_accuracy"]


def mount_with_design(params, mount: dict[str, Any] | None = None):
    """The reference mechanism (or the mount of the mount-file table ``mount``) with the
    design's flexure dimensions in every chain."""
    from flexcal.geometry.mount import mount_from_table
    from flexcal.geometry.params import FlexureChain, reference_mechanism

    mechanism = reference_mechanism() if mount is None else mount_from_table(mount, source="the sweep's --mount")
    if isinstance(params, FlexureChain):
        changes = {f.name: getattr(params, f.name) for f in dataclasses.fields(params) if f.name != "length"}
    else:  # a hinge: its profile says which chain fields it sets (only a leaf fits the mount's chains)
        changes = params.chain_dimensions() if hasattr(params, "chain_dimensions") else None
        if changes is None:
            raise ValueError(f"identification needs a leaf or chain design, not a {type(params).__name__}")
    chains = tuple(dataclasses.replace(p, chain=dataclasses.replace(p.chain, **changes)) for p in mechanism.chains)
    return dataclasses.replace(mechanism, chains=chains)


def _floor_columns(floor: dict[str, Any]) -> dict[str, float]:
    """The model-form floor as flat sweep columns [urad]: the run's model (the paper's here:
    closed-form chains, no second-order terms) at the true values against the noise-free
    truth, RMS per angle and the largest |error|."""
    overall = floor["models"][0]["all"]
    return {**{f"form_floor_rms_{angle}_urad": value for angle, value in overall["rms_urad"].items()},
            "form_floor_max_urad": overall["max_urad"]}


def identification_accuracy(params, settings: dict[str, Any], *, cache_directory: str | None = None
                            ) -> dict[str, float]:
    """Table 1 accuracy figures of identifying the scenario on the design's mount."""
    from flexcal.calibration.pso_settings import PSOSettings
    from flexcal.model.parameters import parameter_space

    from ..prototype.scenario import load_scenario
    from ..prototype.truth import make_truth
    from ..runs.form_floor import truth_from_run
    from ..runs.verify import VerifySettings, run_verify

    start = time.perf_counter()
    space = parameter_space(mount_with_design(params, settings.get("mount")))
    scenario = load_scenario(settings["scenario"], space=space)
    if settings["provider"] == "fem":  # the truth's: each chain's cuts tied (providers.stiffness_provider)
        from ..prototype.tied_chains import DEFAULT_TIES, tied_fem_provider

        provider = tied_fem_provider(DEFAULT_TIES, cache_directory=cache_directory, progress=False)
    else:
        from ..prototype.segments import analytic_provider

        provider = analytic_provider()
    made = make_truth(scenario, provider)
    measurement = made.measurement
    verify_settings = VerifySettings(sobol_n=settings["sobol_n"], seed=settings["seed"],
                                     pso=dataclasses.replace(PSOSettings(), n_particles=settings["particles"],
                                                             max_iterations=settings["iterations"]),
                                     model_threads=1)  # the sweep's designs run side by side on the cores
    report = run_verify(measurement, space, verify_settings, presets=scenario.values,
                        truth=truth_from_run(made.run, scenario.values), progress=False).report
    figures = {row["figure"]: row["ours"] for row in report.get("paper_comparison", [])}
    return {
        "initial_position_max_abs_error_um": figures.get("initial_position_max_abs_error_um"),
        "clearance_max_abs_error_mm": figures.get("clearance_max_abs_error_mm"),
        "hysteresis_max_rel_error_pct": figures.get("hysteresis_max_rel_error_pct"),
        "fit_rms_urad": report["fit_rms_urad"],
        **_floor_columns(report["model_form_floor"]),
        "wall_s": time.perf_counter() - start,
    }
