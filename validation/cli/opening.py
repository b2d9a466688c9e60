"""The shared opening of the calibration commands (verify, identify, compensate, diagnose):
the measurement (a ``--scenario``'s prototype curves, or a ``--data`` file read with its
sidecar and checked against its mount), the mount that models it (the sidecar's, or
``--mount`` with the differences listed key by key) and the calibration model of that mount
(``--model``, ``--model-stiffness``, ``--second-order``). One place, so that every command reads data,
sidecar and mount the same way; the reading itself is ``cli.options`` (``read_data``,
``load_source_with_truth``, ``data_mechanism``). It lives in ``cli/``, not ``runs/``: it is
all reading of the command line's options, and nothing outside ``cli/`` imports ``cli/``
(docs/architecture.md, tests/test_import_arrows.py).

``open_calibration`` does it all; ``open_data`` and ``calibration_model`` are its two halves
for a command that needs the mount before the model (compensate: its targets lie in the
mount's workspace).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

__all__ = ["DataOpening", "Opening", "open_data", "model_option", "dimension_terms", "model_key", "check_model_options",
           "calibration_model", "open_calibration", "overlapped_opening"]


@dataclass(frozen=True, kw_only=True, eq=False)
class DataOpening:
    """measurement: ``Measurement``; presets (45,) [SI] of a synthetic source or None; truth:
    the model-form floor's ``runs.form_floor.TruthCurve`` or None; mechanism: the
    ``MechanismParams`` that models the data (``--mount``, else the sidecar's)."""

    measurement: Any
    presets: np.ndarray | None
    truth: Any
    mechanism: Any


@dataclass(frozen=True, kw_only=True, eq=False)
class Opening:
    """``DataOpening``'s measurement, presets and truth; space: the calibration model's
    ``ParameterSpace`` on the data's mount (``space.mechanism``)."""

    measurement: Any
    presets: np.ndarray | None
    truth: Any
    space: Any


def open_data(args: argparse.Namespace, *, progress: bool, data_path=None) -> DataOpening:
    """The measurement and its mount. data_path: the file of a command that reads data only
    (compensate, diagnose; no presets, no truth); else the command's ``--scenario`` /
    ``--data`` source."""
    from flexcal.model.parameters import parameter_space

    from .options import data_mechanism, load_source_with_truth, read_data

    if data_path is None:
        measurement, presets, truth = load_source_with_truth(args, parameter_space(), progress=progress)
    else:
        measurement, presets, truth = read_data(data_path, args), None, None
    return DataOpening(measurement=measurement, presets=presets, truth=truth,
                       mechanism=data_mechanism(measurement.metadata, args))


def model_option(args: argparse.Namespace) -> str:
    """The ``--model`` name of a parsed command line (``options.DEFAULT_MODEL`` without one)."""
    from .options import DEFAULT_MODEL

    return getattr(args, "model", None) or DEFAULT_MODEL


def dimension_terms(args: argparse.Namespace) -> str:
    """The dimension terms the run's model takes: ``--dimension-terms`` for ``--model consistent``
    with FEM chains; for any other model "linear" (it has no FEM factors that follow the
    dimensions) if the value is the default (``options.DEFAULT_DIMENSION_TERMS``, so that making
    "quadratic" the default leaves ``--model second-order`` runnable), else a ValueError: an
    explicit "quadratic" the model cannot take is refused."""
    from .options import DEFAULT_DIMENSION_TERMS

    terms = getattr(args, "dimension_terms", None) or DEFAULT_DIMENSION_TERMS
    from ..runs.model_names import FEM_STIFFNESS

    model, stiffness = model_option(args), getattr(args, "model_stiffness", "fem")
    if terms == "linear" or (model == "consistent" and stiffness in FEM_STIFFNESS):
        return terms
    if terms == DEFAULT_DIMENSION_TERMS:
        return "linear"
    raise ValueError(f"--dimension-terms quadratic shapes the consistent model's FEM factors: add --model "
                     f"consistent --model-stiffness fem or fem-rigid (this run: {model}, {stiffness})")


def check_model_options(args: argparse.Namespace) -> None:
    """Refuse a combination of model options ``calibration_model`` cannot build (ValueError),
    before any truth or FEM model is made for it."""
    model = model_option(args)
    if getattr(args, "breakaway_force", None) is not None and model != "consistent":
        raise ValueError(f"--breakaway-force sets the consistent model's play state; add --model consistent "
                         f"(this run's model is {model})")
    if model == "consistent" and getattr(args, "second_order", True) is False:
        raise ValueError("the consistent model (the calibration default) is second-order by "
                         "construction: drop --no-second-order, or use --model second-order --no-second-order")
    dimension_terms(args)


def model_key(args: argparse.Namespace) -> dict:
    """The model options of a parsed command line as a JSON table: what a diagnosis baseline is
    named by in diagnose-benchmark's case ids, its null.json and the ``--null`` check of
    ``flexcal diagnose``. ``--model second-order`` gives {stiffness, second_order} alone (the
    key of every case before session 28, whose ids it keeps)."""
    key = {"stiffness": args.model_stiffness, "second_order": bool(getattr(args, "second_order", True))}
    model = model_option(args)
    if model == "second-order":
        return key
    key |= {"model": model, "dimension_terms": dimension_terms(args)}
    if getattr(args, "breakaway_force", None) is not None:
        key["breakaway_force"] = float(args.breakaway_force)
    return key


def calibration_model(args: argparse.Namespace, mechanism, *, progress: bool,
                      after_batch: Callable[[], None] | None = None):
    """The calibration model (``ParameterSpace``) of ``mechanism`` with the command's
    ``--model``, ``--model-stiffness``, ``--second-order``, ``--breakaway-force``,
    ``--dimension-terms`` and executor options (``runs.model_correction.model_space``, then for
    ``--dimension-terms quadratic`` ``runs.dimension_terms.curved_space`` on the same FEM cache).
    after_batch(): ``model_space``'s, called once the model's FEM batch is built."""
    from ..runs.model_correction import model_space
    from .options import executor_options

    check_model_options(args)
    model = model_option(args)
    force = getattr(args, "breakaway_force", None)
    from ..runs.dimension_terms import curved_space, prepare_model_chains

    terms = dimension_terms(args)
    # with the quadratic terms, their chains built in the slopes' batch (prepare_model_chains)
    space = model_space(args.model_stiffness, args.second_order, progress=progress, mechanism=mechanism,
                        model=model, breakaway_force=force, after_batch=after_batch,
                        also_build=prepare_model_chains if terms == "quadratic" else None, **executor_options(args))
    if terms == "quadratic":  # on the provider of the model's own factors (fem or fem-rigid)
        from ..runs.model_correction import model_provider

        space = curved_space(space, model_provider(args.model_stiffness, mechanism, progress=progress,
                                                   **executor_options(args)))
    return space


def open_calibration(args: argparse.Namespace, *, progress: bool, data_path=None,
                     check: Callable[[Any], None] | None = None) -> Opening:
    """``open_data`` then ``calibration_model``; check(measurement) runs between them and
    raises to stop before the model is built (a cold FEM-corrected model takes ~30 s).

    Without ``check``, for a ``--scenario`` source and a model with the quadratic dimension terms
    (the default): the model first, its FEM batch on both cores, then its set-up (~10 s of one
    core on a cold cache: the chains' shortening probes and joins, small-matrix Python) on this
    thread while the truth's FEM is built on the executor's (``overlapped_opening``), then
    ``open_data`` (its FEM cached); the same numbers in less time. The scenario's own checks come
    first (``truth.check_scenario``), so that a bad one fails before the model's FEM."""
    check_model_options(args)
    if check is None and data_path is None and args.scenario is not None and dimension_terms(args) == "quadratic":
        from ..prototype.truth import check_scenario
        from .options import load_scenario_with_trajectory

        scenario = load_scenario_with_trajectory(args)
        check_scenario(scenario)
        mechanism = scenario.space.mechanism  # the data's (--mount or the scenario's)
        space = overlapped_opening(args, mechanism, progress=progress)
        data = open_data(args, progress=progress)
        if data.mechanism != mechanism:  # not expected: the sidecar's mount is the scenario's
            space = calibration_model(args, data.mechanism, progress=progress)
        return Opening(measurement=data.measurement, presets=data.presets, truth=data.truth, space=space)
    data = open_data(args, progress=progress, data_path=data_path)
    if check is not None:
        check(data.measurement)
    return Opening(measurement=data.measurement, presets=data.presets, truth=data.truth,
                   space=calibration_model(args, data.mechanism, progress=progress))


def overlapped_opening(args: argparse.Namespace, mechanism, *, progress: bool):
    """``calibration_model`` of ``mechanism``, its set-up on this thread while another builds the
    truth's FEM (``options.prepare_source_truth``), started once the model's FEM batch is built
    (``after_batch``): the set-up is small-matrix Python on one core, the builds' work PARDISO and
    numpy outside the interpreter lock. Both under one BLAS thread from here to the end:
    threadpoolctl's limits are the process's, and a build batch's limit
    (``fem_provider.build_missing``) or a block's (``fem.solve.one_thread``) ending on one thread
    would otherwise lift the other's midway; with the pools held at one outside, every limit inside
    restores one, as each computes alone."""
    from concurrent.futures import ThreadPoolExecutor

    from ..blas_threads import single_blas_thread
    from .options import prepare_source_truth

    with single_blas_thread(), ThreadPoolExecutor(1, thread_name_prefix="flexcal-truth-fem") as pool:
        started = []
        space = calibration_model(args, mechanism, progress=progress, after_batch=lambda: started.append(
            pool.submit(prepare_source_truth, args, progress=progress)))
        for truth_fem in started:
            truth_fem.result()
    return space


def report_values(path: str, space, option: str) -> np.ndarray:
    """Values (45,) [SI] of ``space``'s mount with the sources identified in a flexcal verify /
    identify report.json at ``path`` (the others nominal); ``option`` names the command-line
    option in the errors (``--at``, ``--start``)."""
    import json
    from pathlib import Path

    try:
        rows = json.loads(Path(path).read_text())["parameters"]
        return space.build_values({r["name"]: r["identified"] for r in rows}, display_units=True)
    except FileNotFoundError:
        raise ValueError(f"{option} {path}: no such file") from None
    except (KeyError, TypeError, json.JSONDecodeError):
        raise ValueError(f"{option} {path}: not a flexcal verify/identify report.json (needs 'parameters' rows with "
                         f"'name' and 'identified')") from None
