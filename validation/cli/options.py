"""The option groups several commands share, each defined once: where results go
(``--out``), what is measured (``--scenario`` | ``--data``, ``--seed``, ``--trajectory``,
``--provider``), which model calibrates (``--model``, refined by ``--model-stiffness``,
``--second-order``, ``--breakaway-force``), how it
identifies (``--method``, ``--prior-scale``, Sobol and PSO sizes) and where heavy items run
(``--workers``, ``--scheduler``). A command's own options stay in its module.
"""

from __future__ import annotations

import argparse
import re
from typing import Any

from ..prototype.providers import PROVIDERS

__all__ = ["add_out", "add_seed", "add_scenario", "add_trajectory", "load_scenario_with_trajectory", "add_mount",
           "mount_option", "data_mechanism",
           "add_executor_options", "executor_options", "worker_count", "scheduler_address", "MODEL_DEFAULTS",
           "DEFAULT_MODEL", "DEFAULT_DIMENSION_TERMS",
           "CALIBRATION_DEFAULTS", "calibration_defaults", "add_model_options",
           "add_identification_options", "add_method_options", "prior_scale_option", "add_calibration_options",
           "add_source_options", "load_source", "load_source_with_truth", "prepare_source_truth", "check_sobol_options",
           "add_point_model_options", "add_unit_check_option", "read_data"]


def add_out(parser: argparse.ArgumentParser, *, required: bool = True, what: str = "report.json, report.md, PNGs",
            when: str = "written only when the run succeeds") -> None:
    """``--out DIR``: the run folder (by default written whole or not at all)."""
    parser.add_argument("--out", metavar="DIR", required=required, help=f"output folder ({what}); {when}")


def add_seed(parser: argparse.ArgumentParser, *, what: str = "random draws", default: int | None = None) -> None:
    """``--seed N``: the one seed of a command's randomness."""
    parser.add_argument("--seed", type=int, metavar="N", default=default,
                        help=f"seed for {what}; the same seed gives the same report" +
                             ("" if default is None else " (default %(default)s)"))


def add_scenario(parser: argparse.ArgumentParser, *, required: bool = True, group=None) -> None:
    """``--scenario NAME|FILE``: a built-in virtual-prototype scenario or a scenario TOML."""
    (group or parser).add_argument("--scenario", metavar="NAME|FILE", required=required if group is None else False,
                                   help="virtual-prototype scenario: table1, paper (drives pass through their "
                                        "clearance), nominal or a scenario TOML file (format: "
                                        "flexcal.validation.prototype.scenario)")


def add_trajectory(parser: argparse.ArgumentParser) -> None:
    """``--trajectory CSV``: drive the scenario along a trajectory file instead of its own."""
    parser.add_argument("--trajectory", metavar="CSV",
                        help="drive the scenario along this trajectory (flexcal design's trajectory.csv: columns "
                             "xa1_mm, xa2_mm, xa3_mm[, leg]) instead of the scenario's own")


def add_mount(parser: argparse.ArgumentParser, *, what: str = "the scenario's mount") -> None:
    """``--mount FILE``: the user's mount file (docs/mount.md) instead of ``what``."""
    parser.add_argument("--mount", metavar="FILE",
                        help=f"mount file (TOML, docs/mount.md; 'flexcal mount --example' prints one) instead of "
                             f"{what}; checked before any computation")


_MOUNTS: dict[tuple, object] = {}  # (path, size, mtime) -> its checked MechanismParams (read and warned about once)


def _file_key(path: str) -> tuple:
    import os

    try:
        stat = os.stat(path)
    except OSError:
        return (path,)  # read_mount says what is wrong
    return (path, stat.st_size, stat.st_mtime_ns)


def mount_option(args: argparse.Namespace):
    """The checked ``MechanismParams`` of ``--mount FILE``, or None without it."""
    path = getattr(args, "mount", None)
    if path is None:
        return None
    key = _file_key(path)
    if key not in _MOUNTS:
        from ..mount_checks import read_checked_mount

        _MOUNTS[key] = read_checked_mount(path)
    return _MOUNTS[key]


def data_mechanism(metadata: dict, args: argparse.Namespace):
    """The mount that models a measurement: ``--mount FILE`` if given, else its sidecar's
    (the reference mount without one). Where ``--mount`` differs from the sidecar's mount,
    one warning lists the differences key by key (once per run)."""
    import logging

    from flexcal.geometry.mount import mount_differences

    from ..prototype.scenario import mechanism_from_metadata

    data = mechanism_from_metadata(metadata)
    mount = mount_option(args)
    if mount is None:
        return data
    differences = mount_differences(data, mount)
    key = ("differences", *_file_key(args.mount), id(metadata))
    if differences and key not in _MOUNTS:
        _MOUNTS[key] = True
        logging.getLogger("flexcal.mount").warning(
            "--mount %s replaces the data's mount (the sidecar's); %d differences: %s", args.mount, len(differences),
            "; ".join(differences))
    return mount


def _check_noise_option(args: argparse.Namespace) -> None:
    if getattr(args, "noise_urad", None) is not None and args.noise_urad < 0:
        raise ValueError(f"--noise-urad={args.noise_urad} must be >= 0")


def load_scenario_with_trajectory(args: argparse.Namespace):
    """The scenario of ``--scenario``/``--seed``/``--noise-urad``/``--mount``, along
    ``--trajectory`` if given."""
    from ..prototype.scenario import load_scenario

    _check_noise_option(args)
    scenario = load_scenario(args.scenario, seed=args.seed, noise_urad=args.noise_urad, mount=mount_option(args))
    trajectory = getattr(args, "trajectory", None)
    return scenario.with_trajectory(trajectory) if trajectory else scenario


def add_executor_options(parser: argparse.ArgumentParser, *, what: str) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` with the same meaning on every command."""
    # default None: FEM segment builds on one thread per usable core (plan_local_builds). Since
    # they run on threads of this process (session 9) there is no start-up to pay: a cold
    # table1 truth on the 2-core machine took 0.62x the in-process time when the machine was
    # idle and 0.84x under two busy-looping processes (docs/scale.md, "Session 10"); worker
    # processes (the cases of diagnose-benchmark) stay opt-in, they import the FEM stack again
    parser.add_argument("--workers", type=worker_count, metavar="N", default=None,
                        help=f"local workers for {what} (default: FEM segments on one thread of this process per "
                             "core, at most one per missing segment and per 1.5 GB of free memory, anything else "
                             "one after the other in this process; 0: everything one after the other in this "
                             "process; N: N at once, FEM segments on N threads of this process, each meshing in "
                             "its own child process, other jobs on N local worker processes)")
    parser.add_argument("--scheduler", type=scheduler_address, metavar="ADDRESS", default=None,
                        help=f"address of a Dask scheduler (tcp://host:8786) to run {what} on; "
                             "default: see --workers)")


def worker_count(text: str) -> int:
    """``--workers`` as argparse's ``type``: a whole number >= 0, checked when the command
    line is read (a run that builds no FEM segment used to accept -1 silently)."""
    try:
        count = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number (0: everything in this process)") from None
    if count < 0:
        raise argparse.ArgumentTypeError(f"{count} must be >= 0 (0: everything in this process)")
    return count


# Dask's protocols (distributed.comm.registry.backends); the scheme may be left out (tcp)
_SCHEDULER = re.compile(r"^(?:(?:tcp|tls|ws|wss|ucx)://)?(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+)(?::(\d{1,5}))?/?$"
                        r"|^inproc://\S+$")


def scheduler_address(text: str) -> str:
    """``--scheduler`` as argparse's ``type``: the shape of a Dask scheduler address
    (``tcp://HOST:PORT``), checked when the command line is read, not when (and if) the
    cluster is first contacted."""
    match = _SCHEDULER.match(text.strip())
    if match is None or (match.group(1) is not None and not 0 < int(match.group(1)) < 65536):
        raise argparse.ArgumentTypeError(f"{text!r} is not a Dask scheduler address; give tcp://HOST:PORT "
                                         f"(e.g. tcp://10.0.0.5:8786)")
    return text.strip()


def executor_options(args: argparse.Namespace) -> dict[str, Any]:
    """{"workers": ..., "scheduler": ...} of a parsed command line (workers None: the
    default, ``add_executor_options``); a command without ``add_executor_options`` runs in
    its own process (workers 0)."""
    return {"workers": getattr(args, "workers", 0), "scheduler": getattr(args, "scheduler", None)}


# The calibration model of verify, identify, sensitivity and design (docs/cli.md "Which model
# calibrates"): the consistent model (issue 24). Session 20 made it the default and took that back:
# fitted from the prior mean its noise-free main job ended in a worse minimum. Since session 21 its
# map/free fits start at the second-order model's estimate on the same data
# (calibration.staged_start), measured on the README's main job: fit 0.0016 urad RMS (max 0.008)
# against the second-order model's 0.286 (1.55), x0 <= 0.63 um, base z RMS 0.83 over 20; with 0.5
# urad noise on seeds 1-3 of both mounts the fit is 0.95-1.06x the noise (second-order: 1.14-1.23x
# table1, 2.5-2.7x paper) and the z RMS 0.52-1.42 (docs/model.md "Session 21"). compensate keeps
# "second-order" (its figures were measured with it); diagnose and diagnose-benchmark take this
# one since session 28 (docs/diagnosis.md, "Issue 28 results (session 28)").
DEFAULT_MODEL = "consistent"
# --model consistent's FEM factors as functions of the chain dimensions: "linear" (the slopes) or
# "quadratic" (docs/model.md, "Session 18"); flipping it is this one line. The default applies
# where it can (consistent with FEM chains); elsewhere the run's model has no such terms
# (cli.opening.dimension_terms), while an explicit choice the model cannot take is refused.
# "quadratic" since session 26: on the tied truth (session 25) the linear terms leave 0.37-1.07
# urad RMS in θy on `flexcal design` trajectories and up to 0.27 on random walks (issue 24's goal
# 0.25), the quadratic ones <= 0.14 on every trajectory, mount and breakaway force measured
# (docs/model.md 11, "Session 26"), at 20 more tied chains cold (the mixed curvatures, one-sided
# since session 30: 40 central).
DEFAULT_DIMENSION_TERMS = "quadratic"
MODEL_DEFAULTS = {"model": DEFAULT_MODEL, "model_stiffness": "fem", "second_order": True,
                  "dimension_terms": DEFAULT_DIMENSION_TERMS}


def _calibration_defaults() -> dict[str, Any]:
    """The calibration commands' defaults, read from the one place they are set: the
    pipeline's ``VerifySettings`` and ``PSOSettings`` (prior_scale 0: the command line's
    "no prior", where the settings' None means cross-validated)."""
    from flexcal.calibration.pso_settings import PSOSettings

    from ..runs.settings import VerifySettings

    run, pso = VerifySettings(), PSOSettings()
    return {"sobol_n": run.sobol_n, "sobol_threshold": run.sobol_threshold, "particles": pso.n_particles,
            "iterations": pso.max_iterations, "polish": run.polish, "remove_offset": run.remove_offset,
            "calibration_seed": run.seed, "method": run.method, "prior_scale": 0.0, **MODEL_DEFAULTS}


CALIBRATION_DEFAULTS = _calibration_defaults()


def calibration_defaults(*names: str, **overrides: Any) -> dict[str, Any]:
    """``CALIBRATION_DEFAULTS`` restricted to ``names`` (a command's own options), then
    ``overrides`` (a command's own values, e.g. compensate's method "paper")."""
    return {**{name: CALIBRATION_DEFAULTS[name] for name in names}, **overrides}


def add_model_options(parser: argparse.ArgumentParser, *, stiffness_default: str = "%(default)s",
                      executor_what: str = "the FEM segment builds (cold cache only)") -> None:
    """Which model the calibration uses (``verify``, ``sensitivity``, ``identify``,
    ``compensate``, ``diagnose``, ``diagnose-benchmark``); defaults from the command's
    DEFAULT_CONFIG (``MODEL_DEFAULTS``); stiffness_default: what --model-stiffness's help says
    its default is (a command whose default depends on another option says which);
    executor_what: what --workers / --scheduler run (``add_executor_options``)."""
    from ..runs.model_names import DEFAULT_BREAKAWAY_N, MODEL_STIFFNESS, MODELS

    parser.add_argument("--model", choices=MODELS,
                        help="the calibration model: paper (Eq. 1-8 as written: closed-form chains, no second-order "
                             "terms), second-order (FEM-informed chains and second-order terms added to the pose; "
                             "--model-stiffness and --second-order refine it) or consistent (FEM factors following "
                             "the dimensions, the chains' measured shortening solved with the clearance, the "
                             "clearance's play state; docs/model.md 9-10; --model-stiffness closed-form: the same on "
                             "Eq. 1's chains) (default %(default)s)")
    parser.add_argument("--second-order", action=argparse.BooleanOptionalAction,
                        help="--model second-order's geometric terms: chain-force P-delta and rigid second-order "
                             "frame kinematics (docs/model.md 8; default: on; --model second-order --no-second-order "
                             "--model-stiffness closed-form = --model paper)")
    parser.add_argument("--model-stiffness", choices=MODEL_STIFFNESS,
                        help="the chain compliance of --model second-order and consistent: closed-form (the paper's "
                             "Eq. 1) or corrected by the FEM at the nominal design, its segments joined through the "
                             "cut fields (fem, as the prototype of --provider fem) or rigidly at the cuts "
                             "(fem-rigid, as --provider fem-rigid: use it with that truth) (docs/model.md 7; default "
                             f"{stiffness_default})")
    parser.add_argument("--breakaway-force", type=float, metavar="N", default=None,
                        help=f"--model consistent's breakaway force of the drives' friction [N] (the clearance's "
                             f"play state, given, not identified; default {DEFAULT_BREAKAWAY_N:g}, the virtual "
                             f"prototype's)")

    parser.add_argument("--dimension-terms", choices=("linear", "quadratic"),
                        help="--model consistent's FEM factors and chain shortening as functions of the chain "
                             "dimensions: linear (slopes) or quadratic (second-order terms and cross terms of the "
                             "factors, the shortening's slopes: the form error on designed trajectories 0.29-0.44 -> "
                             "0.05-0.21 urad theta_y, at ~20 more chain builds on a cold cache; docs/model.md, "
                             "session 18) (default %(default)s, for --model consistent with FEM chains)")
    add_executor_options(parser, what=executor_what)


def add_identification_options(parser: argparse.ArgumentParser) -> None:
    """PSO size, polish and offset removal (``verify``, ``identify``); defaults from DEFAULT_CONFIG."""
    parser.add_argument("--particles", type=int, help="PSO particles (paper: 300; default %(default)s)")
    parser.add_argument("--iterations", type=int, help="PSO iterations (paper: 150; default %(default)s)")
    parser.add_argument("--polish", action=argparse.BooleanOptionalAction,
                        help="least-squares polish of the swarm's best points (default: on)")
    parser.add_argument("--remove-offset", action=argparse.BooleanOptionalAction,
                        help="remove each leg's return offset first (paper Sec. 4.2; default: off)")


def add_method_options(parser: argparse.ArgumentParser) -> None:
    """--method and --prior-scale (``verify``, ``identify``, ``compensate``)."""
    parser.add_argument("--method", choices=("map", "free", "paper"),
                        help="map: all 45 sources with the paper's ranges as a cross-validated prior, standard errors "
                             "and base parameters; free: all 45 without a prior; paper: Sobol screening + improved "
                             "PSO on the selected sources (default %(default)s)")
    parser.add_argument("--prior-scale", type=float, metavar="S",
                        help="MAP prior std as a multiple of each range's own spread (range/sqrt(12)); 0 = choose by "
                             "held-out cross-validation (default %(default)s)")


def prior_scale_option(args: argparse.Namespace) -> float | None:
    """--prior-scale as VerifySettings takes it: None (cross-validate) for 0."""
    scale = getattr(args, "prior_scale", 0.0) or 0.0
    if scale < 0:
        raise ValueError(f"--prior-scale={scale} must be > 0, or 0 to choose it by cross-validation")
    return scale or None


def add_calibration_options(parser: argparse.ArgumentParser) -> None:
    """The screening and identification settings (``verify``, ``sensitivity``, ``identify``);
    their defaults come from the command's DEFAULT_CONFIG."""
    add_method_options(parser)
    parser.add_argument("--sobol-n", type=int, metavar="N", help="Sobol base sample N (power of two; default %(default)s)")
    parser.add_argument("--sobol-threshold", type=float, metavar="S",
                        help="identify sources whose total Sobol index reaches this on any output "
                             "(default %(default)s; 0 identifies all 45)")
    add_identification_options(parser)
    parser.add_argument("--calibration-seed", type=int, metavar="N",
                        help="seed of the Sobol sample and the PSO (default %(default)s)")
    add_model_options(parser)


def add_error_bar_options(parser: argparse.ArgumentParser) -> None:
    """``--error-budget-draws K``, ``--no-error-budget`` and ``--profile-bars`` (``verify``,
    ``identify``, ``compensate``): what the error bars of --method map/free carry besides the noise and the
    residual-fitted discrepancy (validation/runs/error_budget.py, calibration/profile_bars.py)."""
    parser.add_argument("--error-budget-draws", type=int, default=None, metavar="K",
                        help="the error bars of --method map/free carry the model's error measured on the "
                             "virtual prototype (--provider) at the estimate "
                             "(validation/runs/error_budget.py), plus K prior draws of the non-geometric "
                             "sources (default 0)")
    parser.add_argument("--no-error-budget", action="store_true",
                        help="error bars from the residual-fitted discrepancy alone (no prototype runs)")
    # default: on when the measurement declares sensor noise (``profile_option``). Measured on the
    # consistent model, with 0.5 urad noise it brings the base bars into the z-score band (9-28
    # constrained fits), but on the noise-free table1 scenario it ran 99 constrained fits (~450 of a
    # 530 s idle verify) and made the bars ~6x too wide (docs/calibration.md 6, session 17)
    parser.add_argument("--profile-bars", action=argparse.BooleanOptionalAction, default=None,
                        help="widen the bars of the base combinations not identified alone by their profile "
                             "likelihood, the other sources re-optimised (calibration/profile_bars.py; minutes). "
                             "Default: on when the measurement declares its sensor noise (--noise-urad > 0 or the "
                             "sidecar's sensors.noise_urad), off for a noise-free or undeclared one, where the fit's "
                             "noise is the model's own misfit and the profile makes the bars too wide")


def add_provider(parser: argparse.ArgumentParser, *, what: str) -> None:
    """``--provider``: the virtual prototype's segment stiffness (``PROVIDERS``); its default
    comes from the command's DEFAULT_CONFIG. what: what the command builds the prototype for."""
    parser.add_argument("--provider", choices=PROVIDERS, help=f"prototype segment stiffness {what} (default %(default)s)")


def error_budget_option(args: argparse.Namespace, space, inputs, *, progress: bool):
    """The budget callable ``run_verify`` takes (values (45,) [SI] of the estimate ->
    ``runs.error_budget.ErrorBudget`` on ``inputs`` (n, 3) [m]), or None: ``--method paper``
    (no error bars to carry it) or ``--no-error-budget``."""
    if args.method == "paper" or args.no_error_budget:
        return None
    from ..prototype.providers import stiffness_provider
    from ..runs.error_budget import DEFAULT_DRAWS, model_error_budget

    draws = DEFAULT_DRAWS if args.error_budget_draws is None else args.error_budget_draws
    if draws < 0:
        raise ValueError(f"--error-budget-draws={draws} must be >= 0")
    provider = stiffness_provider(args.provider, progress=progress, **executor_options(args))

    def budget(values):
        return model_error_budget(space, inputs, provider, n_draws=draws, estimate=values)
    return budget


def declared_noise_urad(args: argparse.Namespace, metadata: dict) -> float:
    """The largest sensor noise [urad] the run declares: ``--noise-urad`` if given, else the
    measurement sidecar's ``sensors.noise_urad`` (0 when neither states one)."""
    if getattr(args, "noise_urad", None) is not None:
        return float(args.noise_urad)
    from ..sidecar import stated_sensor_noise_urad

    stated = stated_sensor_noise_urad(metadata)
    return 0.0 if stated is None else float(stated.max())


def profile_option(args: argparse.Namespace, metadata: dict) -> bool:
    """``--profile-bars`` as VerifySettings takes it: off for --method paper (no error bars);
    given on or off, as given; by default on exactly when the run declares sensor noise
    (``declared_noise_urad`` > 0). Why by that: the profile likelihood measures how far the
    objective's valley lets a base combination move within one unit of the fit's noise; with
    sensor noise that unit is the sensor's and the widened bars were measured honest (z RMS
    3.40 -> 0.93 on table1, 3.19 -> 1.29 on `paper`, consistent model, seeds 1-3), without it
    the unit is the model's own misfit (0.004 urad) and the bars came out ~6x too wide at ~4x the
    time (docs/calibration.md 6, session 17)."""
    if args.method == "paper":
        return False
    if args.profile_bars is not None:
        return bool(args.profile_bars)
    return declared_noise_urad(args, metadata) > 0.0


def add_source_options(parser: argparse.ArgumentParser) -> None:
    """``--scenario`` | ``--data`` (one required), ``--seed``, ``--noise-urad``, ``--provider``."""
    source = parser.add_mutually_exclusive_group(required=True)
    add_scenario(parser, group=source)
    source.add_argument("--data", metavar="CSV", help="a measurement CSV (synthetic or real); its JSON sidecar's "
                                                      "presets, if any, give the error columns")
    add_seed(parser, what="the scenario's drawn errors and noise (default: the scenario's)")
    parser.add_argument("--noise-urad", type=float, default=None, help="sensor noise of the scenario [urad]")
    add_provider(parser, what="for --scenario")
    add_trajectory(parser)
    add_mount(parser, what="the scenario's or the data's (sidecar's) mount; with --data the differences are listed")
    add_unit_check_option(parser)


def add_unit_check_option(parser: argparse.ArgumentParser) -> None:
    """``--skip-unit-check``: read a measurement whose gain or spans do not fit its mount."""
    parser.add_argument("--skip-unit-check", action="store_true",
                        help="read the measurement even when its gain (angle change per input change) or its spans "
                             "do not fit the mount's, which is how angles in rad or inputs in m under the _urad/_mm "
                             "columns show (flexcal.validation.plausibility); for a mount unlike the sidecar's")


def read_data(path, args: argparse.Namespace):
    """The measurement at ``path`` (``--data``, ``DATA.csv``): every message names the file,
    and unless ``--skip-unit-check`` its gain and spans must fit its mount (the sidecar's, or
    the reference mount): ``flexcal.validation.plausibility``."""
    from ..measurements import read_measurement
    from ..plausibility import mount_scale, unit_evidence, unit_problem

    try:
        measurement = read_measurement(path)
    except ValueError as error:  # name the file in every message (some name only the row)
        if str(path) in str(error):
            raise
        raise ValueError(f"{path}: {error}") from None
    if not getattr(args, "skip_unit_check", False):
        scale = mount_scale(data_mechanism(measurement.metadata, args))
        problem = unit_problem(unit_evidence(measurement.inputs, measurement.angles, scale))
        if problem:
            raise ValueError(f"{path}: {problem}")
    return measurement


def load_source(args: argparse.Namespace, space, *, progress: bool):
    """(measurement, presets (45,) [SI] or None) from ``--scenario`` or ``--data``."""
    return load_source_with_truth(args, space, progress=progress)[:2]


def prepare_source_truth(args: argparse.Namespace, *, progress: bool) -> None:
    """Build now the FEM of the truth ``load_source_with_truth`` will make (``--scenario``: its
    prototype's chains, ``truth.prepare_truth``; nothing for ``--data``)."""
    if args.scenario is None:
        return
    from ..prototype.providers import stiffness_provider
    from ..prototype.truth import prepare_truth

    prepare_truth(load_scenario_with_trajectory(args),
                  stiffness_provider(args.provider, progress=progress, **executor_options(args)))


def load_source_with_truth(args: argparse.Namespace, space, *, progress: bool):
    """``load_source`` and the truth of the model-form floor (``runs.form_floor.TruthCurve``:
    the noise-free prototype curve of ``--scenario``, the sidecar's curve of ``--data``; None
    for data without presets)."""
    from ..runs.form_floor import truth_from_measurement, truth_from_run

    _check_noise_option(args)
    if args.scenario is not None:
        from ..prototype.providers import stiffness_provider
        from ..prototype.truth import make_truth

        scenario = load_scenario_with_trajectory(args)

        provider = stiffness_provider(args.provider, progress=progress, **executor_options(args))
        truth = make_truth(scenario, provider, progress=progress)
        return truth.measurement, scenario.values, truth_from_run(truth.run, scenario.values)
    if getattr(args, "trajectory", None):
        raise ValueError("--trajectory drives a --scenario; a --data file already holds its own trajectory")
    measurement = read_data(args.data, args)
    from flexcal.model.parameters import parameter_space

    space = parameter_space(data_mechanism(measurement.metadata, args))  # the presets' ranges are the data's mount's
    found = measurement.metadata.get("preset_errors")
    presets = space.build_values({e["name"]: e["value"] for e in found}, display_units=True) if found else None
    return measurement, presets, truth_from_measurement(measurement, space)


def check_sobol_options(args: argparse.Namespace) -> None:
    from flexcal.calibration.sensitivity import check_n_base

    check_n_base(args.sobol_n, name="--sobol-n")
    if not 0.0 <= args.sobol_threshold <= 1.0:
        raise ValueError(f"--sobol-threshold={args.sobol_threshold} must be in [0, 1]")


def add_point_model_options(parser: argparse.ArgumentParser) -> None:
    """The analytic model at one point (``forward``, ``inverse``): travel directions, error
    sources from a file, which model terms, output form."""
    parser.add_argument("--directions", metavar="D1,D2,D3",
                        help="travel direction of each actuator, +1 (last move towards the payload) or -1; "
                             "default +1,+1,+1")
    parser.add_argument("--params", metavar="FILE",
                        help="TOML/JSON file of error sources in display units, e.g. \"D1.CL\" = 0.25 "
                             "(names and ranges: docs/parameters.md); default all nominal")
    parser.add_argument("--no-parasitic", action="store_true", help="leave out the parasitic shortening (Eq. 4-5)")
    parser.add_argument("--no-clearance", action="store_true", help="leave out clearance and hysteresis (Eq. 6-7)")
    parser.add_argument("--clearance-mode", choices=("force_only", "directional"), default="force_only",
                        help="how the travel direction enters the clearance (docs/model.md); default force_only")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    parser.add_argument("--out", metavar="DIR",
                        help="also write the point as DIR/report.json and DIR/report.md (optional)")
    add_mount(parser, what="the reference mount")
