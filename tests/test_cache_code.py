"""The code outside flexcal.fem and flexcal.geometry that computes a cached result is in that
result's key (``flexcal.fem.cache.sources_digest``): an edit of it is a new key, never a stale
entry. Each entry kind names its modules (``*_CODE``); the tracing tests check that the list
holds every module of flexcal.validation whose code runs while such an entry is computed (the
sweep's summaries are fTetWild builds, too slow for the default run: their list is by reading
``sweep.job._hinge_fem`` / ``_chain_fem``)."""

import dataclasses
import importlib
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import flexcal.fem.cache as cache
import flexcal.validation
import flexcal.validation.prototype.cut_fields as cut_fields
import flexcal.validation.prototype.fem_provider as fp
import flexcal.validation.prototype.tied_chains as tc
import flexcal.validation.runs.chain_kinematics as ck
import flexcal.validation.structure.fem_segments as structure
import flexcal.validation.sweep.job as sweep_job
from flexcal.geometry.params import STEEL, reference_mechanism
from flexcal.validation.prototype.segments import analytic_provider

CHAIN = reference_mechanism().chains[3].chain  # a driving chain: 150 mm, the cheaper FEM
UNRELATED = "flexcal.validation.prototype.mechanism"  # computes none of these entries


def _segment():
    return fp.canonical_segment(CHAIN, 0.0, CHAIN.length / 2)[0]


def _edited(monkeypatch, module: str) -> None:
    """``module``'s source as if edited on disk, and the digests read afresh (not once per process)."""
    origin = Path(importlib.import_module(module).__file__).resolve()
    read_bytes = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes",
                        lambda path: read_bytes(path) + (b"# edited\n" if Path(path).resolve() == origin else b""))
    monkeypatch.setattr(cache, "sources_digest", lambda *modules: cache._modules_digest(modules))


def test_the_digest_follows_the_named_modules_sources(monkeypatch):
    named = ("flexcal.validation.prototype.cut_fields", "flexcal.validation.prototype.segments")
    before = cache._modules_digest(named)
    assert cache.sources_digest(*named) == before
    _edited(monkeypatch, UNRELATED)
    assert cache._modules_digest(named) == before
    _edited(monkeypatch, "flexcal.validation.prototype.segments")
    assert cache._modules_digest(named) != before
    with pytest.raises(ValueError, match="no Python source"):
        cache._modules_digest(("flexcal.validation.no_such_module",))


KEYS = {  # entry kind -> (its modules, its key for the reference driving chain's entry)
    "segment": (fp.SEGMENT_CODE, lambda: fp.segment_cache_key(_segment())),
    "condensation": (cut_fields.CONDENSATION_CODE, lambda: cache.cache_key(cut_fields.interface_condensation_parts(
        _segment(), False, True, ("d12", "d12"), 0.025, 7.0, {}))),
    "tied chain": (tc.TIED_CHAIN_CODE, lambda: tc.tied_chain_key(CHAIN, elements_through_thickness=7.0)),
    "structure segment": (structure.STRUCTURE_SEGMENT_CODE,
                          lambda: cache.cache_key(structure._parts(_segment(), STEEL, 2.0, "mapped"))),
    "sweep summary": (sweep_job.SUMMARY_CODE, lambda: cache.cache_key(sweep_job.summary_parts(CHAIN, STEEL, 2.0))),
}


@pytest.mark.parametrize("kind", list(KEYS))
def test_an_edit_of_an_entrys_code_is_a_new_key(monkeypatch, kind):
    modules, key = KEYS[kind]
    before = key()
    for module in modules:
        with monkeypatch.context() as patch:
            _edited(patch, module)
            assert key() != before, module
    with monkeypatch.context() as patch:
        _edited(patch, UNRELATED)
        assert key() == before


def test_a_probe_is_read_back_to_the_bit_and_computed_again_after_an_edit_of_its_code(monkeypatch, tmp_path):
    calls = []
    probe = ck._probe
    monkeypatch.setattr(ck, "_probe", lambda *args: calls.append(1) or probe(*args))
    provider = analytic_provider()
    provider.cache_directory = tmp_path  # as the FEM providers carry theirs
    first = ck.chain_shortening(CHAIN, provider)
    again = ck.chain_shortening(CHAIN, provider)
    assert len(calls) == 1
    np.testing.assert_array_equal(again[0], first[0])
    assert again[1] == first[1]
    stiffer = dataclasses.replace(CHAIN, width=1.01 * CHAIN.width)  # other numbers from the provider: a new key
    ck.chain_shortening(stiffer, provider)
    assert len(calls) == 2
    _edited(monkeypatch, "flexcal.validation.prototype.equilibrium")
    edited = ck.chain_shortening(CHAIN, provider)
    assert len(calls) == 3
    np.testing.assert_array_equal(edited[0], first[0])  # the same computation, computed again


def _validation_modules_run(compute) -> set[str]:
    """The modules of flexcal.validation with a function that runs inside ``compute()``."""
    root = Path(flexcal.validation.__file__).parent
    files = set()

    def profile(frame, event, arg):
        if event == "call":
            files.add(frame.f_code.co_filename)

    threading.setprofile(profile)
    sys.setprofile(profile)
    try:
        compute()
    finally:
        sys.setprofile(None)
        threading.setprofile(None)
    modules = set()
    for name in files:
        path = Path(name).resolve()
        if path.is_relative_to(root.resolve()) and path.suffix == ".py":
            parts = path.relative_to(root.resolve()).with_suffix("").parts
            modules.add(".".join(("flexcal.validation",) + tuple(p for p in parts if p != "__init__")))
    return modules


def test_the_probes_list_holds_every_module_its_computation_runs():
    """The probe's chain (its nodes, from the chain) and its equilibria; the provider's numbers are
    in the key as numbers."""
    ran = _validation_modules_run(lambda: ck._probe(*ck._chain_assembly(CHAIN, analytic_provider()),
                                                    ck.SolverSettings()))
    assert "flexcal.validation.prototype.equilibrium" in ran  # the tracing sees the probe's work
    assert ran <= set(ck.PROBE_CODE), ran - set(ck.PROBE_CODE)


@pytest.mark.parametrize("kind", ["segment", "tied chain", "structure segment"])
def test_an_fem_entrys_list_holds_every_module_its_computation_runs(tmp_path, kind):
    """Each entry computed on the coarsest grid (2 through), once to import what it needs and
    once traced, in a cache folder of its own each."""
    segment = _segment()
    compute, modules = {
        "segment": (lambda folder: fp.segment_stiffness_fem(segment, elements_through_thickness=2,
                                                            cache_directory=folder), fp.SEGMENT_CODE),
        "tied chain": (lambda folder: tc.tied_chain_matrices(CHAIN, elements_through_thickness=2,
                                                             cache_directory=folder), tc.TIED_CHAIN_CODE),
        "structure segment": (lambda folder: structure.segment_structure(CHAIN, 0.0, CHAIN.length / 2,
                                                                         elements_through=2, cache_directory=folder),
                              structure.STRUCTURE_SEGMENT_CODE),
    }[kind]
    compute(tmp_path / "first")
    ran = _validation_modules_run(lambda: compute(tmp_path / "traced"))
    assert ran, "the tracing saw no module of flexcal.validation run"
    assert ran <= set(modules), ran - set(modules)


def test_a_reference_studys_level_of_other_code_is_computed_again(monkeypatch, tmp_path):
    """The convergence studies' levels (``reports.hinge_reference._cached``, the benchmarks'
    ``--dir``): reused while the code that computed them is this one, computed again after an edit
    of ``LEVEL_CODE`` (a resumed study never mixes levels of two codes)."""
    import flexcal.validation.reports.hinge_reference as reference

    calls = []

    def compute():
        calls.append(1)
        return np.arange(4.0) * len(calls), 10

    first = reference._cached(tmp_path, "level", compute)
    np.testing.assert_array_equal(reference._cached(tmp_path, "level", compute), first)
    assert len(calls) == 1
    _edited(monkeypatch, "flexcal.validation.reports.chain_reference")
    again = reference._cached(tmp_path, "level", compute)
    assert len(calls) == 2 and again[1] == 2.0  # computed again, and kept under the new version
    np.testing.assert_array_equal(reference._cached(tmp_path, "level", compute), again)
    assert len(calls) == 2 and sorted(p.name for p in tmp_path.iterdir()) == ["level.npz"]
