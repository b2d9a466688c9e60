"""The model's FEM corrections from tied chains (issue 26; docs/model.md 7, "Session 25"): a chain's
end compliance from its K_chain on the five segments' twists (model_correction.twist_end_compliance)
and its shortening probe on a one-chain CoupledStiffness (chain_kinematics.chain_shortening)."""

import functools

import numpy as np
import pytest
import scipy.linalg

from flexcal.fem.mesh_mapped_chain import PROTOTYPE_CHAIN_OPTIONS
from flexcal.model.parameters import parameter_space
from flexcal.model.serial import serial_compliance
from flexcal.validation.prototype.cut_fields import (interface_condensed, interface_scale, interface_segments,
                                                     joined_through_interface, twist_stiffness_through_interface)
from flexcal.validation.prototype.segments import analytic_provider, end_stiffness, section_nodes
from flexcal.validation.reports.chain_reference import reference_chain
from flexcal.validation.runs.chain_kinematics import chain_shortening
from flexcal.validation.runs.model_correction import compliance_factors, provider_chain_compliance, twist_end_compliance

# the coarse whole L1 chain (2 through), distributing order-2 fields at the mid-connector cuts and
# kinematic order-2 ones at the strut cuts: a K_chain with the warping's coupling, in < 1 s
INTERFACE = ("d2", "p2", "p2", "d2")


@functools.cache
def _coarse_tied_chain(interface=INTERFACE):
    """(chain, K_chain (30, 30), the joined stretch's 12 x 12) of the coarse L1 chain tied by
    ``interface`` ("rigid": its segments on the same meshes joined rigidly)."""
    chain = reference_chain("L1")
    plan, scale = interface_segments(chain, 5), interface_scale(chain, 5)
    condensed = interface_condensed(plan, interface, 2, {**PROTOTYPE_CHAIN_OPTIONS, "slenderness": None},
                                    scale=scale)
    return (chain, twist_stiffness_through_interface(plan, condensed, interface, scale),
            joined_through_interface(plan, condensed, interface))


def _segments(chain, provider=analytic_provider()):
    nodes = section_nodes(chain)
    return [provider(chain, float(a), float(b)) for a, b in zip(nodes[:-1], nodes[1:])]


def _tied(provider, chain_stiffness):
    """A provider whose chains are ``chain_stiffness(chain)`` (30, 30), as the tied one's."""
    def tied(chain, x_start, x_end):
        return provider(chain, x_start, x_end)

    tied.chain_stiffness = chain_stiffness
    return tied


def _rigid_twist_stiffness(chain):
    return scipy.linalg.block_diag(*(end_stiffness(k) for k in _segments(chain)))


@pytest.mark.parametrize("index", [0, 3])
def test_rigid_cuts_are_the_block_diagonal_special_case_of_eq_1(index):
    chain = parameter_space().mechanism.chains[index].chain
    nodes = section_nodes(chain)
    kjj = np.array([end_stiffness(k) for k in _segments(chain)])
    compliance = np.linalg.inv(0.5 * (kjj + np.swapaxes(kjj, 1, 2)))
    ends = np.stack([nodes[1:], np.zeros(5), np.zeros(5)], axis=-1)
    eq_1 = serial_compliance(compliance, np.broadcast_to(np.eye(3), (5, 3, 3)), ends, np.array([chain.length, 0, 0]))
    eq_1 = 0.5 * (eq_1 + eq_1.T)  # Eq. 1, as model_correction composed the chains before session 25
    joined = twist_end_compliance(_rigid_twist_stiffness(chain), nodes)
    size = np.sqrt(np.outer(np.diag(eq_1), np.diag(eq_1)))
    # the same sum; the inversions differ (6 x 6 LU against the Jacobi-scaled 30 x 30 Cholesky):
    # measured <= 7e-15 of the diagonals' geometric mean (1.4e-14 on FEM segments); 1e-12
    assert np.max(np.abs(joined - eq_1) / size) <= 1e-12
    # and the provider's chain compliance is that (a provider without chain_stiffness: rigid cuts)
    np.testing.assert_array_equal(provider_chain_compliance(chain, analytic_provider()), joined)


def test_the_tied_chains_end_compliance_is_the_joined_stretchs():
    chain, twist, joined = _coarse_tied_chain()
    mine = twist_end_compliance(twist, section_nodes(chain))
    stretch = np.linalg.inv(joined[6:, 6:])  # the joined stretch's end block, A clamped, inverted
    stretch = 0.5 * (stretch + stretch.T)
    size = np.sqrt(np.outer(np.diag(stretch), np.diag(stretch)))
    # the same energy minimised in two orders (each cut's warping, then the section bodies, against
    # all the interface DOFs at once): the round-off of the cancellation in the transverse stiffness
    # at B (tests/test_chain_twist_stiffness.py: <= 1.8e-8 on the stiffness), measured 3.8e-8 of the
    # diagonals' geometric mean here (1.3e-8 with rigid ties); the fields move entries by > 3e-2
    # (below); 1e-6
    assert np.max(np.abs(mine - stretch) / size) <= 1e-6, np.max(np.abs(mine - stretch) / size)
    _, rigid_twist, _ = _coarse_tied_chain("rigid")
    rigid = twist_end_compliance(rigid_twist, section_nodes(chain))
    # the fields make the chain softer than its segments on the same meshes joined rigidly, on every
    # diagonal entry (measured: axial 1.37x, the others 1.04-1.09x), so the check above has teeth; 3e-2
    assert np.all(np.diag(mine) > (1 + 3e-2) * np.diag(rigid)), np.diag(mine) / np.diag(rigid)


def test_a_tied_providers_factors_come_from_its_chain_stiffness():
    space = parameter_space()
    plain = compliance_factors(space, analytic_provider())
    # K_chain the rigid cuts' block diagonal: today's factors (the same composition, to the bit)
    same = _tied(analytic_provider(), _rigid_twist_stiffness)
    np.testing.assert_array_equal(compliance_factors(space, same), plain)
    # K_chain at half the stiffness: every compliance, and so every factor, doubles (exactly, but for
    # the rounding of the scaled Cholesky solve, ~1e-15); 1e-12
    half = _tied(analytic_provider(), lambda chain: 0.5 * _rigid_twist_stiffness(chain))
    np.testing.assert_allclose(compliance_factors(space, half), 2.0 * plain, rtol=1e-12, atol=0)  # 1e-12: as above


def _softer_with_width(nominal_width):
    """A tied provider on analytic segments whose chains' compliance goes as w0 / w: every factor is
    w0 / w times the analytic one (1 to 1e-7), 1 / (1 + r_w) in the relative width change r_w."""
    return _tied(analytic_provider(), lambda chain: _rigid_twist_stiffness(chain) * chain.width / nominal_width)


def test_a_tied_providers_slopes_and_curvatures_are_its_own_chains():
    from flexcal.model.parameters import DIMENSION_SYMBOLS
    from flexcal.validation.runs.dimension_terms import compliance_curvatures
    from flexcal.validation.runs.model_correction import SLOPE_STEPS, compliance_slopes

    space = parameter_space()
    assert len({p.chain.width for p in space.mechanism.chains}) == 1  # one nominal width, w0
    provider = _softer_with_width(space.mechanism.chains[0].chain.width)
    s, w = SLOPE_STEPS["w"], DIMENSION_SYMBOLS.index("w")
    slopes = compliance_slopes(space, provider)  # the builds: the moved chains asked whole
    expected = np.zeros_like(slopes)
    expected[:, w] = -1.0 / (1.0 - s * s)  # the central difference of 1 / (1 + r) over +-s
    # the analytic factors' rounding over 2 s = 0.06 (the same segments' rounding on both sides, and in
    # the closed form: measured 2e-13); 1e-9
    np.testing.assert_allclose(slopes, expected, rtol=0, atol=1e-9)
    curvatures = compliance_curvatures(space, provider)
    expected = np.zeros_like(curvatures)
    expected[:, w, w] = 2.0 / (1.0 - s * s)  # the second difference of 1 / (1 + r) over +-s
    # that rounding over s^2 = 9e-4 (and the mixed terms' over 2 s_k s_m): measured 3.8e-11; 1e-7
    np.testing.assert_allclose(curvatures, expected, rtol=0, atol=1e-7)
    with pytest.raises(ValueError, match="builds"):  # no condensed derivative of a tied chain
        compliance_slopes(space, provider, method="condensed")


def test_a_tied_providers_terms_on_another_grid_are_that_grids_relative_ones():
    """On another grid (``elements_through``: the provider's ``on_grid``, tied too) the slopes and
    curvatures are that grid's relative ones times the factor on the provider's grid: here the
    other grid's chains are 2 % stiffer and their compliance goes as (w0 / w)^2, so the terms are
    those of 1 / (1 + r)^2 (the 2 % cancels), not the provider's own 1 / (1 + r)."""
    from flexcal.model.parameters import DIMENSION_SYMBOLS
    from flexcal.validation.runs.dimension_terms import compliance_curvatures
    from flexcal.validation.runs.model_correction import SLOPE_STEPS, compliance_slopes

    space = parameter_space()
    w0 = space.mechanism.chains[0].chain.width
    provider = _softer_with_width(w0)
    grids = []

    def on_grid(n):
        grids.append(n)
        return _tied(analytic_provider(), lambda chain: 1.02 * _rigid_twist_stiffness(chain) * (chain.width / w0) ** 2)

    provider.on_grid, provider.mesher = on_grid, "mapped"
    s, w = SLOPE_STEPS["w"], DIMENSION_SYMBOLS.index("w")
    plus, minus = (1.0 + s) ** -2, (1.0 - s) ** -2
    slopes = compliance_slopes(space, provider, elements_through=3)
    expected = np.zeros_like(slopes)
    # the other grid's central difference over the mean of its +-s factors, times the factor here (1)
    expected[:, w] = (plus - minus) / (2.0 * s) / (0.5 * (plus + minus))
    # the analytic factors' rounding over 2 s (measured 2e-13 above); 1e-9
    np.testing.assert_allclose(slopes, expected, rtol=0, atol=1e-9)
    curvatures = compliance_curvatures(space, provider, elements_through=3)
    expected = np.zeros_like(curvatures)
    expected[:, w, w] = (plus + minus - 2.0) / s**2  # over the other grid's nominal factor, times 1
    # the rounding over s^2 = 9e-4 (measured 3.8e-11 above); 1e-7
    np.testing.assert_allclose(curvatures, expected, rtol=0, atol=1e-7)
    assert grids and set(grids) == {3.0}


def test_a_tied_fem_provider_on_another_grid_is_tied_on_that_grid():
    from flexcal.validation.prototype.segments import is_tied
    from flexcal.validation.prototype.tied_chains import tied_fem_provider

    provider = tied_fem_provider("d12/p8", elements_through_thickness=7, progress=False)
    coarse = provider.on_grid(4)
    assert is_tied(coarse) and coarse.ties == provider.ties
    assert coarse.elements_through_thickness == 4.0 and provider.elements_through_thickness == 7.0
    assert coarse.keeping_segments().elements_through_thickness == 4.0


def test_the_shortening_probe_runs_on_the_tied_chain():
    chain, twist, _ = _coarse_tied_chain()
    _, rigid_twist, _ = _coarse_tied_chain("rigid")
    provider = analytic_provider()
    # K_chain the rigid cuts' block diagonal: the coupled equilibrium (a one-chain CoupledStiffness,
    # its cross blocks zero) is the rigid probe's, S and k to the bit (measured; the wrench offsets
    # are exact zeros)
    s_rigid, k_rigid = chain_shortening(chain, provider)
    s_same, k_same = chain_shortening(chain, _tied(provider, _rigid_twist_stiffness))
    assert k_same == k_rigid
    np.testing.assert_array_equal(s_same, s_rigid)
    # the coarse tied chain: the probe's axial stiffness is the chain's, 1 / C_xx of its end
    # compliance from the same K_chain (ux uncoupled on a straight chain): a central difference of a
    # nearly linear force at 2e-4 m, measured 4.6e-12 (5.9e-12 on the same meshes tied rigidly); 1e-9
    s_tied, k_tied = chain_shortening(chain, _tied(provider, lambda c: twist))
    axial = twist_end_compliance(twist, section_nodes(chain))[0, 0]
    assert abs(k_tied * axial - 1) <= 1e-9  # 1e-9: see above
    s_cut, k_cut = chain_shortening(chain, _tied(provider, lambda c: rigid_twist))
    assert k_tied < 0.8 * k_cut  # 0.8: the fields soften the coarse chain axially (measured 0.727x)
    # the shortening form (a quadratic over the axial stiffness) is nearly the rigid cuts': its
    # lateral and bending diagonal within 5 % (measured 0.2-1.9 %); 5e-2
    lateral = [1, 2, 4, 5]
    np.testing.assert_allclose(np.diag(s_tied)[lateral], np.diag(s_cut)[lateral], rtol=5e-2)  # 5e-2: as above


@pytest.mark.slow
def test_the_tied_fem_corrections_are_the_softer_chains():
    """The reference mount's corrections from the provider fem (cuts tied) against fem-rigid (slow: 3 tied
    chains and the rigid segments on a cold cache, ~50 s CPU)."""
    from flexcal.validation.prototype.providers import stiffness_provider
    from flexcal.validation.runs.chain_kinematics import chain_shortening

    space = parameter_space()
    rigid = stiffness_provider("fem-rigid", progress=False, workers=None)
    tied = stiffness_provider("fem", progress=False, workers=None)
    ratio = compliance_factors(space, tied) / compliance_factors(space, rigid)
    # rigid cuts make the whole chains 19-23 % too stiff axially (docs/meshing.md, session 24);
    # measured 1.188 (L) and 1.230 (D) here; the band 1.15-1.27 is that figure +-4 %
    assert np.all((ratio[:, 0] > 1.15) & (ratio[:, 0] < 1.27)), ratio[:, 0]
    # bending and shear entries measured 1.004-1.008, torsion 1.023-1.026: the cuts' fields free
    # the section mostly axially; 2 % and 5 % bound them (well below the axial 15 %)
    assert np.all(np.abs(ratio[:, 1:7] - 1) < 0.02) and np.all(np.abs(ratio[:, 7] - 1) < 0.05), ratio
    chain = space.mechanism.chains[3].chain  # D1: the driving chains' shortening matters most
    (s_tied, k_tied), (s_rigid, k_rigid) = chain_shortening(chain, tied), chain_shortening(chain, rigid)
    compliance = twist_end_compliance(tied.chain_stiffness(chain), section_nodes(chain))
    # the probe's axial stiffness is the tied chain's 1 / C_xx (as on the coarse chain above): the
    # central difference's O(h^2) at 2e-4 m on the short chain, measured 2.4e-9 (L1: 5e-12); 1e-7
    assert abs(k_tied * compliance[0, 0] - 1) <= 1e-7, k_tied * compliance[0, 0] - 1
    assert k_tied < 0.85 * k_rigid  # 0.85: the 1.23 axial factor above (k measured 0.813x)
    # S, a quadratic over k, keeps its lateral and bending terms: measured within 0.3 % of the rigid
    # cuts' (the coarse chain: 0.2-1.9 %); 1e-2
    np.testing.assert_allclose(np.diag(s_tied)[[1, 2, 4, 5]], np.diag(s_rigid)[[1, 2, 4, 5]], rtol=1e-2)  # 1e-2: above


def test_one_batch_builds_every_chain_the_models_corrections_ask_for():
    """``dimension_terms.prepare_model_chains`` hands the executor, in one batch, every chain the
    consistent model's corrections then ask a tied provider for (slopes, L2's own shortening probe,
    curvatures, shortening slopes): asked phase by phase, L2's chain was built alone on one of two
    cores. A recording tied provider on analytic segments: every chain asked for afterwards, by
    ``chain_stiffness`` or by a phase's ``prepare_chains``, is one of the batch's."""
    from flexcal.validation.runs.chain_kinematics import consistent_space
    from flexcal.validation.runs.dimension_terms import curved_space, prepare_model_chains
    from flexcal.validation.runs.model_correction import corrected_space

    space = parameter_space()
    batches, asked = [], []

    def stiffness(chain):
        asked.append(chain)
        return _rigid_twist_stiffness(chain)

    provider = _tied(analytic_provider(), stiffness)
    provider.prepare_chains = lambda chains: batches.append(list(chains))
    prepare_model_chains(space, provider)
    assert len(batches) == 1
    batch = set(batches[0])
    # the nominal designs D and L1 (= L3), L2 (1 ulp longer: its own probe), 2 x 10 single moves,
    # 2 x 10 one-sided pairs
    assert len(batches[0]) == len(batch) == 3 + 20 + 20
    assert {p.chain for p in space.mechanism.chains} <= batch
    curved_space(consistent_space(corrected_space(space, provider, slopes=True), provider), provider)
    assert len(batches) > 1 and all(set(b) <= batch for b in batches[1:])
    assert asked and set(asked) <= batch
    assert set(asked) | {c for b in batches[1:] for c in b} == batch  # the batch builds nothing unasked


def test_the_mixed_curvatures_on_another_grid_are_that_grids_relative_ones_and_the_diagonal_stays():
    """``mixed_elements_through``: the mixed entries are the other grid's relative ones (its
    one-sided pair difference over its own nominal factor) times the factor here, the diagonal
    the provider's own. Here the chains' compliance goes as 1 / x, x = (w / w0) (t1 / t1_0) (each
    factor 1 / x), on the other grid as 1 / (1.02 x^2): the mixed (w, t1) entry is (1 - 1 / (1 + s_w)
    ^2) (1 - 1 / (1 + s_t)^2) / (s_w s_t) (the 2 % cancels), not this grid's 1 / ((1 + s_w)(1 + s_t)),
    and the diagonal is this grid's 2 / (1 - s^2). The batch of the model's chains builds the
    other grid's apart, after: its nominal designs, single moves (+s alone) and pairs."""
    from flexcal.model.parameters import DIMENSION_SYMBOLS
    from flexcal.validation.runs.dimension_terms import compliance_curvatures, prepare_model_chains
    from flexcal.validation.runs.model_correction import SLOPE_STEPS

    space = parameter_space()
    w0 = space.mechanism.chains[0].chain.width
    assert len({p.chain.width for p in space.mechanism.chains}) == 1  # one nominal width, w0
    # the designs' leaf thicknesses (4 and 3 mm): a moved one is within 3 % of its own
    t_nominal = sorted({p.chain.thickness_1 for p in space.mechanism.chains})

    def x(chain):
        t0 = min(t_nominal, key=lambda t: abs(chain.thickness_1 - t))
        return (chain.width / w0) * (chain.thickness_1 / t0)

    batches = []
    provider = _tied(analytic_provider(), lambda chain: _rigid_twist_stiffness(chain) * x(chain))
    coarse = _tied(analytic_provider(), lambda chain: 1.02 * _rigid_twist_stiffness(chain) * x(chain) ** 2)
    grids = []

    def on_grid(n):
        grids.append(n)
        return coarse

    provider.on_grid, provider.mesher = on_grid, "mapped"
    provider.prepare_chains = lambda chains: batches.append(("fine", list(chains)))
    coarse.prepare_chains = lambda chains: batches.append(("coarse", list(chains)))
    sw, st = SLOPE_STEPS["w"], SLOPE_STEPS["t1"]
    w, t = DIMENSION_SYMBOLS.index("w"), DIMENSION_SYMBOLS.index("t1")
    curvatures = compliance_curvatures(space, provider, mixed_elements_through=3)
    expected = np.zeros_like(curvatures)
    expected[:, w, w] = 2.0 / (1.0 - sw * sw)
    expected[:, t, t] = 2.0 / (1.0 - st * st)
    expected[:, w, t] = expected[:, t, w] = (1 - (1 + sw) ** -2) * (1 - (1 + st) ** -2) / (sw * st)
    # the analytic factors' rounding over s^2 = 9e-4 (measured 3.8e-11 in the test above); 1e-7
    np.testing.assert_allclose(curvatures, expected, rtol=0, atol=1e-7)
    same = compliance_curvatures(space, provider)  # the default: every entry on this grid
    assert abs(same[0, w, t, 0] - 1.0 / ((1 + sw) * (1 + st))) < 1e-7  # this grid's one-sided pair
    np.testing.assert_array_equal(np.diagonal(curvatures, axis1=1, axis2=2), np.diagonal(same, axis1=1, axis2=2))
    assert set(grids) == {3.0}
    batches.clear()
    prepare_model_chains(space, provider, mixed_elements_through=3)
    assert [kind for kind, _ in batches] == ["fine", "coarse"]
    # fine: the 3 nominal chains and 2 x 10 single moves; coarse: the 2 designs, 2 x 5 (+s) moves, 2 x 10 pairs
    assert (len(batches[0][1]), len(batches[1][1])) == (3 + 20, 2 + 10 + 20)
