"""The tied provider's builds (validation/prototype/tied_chains.py; docs/meshing.md, "Session
24: the tied-cut frame", "Cost, session 24 (cost26)"): one set of condensations per chain gives
both K_chain and the segments' 12 x 12, and the chains are built on the executor's threads."""

import numpy as np
import pytest

import flexcal.validation.executor as executor
import flexcal.validation.prototype.fem_provider as fp
import flexcal.validation.prototype.tied_chains as tc
from flexcal.geometry.params import reference_mechanism
from flexcal.validation.prototype.mechanism import build_prototype
from flexcal.validation.prototype.segments import analytic_provider, section_nodes
from flexcal.validation.prototype.transmission import ActuatorTransmission


def _fake_matrices(calls):
    """tied_chain_matrices from the analytic segments: the 12 x 12 as they are, K_chain their end
    blocks side by side (what rigid ties give, test_chain_twist_stiffness.py)."""
    def matrices(chain, ties, material, *, elements_through_thickness, cache_directory=None):
        calls.append(chain)
        nodes = section_nodes(chain)
        segments = np.array([analytic_provider()(chain, float(a), float(b)) for a, b in zip(nodes[:-1], nodes[1:])])
        stiffness = np.zeros((30, 30))
        for s, k in enumerate(segments):
            stiffness[6 * s:6 * s + 6, 6 * s:6 * s + 6] = k[6:, 6:]
        return {"stiffness": stiffness, "segments": segments}

    return matrices


def test_the_tied_prototype_takes_its_segments_from_the_chains_condensations_and_builds_no_rigid_one(monkeypatch):
    calls = []
    monkeypatch.setattr(tc, "tied_chain_matrices", _fake_matrices(calls))

    def no_rigid(*args, **kwargs):
        raise AssertionError("the tied prototype built a rigidly tied segment")

    monkeypatch.setattr(fp, "segment_stiffness_fem", no_rigid)
    provider = tc.tied_fem_provider(progress=False, workers=0)
    assert provider.prepare_chains([]) == 0  # workers=0: each chain is built at its first call
    mechanism = reference_mechanism()
    transmissions = [ActuatorTransmission(initial_position=-0.2e-3, clearance=0.42e-3, hysteresis=0.83)] * 3
    prototype = build_prototype(mechanism, transmissions, provider)
    for c, placement in enumerate(mechanism.chains):
        expected = _fake_matrices([])(placement.chain, "", None, elements_through_thickness=7)
        segments = expected["segments"]  # build_prototype stores them symmetrised, as every provider's
        np.testing.assert_array_equal(prototype.segment_stiffness_12[c], 0.5 * (segments + segments.transpose(0, 2, 1)))
        np.testing.assert_array_equal(prototype.chain_stiffness[c], expected["stiffness"])
    assert set(calls) == {p.chain for p in mechanism.chains}
    # the provider's own slices stay the rigidly tied segments' (the model's corrections ask for them)
    with pytest.raises(AssertionError, match="built a rigidly tied segment"):
        provider(mechanism.chains[0].chain, 0.0, float(section_nodes(mechanism.chains[0].chain)[1]))


def test_the_tied_chains_go_to_job_threads_once_each(monkeypatch, tmp_path):
    plans, submitted = [], []

    def record(items, job, on_done, **kw):
        submitted.extend(items)
        plans.append((job, kw["workers"], kw["in_threads"], kw["job_options"]["solver_threads"]))
        return {}

    monkeypatch.setattr(executor, "run_jobs", record)
    monkeypatch.setattr(executor, "usable_cores", lambda: 2)
    mechanism = reference_mechanism()
    provider = tc.tied_fem_provider(progress=False, workers=None, cache_directory=tmp_path)
    provider.prepare_chains(list(dict.fromkeys(p.chain for p in mechanism.chains)))
    # the nominal mount's six chains are three designs: each built once, on two threads of one core each
    assert submitted == list(dict.fromkeys(p.chain for p in mechanism.chains)) and len(submitted) == 3
    assert plans == [(tc.build_tied_chain_job, 2, True, 1)]


@pytest.mark.slow
def test_a_tied_chain_built_on_a_job_thread_is_the_one_built_here_to_the_bit(tmp_path):
    from flexcal.fem.solve import solver_threads

    from flexcal.validation.executor import usable_cores

    chain = reference_mechanism().chains[3].chain  # a driving chain: the smallest condensations
    assert tc.build_tied_chains([chain], cache_directory=tmp_path / "thread", workers=1, progress=False,
                                elements_through_thickness=fp.DEFAULT_ELEMENTS_THROUGH) == 1
    cores = fp.plan_local_builds(1, 1, cores=usable_cores(), available_bytes=0.0)[1]
    with solver_threads(cores):  # PARDISO on the job's threads (plan_local_builds of this 1-job build)
        here = tc.tied_chain_matrices(chain, elements_through_thickness=fp.DEFAULT_ELEMENTS_THROUGH,
                                      cache_directory=tmp_path / "here")
    there = tc.tied_chain_matrices(chain, elements_through_thickness=fp.DEFAULT_ELEMENTS_THROUGH,
                                   cache_directory=tmp_path / "thread")  # a cache hit: the job thread's
    for name in ("stiffness", "segments"):
        np.testing.assert_array_equal(there[name], here[name])
