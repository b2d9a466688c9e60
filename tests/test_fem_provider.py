"""Chain segments and the prototype's FEM stiffness provider."""

import numpy as np
import pytest

from flexcal.geometry.params import ChainSegment, FlexureChain, reference_mechanism
from flexcal.validation.prototype.fem_provider import fem_provider, mirror_segment_stiffness
from flexcal.validation.prototype.segments import analytic_provider, section_nodes


def test_segment_cuts_must_avoid_leaves():
    chain = FlexureChain(length=0.150, thickness_1=0.003, thickness_2=0.003)
    with pytest.raises(ValueError, match="cuts through a leaf"):
        ChainSegment(chain=chain, x_start=0.0, x_end=0.020)  # leaf 1 spans 10-30 mm
    with pytest.raises(ValueError, match="x_end"):
        ChainSegment(chain=chain, x_start=0.0, x_end=0.2)
    segment = ChainSegment(chain=chain, x_start=0.0, x_end=0.035)
    kinds = [kind for kind, _, _ in segment.segments()]
    assert kinds == ["block", "leaf1", "connector"]


def test_mirror_of_first_segment_is_the_last():
    """Independent check of the pi-about-z mirror: the analytic provider computes the
    last segment directly, the mirror maps the first onto it (exact: 1e-9 relative is
    round-off of the compliance inversions)."""
    chain = reference_mechanism().chains[3].chain
    xs = section_nodes(chain)
    provider = analytic_provider()
    first = provider(chain, xs[0], xs[1])
    last = provider(chain, xs[-2], xs[-1])
    # round-off of the compliance inversions (docstring)
    np.testing.assert_allclose(mirror_segment_stiffness(first), last, rtol=0, atol=1e-9 * np.abs(last).max())
    # a signed permutation twice: exact (was atol=1e-6 with the default rtol 1e-7)
    np.testing.assert_allclose(mirror_segment_stiffness(mirror_segment_stiffness(first)), first, rtol=0, atol=0)


def test_fem_provider_caches_and_mirrors(tmp_path):
    """One FEM leaf segment (coarse: 2 elements through the leaf) against the analytic
    segment: the leaf's working bending compliance within 5 % (beam theory vs 3-D
    FEM of a 3 mm leaf with fillets: +1.3 % measured on the reference leaf hinge, the
    coarse mesh adds ~1 %); a second call and the mirrored call are served by the cache."""
    chain = reference_mechanism().chains[3].chain
    xs = section_nodes(chain)
    provider = fem_provider(elements_through_thickness=2, cache_directory=tmp_path, progress=False)
    first = provider(chain, xs[0], xs[1])
    assert len(list(tmp_path.rglob("*.npz"))) == 1
    mirrored = provider(chain, xs[-2], xs[-1])
    assert len(list(tmp_path.rglob("*.npz"))) == 1  # no new solve
    np.testing.assert_allclose(mirrored, mirror_segment_stiffness(first))
    # solver round-off, as in test_fem_condense (eps x cond)
    np.testing.assert_allclose(first, first.T, atol=1e-9 * np.abs(first).max())
    fem_c = np.linalg.inv(first[6:, 6:])
    ana_c = np.linalg.inv(analytic_provider()(chain, xs[0], xs[1])[6:, 6:])
    # 5 %: beam theory vs 3-D FEM +1.3 %, coarse mesh ~1 % (docstring)
    assert fem_c[5, 5] == pytest.approx(ana_c[5, 5], rel=0.05)
    assert fem_c[1, 1] == pytest.approx(ana_c[1, 1], rel=0.05)  # as above


def test_parallel_builds_into_an_unwritable_cache_keep_their_matrices(tmp_path, monkeypatch, caplog):
    """``build_segments`` with FLEXCAL's cache folder below a regular file (ENOTDIR; tests
    run as root, so mode bits would not do): one warning before the builds, every built
    matrix kept in this process, and the provider's calls that follow served from it with
    no FEM (the closed form stands in for the segment builds, which are not under test)."""
    import logging

    import flexcal.fem.mesh
    import flexcal.validation.prototype.fem_provider as fp
    from flexcal.geometry.params import STEEL

    caplog.set_level(logging.WARNING, logger="flexcal.fem.cache")
    (tmp_path / "a-file").write_text("not a folder")
    folder = tmp_path / "a-file" / "cache"
    analytic = analytic_provider()
    built = []

    def warnings():
        return [r.getMessage() for r in caplog.records if r.name == "flexcal.fem.cache"]

    def job(segment, *, material, elements_through_thickness, **_):
        assert len(warnings()) == 1  # warned before the first build
        built.append(segment)
        return {"key": fp.segment_cache_key(segment, material, elements_through_thickness=elements_through_thickness),
                "stiffness": analytic(segment.chain, segment.x_start, segment.x_end), "wall_s": 0.0}

    monkeypatch.setattr(fp, "build_segment_job", job)
    chain = reference_mechanism().chains[3].chain
    xs = section_nodes(chain)
    slices = [(chain, float(a), float(b)) for a, b in zip(xs[:-1], xs[1:])]
    n_built = fp.build_segments(slices, STEEL, cache_directory=folder, workers=1, progress=False)
    assert n_built == len(built) > 0

    def no_fem(*args, **kwargs):
        raise AssertionError("a kept segment was meshed again")

    monkeypatch.setattr(flexcal.fem.mesh, "mesh_part", no_fem)
    provider = fem_provider(cache_directory=folder, progress=False)
    for chain_, a, b in slices:  # mirrored halves included: the same kept matrices, turned
        np.testing.assert_allclose(provider(chain_, a, b), analytic(chain_, a, b), rtol=0,
                                   atol=1e-9 * np.abs(analytic(chain_, a, b)).max())  # round-off of the mirror
    assert len(warnings()) == 1 and "cannot be written" in warnings()[0]


def test_segments_are_meshed_by_the_mapped_mesher_by_default_under_their_own_key(tmp_path, monkeypatch):
    """The default provider meshes a segment without fTetWild (the deterministic mapped
    mesher); fTetWild stays selectable, under another cache key; an unknown mesher is refused."""
    import flexcal.fem.mesh

    from flexcal.validation.prototype.fem_provider import canonical_segment, segment_cache_key

    chain = reference_mechanism().chains[3].chain
    xs = section_nodes(chain)
    segment, _ = canonical_segment(chain, xs[0], xs[1])
    assert segment_cache_key(segment) != segment_cache_key(segment, mesher="tetwild")

    def no_tetwild(*args, **kwargs):
        raise AssertionError("fTetWild was called")

    monkeypatch.setattr(flexcal.fem.mesh, "mesh_part", no_tetwild)
    provider = fem_provider(elements_through_thickness=2, cache_directory=tmp_path, progress=False)
    stiffness = provider(chain, xs[0], xs[1])
    assert "mapped" in provider.description and np.all(np.isfinite(stiffness))
    with pytest.raises(ValueError, match="mapped, tetwild"):
        fem_provider(mesher="gmsh")
