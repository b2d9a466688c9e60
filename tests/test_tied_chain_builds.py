"""The tied provider's builds (validation/prototype/tied_chains.py; docs/meshing.md, "Session
24: the tied-cut frame", "Cost, session 24 (cost26)"): one set of condensations per chain gives
both K_chain and the segments' 12 x 12, and the chains are built on the executor's threads."""

import numpy as np
import pytest

import flexcal.validation.executor as executor
import flexcal.validation.prototype.fem_provider as fp
import flexcal.validation.prototype.tied_chains as tc
from flexcal.geometry.params import reference_mechanism
from flexcal.validation.prototype.segments import chain_slices, section_nodes


def _fake_matrices(calls):
    def matrices(chain, ties, material, *, elements_through_thickness, cache_directory=None):
        calls.append(chain)
        segments = np.arange(5 * 144, dtype=float).reshape(5, 12, 12) + chain.length
        return {"stiffness": np.eye(30) * chain.length, "segments": segments}

    return matrices


def test_the_tied_provider_gives_the_chains_own_segments_from_its_condensations_and_builds_no_rigid_one(monkeypatch):
    calls = []
    monkeypatch.setattr(tc, "tied_chain_matrices", _fake_matrices(calls))

    def no_rigid(*args, **kwargs):
        raise AssertionError("the tied provider built a rigidly tied segment")

    monkeypatch.setattr(fp, "segment_stiffness_fem", no_rigid)
    provider = tc.tied_fem_provider(progress=False, workers=0)
    assert provider.prepare([]) == 0  # workers=0: each chain is built at its first call
    chain = reference_mechanism().chains[3].chain
    nodes = section_nodes(chain)
    for s, (a, b) in enumerate(zip(nodes[:-1], nodes[1:])):
        expected = np.arange(5 * 144, dtype=float).reshape(5, 12, 12)[s] + chain.length
        np.testing.assert_array_equal(provider(chain, float(a), float(b)), expected)
    np.testing.assert_array_equal(provider.chain_stiffness(chain), np.eye(30) * chain.length)
    assert calls == [chain] * 6
    with pytest.raises(ValueError, match="chain's own segments"):
        provider(chain, float(nodes[0]), float(nodes[2]))
    # the rigid provider's attributes stay (its grid, executor, mesher)
    assert provider.mesher == "mapped" and provider.workers == 0 and callable(provider.on_grid)


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
    provider.prepare(chain_slices(p.chain for p in mechanism.chains))
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
