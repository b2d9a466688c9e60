"""fem.condense_taylor: a tied segment's condensation with its first and second derivatives in the
chain's relative dimensions, against finite differences of full condensations on the same cells."""

import dataclasses

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

THROUGH = 1  # the coarsest mapped grid: the mathematics does not depend on it, the test's time does
W, A, L, T1 = 0, 1, 2, 3  # DIMENSION_SYMBOLS: w, a, l, t1, t2


@pytest.fixture(scope="module")
def segment_family():
    """(part_at(r) -> (mesh, couplings, axes), exact(r) -> condensation) of table1's D1 segment
    [0, m1] meshed on its nominal cells, r the five relative dimensions."""
    from flexcal.fem.condense import mirrored_coupled_stiffness
    from flexcal.fem.mesh_mapped_chain import mapped_mesh_chain_mirror_part
    from flexcal.fem.solve import one_thread
    from flexcal.geometry.params import STEEL
    from flexcal.model.parameters import DIMENSION_FIELDS, DIMENSION_SYMBOLS
    from flexcal.validation.prototype.cut_fields import segment_couplings, step_interfaces
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.prototype.tied_chains import DEFAULT_TIES, _tied_plan

    nominal = load_scenario("table1").space.mechanism.chains[3].chain  # D1: its 3 mm leaves round their cores
    fields = [DIMENSION_FIELDS[s] for s in DIMENSION_SYMBOLS]
    plan0, interfaces, options, _ = _tied_plan(nominal, DEFAULT_TIES)
    labels = step_interfaces(plan0, interfaces)[0]

    def part_at(r):
        chain = dataclasses.replace(nominal, **{f: getattr(nominal, f) * (1 + x) for f, x in zip(fields, r)})
        plan, _, _, scale = _tied_plan(chain, DEFAULT_TIES)
        segment, _, starts, ends = plan[0]
        mesh, axes = mapped_mesh_chain_mirror_part(segment, elements_through_thickness=THROUGH, template=plan0[0][0],
                                                   **options)
        return mesh, segment_couplings(segment, mesh, starts, ends, labels, scale), axes

    def exact(r):  # on one thread, as the Taylor's (PARDISO's last bits depend on the thread count)
        mesh, couplings, axes = part_at(np.asarray(r, float))
        with one_thread():
            return mirrored_coupled_stiffness(mesh, STEEL, couplings, axes)

    return part_at, exact


@pytest.fixture(scope="module")
def taylor(segment_family):
    from flexcal.fem.condense_taylor import mirrored_coupled_stiffness_taylor
    from flexcal.fem.solve import one_thread
    from flexcal.geometry.params import STEEL

    part_at, _ = segment_family
    axes = part_at(np.zeros(5))[2]
    with one_thread():
        return mirrored_coupled_stiffness_taylor(lambda r: part_at(r)[:2], STEEL, axes, 5)


def _scale(S):
    """Each entry's own scale sqrt(|S_ii S_jj|): the condensation mixes forces, moments and field
    loads of very different sizes."""
    return np.sqrt(np.abs(np.outer(np.diag(S), np.diag(S))))


def test_the_value_is_the_condensation_itself_to_the_bit(segment_family, taylor):
    _, exact = segment_family
    assert np.array_equal(taylor.value, exact(np.zeros(5)))


def test_the_derivatives_are_the_limits_of_central_differences_at_second_order(segment_family, taylor):
    """Halving h divides a central difference's error by 4 (O(h^2)); the second-order polynomial's
    error at r = h e_p by 8 (O(h^3)). A wrong first or second derivative stalls both (the fillet
    ends' root once did: its 6e-11 m jump gave a constant error, fixed in LeafPiece.local_thickness)."""
    _, exact = segment_family
    S0 = exact(np.zeros(5))
    d = _scale(S0)
    for p in (W, A, T1):
        e = np.eye(5)[p]
        errors = []
        for h in (1e-2, 5e-3):
            plus, minus = exact(h * e), exact(-h * e)
            errors.append((np.max(np.abs((plus - minus) / (2 * h) - taylor.first[p]) / d),
                           np.max(np.abs(taylor.at(h * e) - plus) / d)))
        (first_h, poly_h), (first_h2, poly_h2) = errors
        # ratio 4 in theory (O(h^2)); 3 leaves room for the next order's share at h = 1e-2
        assert first_h / first_h2 > 3.0, errors
        # ratio 8 in theory (O(h^3)); 6 for the next order; a wrong second derivative gives 4
        assert poly_h / poly_h2 > 6.0, errors
        # the derivative itself is O(1) of the entries (w: 2.6, t1: 2.1 at their largest)
        assert first_h2 < 5e-3 * np.max(np.abs(taylor.first[p]) / d), errors


@pytest.mark.parametrize("p, q", [(W, T1), (A, L)])
def test_the_mixed_second_derivatives_are_the_four_point_differences(segment_family, taylor, p, q):
    """(a, l) both move the fillets' x: their mixed term from the assemblies' one-sided mixed
    difference (O(step)) was 0.6 % off on the prototype's grid, which a driving chain's lateral
    compliance amplified 10x; now from the diagonal points, O(step^2)."""
    _, exact = segment_family
    S0 = exact(np.zeros(5))
    d = _scale(S0)
    h = 5e-3
    e_p, e_q = np.eye(5)[p], np.eye(5)[q]
    mixed = (exact(h * (e_p + e_q)) - exact(h * (e_p - e_q)) - exact(h * (e_q - e_p)) + exact(-h * (e_p + e_q))) / (
        4 * h * h)
    # the four-point difference is O(h^2) = 2.5e-5 relative to fourth derivatives of O(10-100)
    # here; the assemblies' own differences (DERIVATIVE_STEP 1e-4) are O(1e-8)
    assert np.max(np.abs(mixed - taylor.second[p, q]) / d) < 2e-3 * max(1.0, np.max(np.abs(mixed) / d))
    assert np.array_equal(taylor.second[p, q], taylor.second[q, p])


def test_a_dimension_the_segment_does_not_have_has_no_derivative(taylor):
    """t2 is leaf 2's: segment [0, m1] holds leaf 1 only."""
    assert not np.any(taylor.first[4]) and not np.any(taylor.second[4])


def test_a_connectivity_plan_gives_a_moved_parts_classes_to_the_bit(segment_family):
    """The Taylor's moved assemblies reuse the nominal part's index work (``connectivity_plan``):
    every class's K_ii (pattern and values), K_im, K_mm and G equal those ``mirror_class_systems``
    finds from scratch; a mesh of another connectivity is refused."""
    from flexcal.fem.condense import connectivity_plan, mirror_class_systems
    from flexcal.fem.mesh_tets import TetMesh
    from flexcal.geometry.params import STEEL

    part_at, _ = segment_family
    mesh0, couplings0, axes = part_at(np.zeros(5))
    plan = connectivity_plan(mesh0, couplings0, mirror_class_systems(mesh0, STEEL, couplings0, axes, drop_zeros=False))
    mesh, couplings, _ = part_at(np.array([0.02, -0.02, 0.01, 0.03, 0.0]))
    scratch = mirror_class_systems(mesh, STEEL, couplings, axes, drop_zeros=False)
    planned = mirror_class_systems(mesh, STEEL, couplings, axes, drop_zeros=False, plan=plan)
    assert len(planned.classes) == len(scratch.classes) == 4
    for mine, theirs in zip(planned.classes, scratch.classes):
        for name in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(mine.sub, name), getattr(theirs.sub, name))
        assert np.array_equal(mine.K_im, theirs.K_im) and np.array_equal(mine.K_mm, theirs.K_mm)
        assert (mine.G != theirs.G).nnz == 0
    assert not np.array_equal(planned.classes[0].sub.data, plan.classes[0].data)  # values, not positions
    one_fewer = TetMesh(nodes=mesh.nodes, tets=mesh.tets[:-1])
    with pytest.raises(ValueError, match="connectivity plan"):
        mirror_class_systems(one_fewer, STEEL, couplings, axes, drop_zeros=False, plan=plan)
    with pytest.raises(ValueError, match="drop_zeros=False"):
        mirror_class_systems(mesh, STEEL, couplings, axes, plan=plan)
