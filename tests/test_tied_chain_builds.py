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
    def matrices(chain, ties, material, *, elements_through_thickness, cache_directory=None, keep_segments=False):
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
        plans.append((job, kw["workers"], kw["in_threads"], kw["job_options"]["solver_threads"],
                      kw["job_options"]["keep_segments"]))
        return {}

    monkeypatch.setattr(executor, "run_jobs", record)
    monkeypatch.setattr(executor, "usable_cores", lambda: 2)
    mechanism = reference_mechanism()
    provider = tc.tied_fem_provider(progress=False, workers=None, cache_directory=tmp_path)
    provider.prepare_chains(list(dict.fromkeys(p.chain for p in mechanism.chains)))
    # the nominal mount's six chains are three designs: each built once, on two threads of one core each
    assert submitted == list(dict.fromkeys(p.chain for p in mechanism.chains)) and len(submitted) == 3
    # and the prototype's chains keep no segment entries (they share none; docs/scale.md, session 27)
    assert plans == [(tc.build_tied_chain_job, 2, True, 1, False)]


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


def test_a_moved_chain_shares_exactly_the_unchanged_slices_segment_entries():
    """The tied chains' segment entries (``tied_segment_keys``, keyed on the pieces) of a chain
    moved as the slopes move it (``SLOPE_STEPS``) are the nominal chain's exactly for the slices
    ``unchanged_slices`` names (the rigid provider's rule), on table1's two designs; every other
    entry is a key of its own, and a segment with another cut field, on another grid or of a chain
    of another length has its own."""
    import dataclasses

    from flexcal.model.parameters import DIMENSION_FIELDS, parameter_space
    from flexcal.validation.runs.model_correction import SLOPE_STEPS, unchanged_slices

    through = fp.DEFAULT_ELEMENTS_THROUGH
    for c in (0, 3):  # L1, D1
        nominal = parameter_space().mechanism.chains[c].chain
        keys = tc.tied_segment_keys(nominal, elements_through_thickness=through)
        assert len(keys) == len(set(keys.values())) == 3
        for symbol, field in DIMENSION_FIELDS.items():
            for sign in (1, -1):
                moved = dataclasses.replace(nominal, **{field: getattr(nominal, field) * (1 + sign * SLOPE_STEPS[symbol])})
                shared = {plan[:2] for plan, key in tc.tied_segment_keys(moved, elements_through_thickness=through).items()
                          if key in keys.values()}
                half = {(round(x0, 12), round(x1, 12)) for x0, x1 in unchanged_slices(nominal, moved)
                        if x0 < 0.5 * nominal.length}
                assert shared == half, (c, symbol, sign)
                assert len(shared) == {"w": 1, "a": 1, "l": 0, "t1": 2, "t2": 2}[symbol]
        # the ties "d12/d8" have the d12 cut at m1 too: [0, m1] (its other end rigid) is the same
        # condensation; [m1, s0] and the strut (d8 at s0, s1) are not
        d8 = tc.tied_segment_keys(nominal, "d12/d8", elements_through_thickness=through)
        assert [key in keys.values() for key in d8.values()] == [True, False, False]
        assert not set(keys.values()) & set(tc.tied_segment_keys(nominal, elements_through_thickness=through - 1).values())
    # L2 is 1 ulp longer than L1, the same pieces: kept apart, as unchanged_slices keeps it (its
    # own chain for the shortening probe, docs/calibration.md "Session 25")
    l1, l2 = (placement.chain for placement in parameter_space().mechanism.chains[:2])
    assert l1.length != l2.length and not unchanged_slices(l1, l2)
    assert not set(tc.tied_segment_keys(l1, elements_through_thickness=through).values()) & set(
        tc.tied_segment_keys(l2, elements_through_thickness=through).values())


def test_a_moved_chain_built_on_the_nominal_chains_segments_is_the_one_built_alone_to_the_bit(tmp_path, monkeypatch):
    """Built after the nominal chain with ``keep_segments``, a chain with t1 moved condenses only
    its [0, m1] (its [m1, s0] and strut are the nominal's entries) and is the same chain, to the
    bit, as built in a cache of its own without them, which holds the chain's entry alone (D1 on
    2 cells through, to be quick)."""
    import dataclasses

    import flexcal.validation.prototype.cut_fields as cf

    nominal = reference_mechanism().chains[3].chain
    moved = dataclasses.replace(nominal, thickness_1=nominal.thickness_1 * 1.03)
    condense, calls = cf.interface_segment_stiffness, []

    def counted(segment, *args):
        calls.append((segment.x_start, segment.x_end))
        return condense(segment, *args)

    monkeypatch.setattr(cf, "interface_segment_stiffness", counted)
    tc.tied_chain_matrices(nominal, elements_through_thickness=2, cache_directory=tmp_path / "shared",
                           keep_segments=True)
    assert len(calls) == 3
    shared = tc.tied_chain_matrices(moved, elements_through_thickness=2, cache_directory=tmp_path / "shared",
                                    keep_segments=True)
    assert len(calls) == 4 and calls[-1] == (0.0, round(float(section_nodes(moved)[1]), 12))
    alone = tc.tied_chain_matrices(moved, elements_through_thickness=2, cache_directory=tmp_path / "alone")
    assert len(calls) == 7
    for name in ("stiffness", "segments"):
        np.testing.assert_array_equal(shared[name], alone[name])
    # two chains and their 3 + 1 segment entries kept; without keep_segments the chain's entry alone
    assert len(list((tmp_path / "shared").glob("*.npz"))) == 6
    assert [f.name for f in (tmp_path / "alone").glob("*.npz")] == [
        tc.tied_chain_key(moved, elements_through_thickness=2) + ".npz"]
    assert not np.array_equal(shared["stiffness"],
                              tc.tied_chain_matrices(nominal, elements_through_thickness=2,
                                                     cache_directory=tmp_path / "shared")["stiffness"])


def test_the_slopes_hand_out_the_nominal_chains_first(monkeypatch, tmp_path):
    """The tied slopes' builds start with the two nominal designs (L1, D1), so that the moved
    chains on the other job thread find the segments they share with them."""
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.runs.model_correction import compliance_slopes

    submitted, keep = [], []

    def record(items, job, on_done, **kw):
        submitted.extend(items)
        keep.append(kw["job_options"]["keep_segments"])
        return {}

    monkeypatch.setattr(executor, "run_jobs", record)
    monkeypatch.setattr(executor, "usable_cores", lambda: 2)
    monkeypatch.setattr(tc, "tied_chain_matrices", _fake_matrices([]))  # the chains as the loop then asks for them
    space = parameter_space()
    compliance_slopes(space, tc.tied_fem_provider(progress=False, workers=None, cache_directory=tmp_path))
    assert submitted[:2] == [space.mechanism.chains[0].chain, space.mechanism.chains[3].chain]
    assert len(submitted) == 22 == len(set(submitted))  # and the 2 x 5 x 2 moved ones
    assert keep == [True]  # their segment entries kept, for each other to share


def test_the_curvatures_moved_chains_keep_their_segments(monkeypatch, tmp_path):
    """The curvatures' moved chains (a pair's chain shares segments with the pair's single moves
    and the nominal chain) are built keeping their segment entries, as the slopes' are."""
    from flexcal.model.parameters import parameter_space
    from flexcal.validation.runs.dimension_terms import compliance_curvatures

    keep = []

    def record(items, job, on_done, **kw):
        keep.append((len(items), kw["job_options"]["keep_segments"]))
        return {}

    monkeypatch.setattr(executor, "run_jobs", record)
    monkeypatch.setattr(executor, "usable_cores", lambda: 2)
    monkeypatch.setattr(tc, "tied_chain_matrices", _fake_matrices([]))
    compliance_curvatures(parameter_space(), tc.tied_fem_provider(progress=False, workers=None,
                                                                   cache_directory=tmp_path))
    # the 2 designs' single moves at +-step and pair moves at +step (then the nominal chains for the
    # factors, which this fake executor never stored)
    assert keep[0] == (2 * (5 * 2 + 10), True)


def test_a_tied_chain_holds_the_same_bits_built_alone_on_every_core_or_beside_another(tmp_path):
    """The entry of a chain built here with PARDISO and BLAS on two threads (all of this machine's
    cores, as a lone build had them) is the one built on a job thread beside another chain: an
    entry is computed on one thread (``fem.cache.cached``). Before, D1 on 2 cells through came
    out 3.8e-15 relative apart, and 1.4e-13 for table1's L2 on the prototype's grid, which the
    shortening probe turned into a noise-free run's other estimate (docs/scale.md, "Issue 26,
    session 36")."""
    import dataclasses

    from flexcal.fem.solve import solver_threads
    from flexcal.validation.blas_threads import blas_threads

    chain = reference_mechanism().chains[3].chain
    other = dataclasses.replace(chain, thickness_1=chain.thickness_1 * 1.03)
    with solver_threads(2), blas_threads(2):
        here = tc.tied_chain_matrices(chain, elements_through_thickness=2, cache_directory=tmp_path / "here")
    assert tc.build_tied_chains([chain, other], elements_through_thickness=2, cache_directory=tmp_path / "pair",
                                workers=2, progress=False) == 2
    beside = tc.tied_chain_matrices(chain, elements_through_thickness=2, cache_directory=tmp_path / "pair")
    # a lone job on the executor (it had every core: both MKL threads and the BLAS pools unlimited)
    assert tc.build_tied_chains([chain], elements_through_thickness=2, cache_directory=tmp_path / "lone",
                                workers=None, progress=False) == 1
    lone = tc.tied_chain_matrices(chain, elements_through_thickness=2, cache_directory=tmp_path / "lone")
    for name in ("stiffness", "segments"):
        np.testing.assert_array_equal(here[name], beside[name])
        np.testing.assert_array_equal(lone[name], beside[name])
