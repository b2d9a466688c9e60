"""cli.opening: a --scenario run's opening builds the model's FEM first, then sets the model up on
the main thread while another thread builds the truth's FEM (started from model_space's
after_batch), under one BLAS thread, and returns
what the sequential opening returns (the FEM and the models are stubbed: only the order, the
threads and the BLAS limits are under test; the real numbers are the slow tests' and the cold
runs', docs/scale.md "Issue 26, session 41")."""

import threading
import time

import pytest
from threadpoolctl import threadpool_info

from flexcal.validation import cli
from flexcal.validation.cli import opening, options


def _args(*extra):
    return cli.build_parser(only="verify").parse_args(["verify", "--scenario", "table1", "--out", "o", *extra])


def _blas_threads():
    """The thread counts of the process's OpenBLAS pools (numpy's, scipy's): global, the ones a
    limit on one thread sets for all. MKL's follows OpenMP's count, each thread's own (a new thread
    starts at the machine's): a FEM job holds its own at one (``fem.solve.one_thread``)."""
    return {pool["num_threads"] for pool in threadpool_info() if pool["internal_api"] == "openblas"}


@pytest.fixture
def stubs(monkeypatch):
    """Stubbed halves of the opening that record (what, thread, BLAS threads, start, end)."""
    log = []

    def record(what, seconds=0.0):
        start = time.perf_counter()
        time.sleep(seconds)  # long enough for the other thread to start beside it
        log.append((what, threading.current_thread().name, _blas_threads(), start, time.perf_counter()))

    def data(args, *, progress, data_path=None):
        record("data")
        return opening.DataOpening(measurement="measured", presets=None, truth=None,
                                   mechanism=options.load_scenario_with_trajectory(args).space.mechanism)

    def model(args, mechanism, *, progress, after_batch=None):
        record("model batch")
        if after_batch is not None:
            after_batch()
        record("model", 0.3)
        return "space"

    monkeypatch.setattr(options, "prepare_source_truth", lambda args, progress: record("truth FEM", 0.3))
    monkeypatch.setattr(opening, "calibration_model", model)
    monkeypatch.setattr(opening, "open_data", data)
    return log


def test_the_model_is_set_up_beside_the_truths_fem_on_one_blas_thread(stubs):
    found = opening.open_calibration(_args(), progress=False)
    assert (found.space, found.measurement) == ("space", "measured")
    steps = {what: (thread, blas, start, end) for what, thread, blas, start, end in stubs}
    assert [what for what, *_ in stubs][0] == "model batch" and [what for what, *_ in stubs][-1] == "data"
    main = threading.main_thread().name
    assert steps["model"][0] == main and steps["truth FEM"][0] != main
    # side by side, the truth's FEM started after the model's batch: each started before the other ended
    assert steps["model batch"][3] <= steps["truth FEM"][2]
    assert steps["model"][2] < steps["truth FEM"][3] and steps["truth FEM"][2] < steps["model"][3]
    assert steps["model"][1] == steps["truth FEM"][1] == {1}
    assert steps["data"][2] >= max(steps["model"][3], steps["truth FEM"][3])  # the truth's FEM is cached by then


def test_a_model_without_the_quadratic_terms_or_a_check_opens_in_order(stubs):
    for other in (["--dimension-terms", "linear"], ["--model", "second-order"]):
        opening.open_calibration(_args(*other), progress=False)
        assert [what for what, *_ in stubs] == ["data", "model batch", "model"]
        assert {thread for _, thread, *_ in stubs} == {threading.main_thread().name}
        stubs.clear()
    checked = []
    opening.open_calibration(_args(), progress=False, check=checked.append)
    assert [what for what, *_ in stubs] == ["data", "model batch", "model"] and checked == ["measured"]


def test_a_bad_scenario_fails_before_the_models_fem(stubs):
    with pytest.raises(ValueError, match="must be >= 0"):
        opening.open_calibration(_args("--noise-urad", "-1"), progress=False)
    with pytest.raises(ValueError, match="scenario table1"):
        opening.open_calibration(_args("--noise-urad", "1e9"), progress=False)
    assert stubs == []


def test_a_data_mount_other_than_the_scenarios_gets_its_own_model(stubs, monkeypatch):
    import dataclasses

    models = []
    monkeypatch.setattr(opening, "calibration_model",
                        lambda args, mechanism, progress, after_batch=None: models.append(mechanism))
    real_data = opening.open_data

    def other_mount(args, *, progress, data_path=None):
        found = real_data(args, progress=progress)
        first = found.mechanism.chains[0]
        wider = dataclasses.replace(first, chain=dataclasses.replace(first.chain, width=first.chain.width * 1.1))
        return dataclasses.replace(found, mechanism=dataclasses.replace(found.mechanism,
                                                                        chains=(wider, *found.mechanism.chains[1:])))

    monkeypatch.setattr(opening, "open_data", other_mount)
    opening.open_calibration(_args(), progress=False)
    assert len(models) == 2 and models[1] != models[0]


def test_the_truths_fem_prepared_ahead_is_what_the_truth_then_asks_for(monkeypatch):
    """``truth.prepare_truth`` asks the provider for the chains ``make_truth``'s prototype reads,
    the mount offsets applied (they move the chains' ends: a prefetch without them built six
    chains the truth then did not read, and the truth built three again)."""
    from flexcal.validation.prototype import mechanism, truth
    from flexcal.validation.prototype.providers import stiffness_provider

    asked = []
    real = mechanism.prepare_chains
    monkeypatch.setattr(mechanism, "prepare_chains", lambda provider, chains: asked.append(list(chains))
                        or real(provider, chains))
    scenario = options.load_scenario_with_trajectory(_args())
    provider = stiffness_provider("analytic", progress=False)
    truth.prepare_truth(scenario, provider)
    truth.make_truth(scenario, provider)
    assert len(asked) == 2 and asked[0] == asked[1]
    assert asked[0] != [p.chain for p in truth.as_built(scenario.space, scenario.values)[0].chains]  # offsets moved them


def test_the_models_batch_then_the_hook_then_its_set_up(monkeypatch):
    """``model_space`` calls ``after_batch`` once the consistent model's FEM batch (``also_build``)
    is built and before its set-up reads it; a model without that batch never calls it."""
    from flexcal.validation.runs import model_correction

    order = []

    class SetUp(Exception):
        pass

    def set_up(*args, **kwargs):
        order.append("set-up")
        raise SetUp

    monkeypatch.setattr(model_correction, "model_provider", lambda *args, **kwargs: "provider")
    monkeypatch.setattr(model_correction, "corrected_space", set_up)
    with pytest.raises(SetUp):
        model_correction.model_space("fem", model="consistent", also_build=lambda space, provider: order.append("batch"),
                                     after_batch=lambda: order.append("after"))
    assert order == ["batch", "after", "set-up"]
    order.clear()
    import flexcal.validation.prototype.providers as providers

    monkeypatch.setattr(providers, "stiffness_provider", lambda *args, **kwargs: "provider")
    with pytest.raises(SetUp):
        model_correction.model_space("fem", model="second-order", after_batch=lambda: order.append("after"))
    assert order == ["set-up"]
