"""The commands whose model batches are many candidates (a Jacobian's 46, a Sobol sample's
chunks) run them on every usable core: ``flexcal sensitivity``'s screening and ``flexcal
design``'s Jacobians and ``flexcal diagnose``'s baseline, as verify's estimate (tests/test_verify_blas_threads.py). The bits do not
depend on the count (``model.forward``, tests/test_model_forward.py); measured, session 32:
sensitivity 27.8 -> 19.0 s, design 34.5 -> 32.2 s on table1 (docs/scale.md)."""

import pytest

import flexcal.calibration.problem as problem_module
from flexcal.validation import cli
from flexcal.validation.executor import usable_cores
from test_cli_common import small_csv  # noqa: F401 (a fixture)


def recorded_model_threads(monkeypatch) -> list:
    """The thread counts the problems ask ``model.forward`` for, call by call (filled as they run)."""
    asked = []
    real = problem_module.forward

    def recording(*args, **kwargs):
        asked.append(kwargs.get("n_threads", 1))
        return real(*args, **kwargs)
    monkeypatch.setattr(problem_module, "forward", recording)
    return asked


def test_the_screening_runs_on_every_usable_core(tmp_path, small_csv, monkeypatch):  # noqa: F811
    asked = recorded_model_threads(monkeypatch)
    assert cli.main(["sensitivity", "--data", str(small_csv), "--model", "second-order", "--sobol-n", "4",
                     "--out", str(tmp_path / "out"), "-q"]) == 0
    assert asked and set(asked) == {usable_cores()}


def test_the_designs_jacobians_run_on_every_usable_core(tmp_path, monkeypatch):
    asked = recorded_model_threads(monkeypatch)
    assert cli.main(["design", "--model", "second-order", "--points", "41", "--candidates", "200",
                     "--model-stiffness", "closed-form", "--inadequacy", "none", "--out", str(tmp_path / "design"),
                     "-q"]) == 0
    assert asked and set(asked) == {usable_cores()}


def test_the_diagnosis_baseline_runs_on_every_usable_core(tmp_path, monkeypatch):
    """The baseline's swarm and polish (session 33: table1's noise-free diagnosis 27.9 -> 20.8 s);
    the same bits at any count (tests/test_model_forward.py). Blind data of the analytic prototype
    (tests/test_diagnose.py's)."""
    from flexcal.validation.diagnosis.benchmark import benchmark_measurement
    from flexcal.validation.measurements import write_measurement
    from flexcal.validation.prototype.segments import analytic_provider

    data = tmp_path / "curves.csv"
    write_measurement(data, benchmark_measurement("none", 0.0, 0, analytic_provider()).measurement)
    asked = recorded_model_threads(monkeypatch)
    assert cli.main(["diagnose", str(data), "--model", "second-order", "--model-stiffness", "closed-form",
                     "--particles", "40", "--iterations", "2", "--out", str(tmp_path / "diagnosis"), "-q"]) == 0
    assert asked and set(asked) == {usable_cores()}


def test_the_baseline_and_the_problem_refuse_a_thread_count_below_one():
    """One rule (``calibration.problem.check_thread_count``) for every holder of a thread count."""
    import numpy as np

    from flexcal.calibration.problem import CalibrationProblem
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.diagnosis.baseline import calibrate_baseline

    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="n_threads"):
            calibrate_baseline(None, n_threads=bad)
        with pytest.raises(ValueError, match="n_threads"):
            CalibrationProblem(space=parameter_space(), inputs=np.zeros((4, 3)), angles=np.zeros((4, 3)),
                               n_threads=bad)


def test_the_benchmarks_null_runs_its_baselines_on_every_usable_core(monkeypatch):
    """The null's `none` files are diagnosed in this process one after the other (its cases, on
    parallel workers, keep one thread each). Small baselines: the count is what is checked."""
    import flexcal.validation.diagnosis.baseline as baseline_module
    from flexcal.validation.cli.diagnose_benchmark import benchmark_null
    from flexcal.validation.runs.model_correction import model_space
    from flexcal.validation.runs.settings import BaselineSettings

    seen = []
    real = baseline_module.calibrate_baseline

    def small(measurement, rng=None, progress=False, settings=None, space=None, n_threads=1):
        seen.append(n_threads)
        return real(measurement, rng, progress, BaselineSettings(particles=40, iterations=2, starts=1), space,
                    n_threads)

    monkeypatch.setattr(baseline_module, "calibrate_baseline", small)
    null = benchmark_null(provider_name="analytic", noise_urad=0.5, cycles=1, seed=0,
                          space=model_space("closed-form", second_order=True))
    assert null.n_files == len(seen) == 3 and set(seen) == {usable_cores()}


def test_the_benchmarks_cases_here_run_the_baseline_on_every_core_and_on_workers_on_one(tmp_path, monkeypatch):
    """Cases one after the other in this process (``--workers 0``, the default) hand the baseline
    every usable core; cases on parallel workers or a cluster one thread each. The diagnosis is a
    stub (the real one: test_diagnose)."""
    import flexcal.validation.diagnosis.diagnose as diagnose
    import flexcal.validation.executor as executor
    from flexcal.validation.cli.diagnose_benchmark import run_benchmark
    from test_diagnose_benchmark_mount import Stub

    baselines = []
    monkeypatch.setattr(diagnose, "run_diagnosis", lambda m, **options: baselines.append(options["baseline"]) or Stub())
    assert cli.main(["diagnose-benchmark", "--grid", "tiny", "--effects", "none", "--workers", "0", "--no-null", "-q",
                     "--out", str(tmp_path / "bench")]) == 0
    assert baselines and {b.keywords["n_threads"] for b in baselines} == {usable_cores()}
    asked = []
    monkeypatch.setattr(executor, "run_jobs", lambda items, job, on_done, **kw: asked.append(
        (kw["workers"], kw["scheduler"], kw["job_options"]["model_threads"])) or {})
    for workers, scheduler in ((0, None), (2, None), (0, "tcp://127.0.0.1:1")):
        run_benchmark(["none"], "tiny", noise_urad=0.5, cycles=2, seed=0, progress=False, workers=workers,
                      scheduler=scheduler)
    assert [threads for *_, threads in asked] == [usable_cores(), 1, 1]
