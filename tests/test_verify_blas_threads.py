"""``flexcal verify``'s estimate runs its dense algebra on one BLAS thread (runs.verify,
``single_blas_thread``): on 2 cores the threaded BLAS made the README's warm main job 44 s
against 30 s (session 21, docs/scale.md "Session 21"); and its model batches on every usable
core (``IdentificationSettings.n_threads``; the same bits on any count, session 32)."""

from threadpoolctl import threadpool_info

import flexcal.validation.runs.verify as verify_module
from flexcal.validation import cli
from flexcal.validation.executor import usable_cores


def test_the_estimate_runs_on_one_blas_thread(tmp_path, monkeypatch):
    seen, model_threads = [], []
    real = verify_module.identify_all

    def recording(*args, **kwargs):
        seen.append([pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"])
        model_threads.append(args[4].n_threads)
        return real(*args, **kwargs)
    monkeypatch.setattr(verify_module, "identify_all", recording)
    assert cli.main(["verify", "--scenario", "table1", "--provider", "analytic", "--model", "second-order",
                     "--model-stiffness", "closed-form", "--prior-scale", "1", "--no-error-budget",
                     "--out", str(tmp_path / "run"), "-q"]) == 0
    assert seen and all(threads == [1] * len(threads) and threads for threads in seen)
    assert model_threads == [usable_cores()] * len(seen)


def test_the_papers_method_runs_its_model_batches_on_every_usable_core(tmp_path, monkeypatch):
    """The Sobol screening's problem and the swarm's (``identify_swarm(n_threads=...)``)."""
    screening, swarm = [], []
    real_problem, real_swarm = verify_module.CalibrationProblem, verify_module.identify_swarm

    def problem(**kwargs):
        screening.append(kwargs.get("n_threads", 1))
        return real_problem(**kwargs)

    def recording(*args, **kwargs):
        swarm.append(kwargs.get("n_threads", 1))
        return real_swarm(*args, **kwargs)
    monkeypatch.setattr(verify_module, "CalibrationProblem", problem)
    monkeypatch.setattr(verify_module, "identify_swarm", recording)
    assert cli.main(["verify", "--scenario", "table1", "--provider", "analytic", "--model", "second-order",
                     "--model-stiffness", "closed-form", "--method", "paper", "--sobol-n", "8", "--particles", "40",
                     "--iterations", "3", "--no-error-budget", "--out", str(tmp_path / "run"), "-q"]) == 0
    assert screening == [usable_cores()] and swarm == [usable_cores()]


def test_a_caller_running_identifications_side_by_side_gives_each_one_thread(monkeypatch):
    """``VerifySettings.model_threads`` (a sweep's designs: 1, ``sweep.identify``) reaches the
    estimate; None is every usable core; anything but a count >= 1 is refused."""
    import numpy as np
    import pytest

    from flexcal.model.parameters import parameter_space
    from flexcal.validation.runs.settings import VerifySettings

    class Stop(Exception):
        pass

    seen = []

    def stop(*args, **kwargs):
        seen.append(args[4].n_threads)
        raise Stop
    monkeypatch.setattr(verify_module, "identify_all", stop)
    measurement = type("M", (), {"inputs": np.zeros((77, 3)), "leg": np.ones(77, int)})()
    for threads in (1, None):
        with pytest.raises(Stop):
            verify_module._estimated_identification(measurement, np.zeros((77, 3)), parameter_space(),
                                                    VerifySettings(model_threads=threads), log=lambda _: None)
    assert seen == [1, usable_cores()]
    for threads in (0, 2.0):
        with pytest.raises(ValueError, match="model_threads"):
            VerifySettings(model_threads=threads)
