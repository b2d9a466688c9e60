"""Effects that change the segments' stiffness on a prototype with tied cuts (docs/effects.md,
"Effects on tied cuts"): a change K_jj -> K_jj' acts on K_chain as T^T K_chain T, T the block
diagonal of the segments' congruences (``mechanism.stiffness_congruence``, T_s^T K_jj T_s = K_jj')."""

from __future__ import annotations

import numpy as np
import pytest

from flexcal.geometry.params import reference_mechanism
from flexcal.validation.effects.injectors import ANGLE_REFERENCE, GravitySag, LargeDeflection, reference_angle_gain
from flexcal.validation.prototype.mechanism import (build_prototype, frame_stiffness, simulate, stiffness_congruence,
                                                    tied_chain_stiffness)
from flexcal.validation.prototype.segments import analytic_provider, section_nodes
from flexcal.validation.prototype.transmission import ActuatorTransmission

UNITS = np.r_[np.ones(3), np.full(3, 0.02)]  # [m] per unit DOF: rotations as displacements 20 mm out


def _spd(rng, n, units):
    """A random symmetric positive definite (n, n) in the DOFs' ``units`` [SI-like: ~1e6 N/m]."""
    a = rng.normal(size=(n, n))
    return 1e6 * (a @ a.T + n * np.eye(n)) / units[:, None] / units[None, :]


def _block_diagonal(blocks):
    out = np.zeros((30, 30))
    for s, k in enumerate(blocks):
        out[6 * s:6 * s + 6, 6 * s:6 * s + 6] = k
    return out


def _relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


def test_congruence_maps_the_stiffness_onto_the_changed_one():
    rng = np.random.default_rng(3)
    K, K_changed = _spd(rng, 6, UNITS), _spd(rng, 6, UNITS)
    T = stiffness_congruence(K, K_changed)
    assert _relative(T.T @ K @ T, K_changed) <= 1e-12  # round-off of 6 x 6 products (condition ~1e4); 1e-12
    # a factor s on K is sqrt(s) I (round-off of the Cholesky factor's inverse; 1e-13)
    assert np.abs(stiffness_congruence(K, 1.21 * K) - 1.1 * np.eye(6)).max() <= 1e-13
    with pytest.raises(ValueError, match="not positive definite"):
        stiffness_congruence(K, K - 2.0 * np.linalg.eigvalsh(K)[-1] * np.eye(6))


def test_tied_chain_stiffness_reduces_to_the_changed_blocks_and_scales_whole_chains():
    rng = np.random.default_rng(4)
    kjj = np.array([[_spd(rng, 6, UNITS) for _ in range(5)] for _ in range(6)])
    changed = kjj.copy()
    changed[1, 2] = _spd(rng, 6, UNITS)  # any change of one segment
    changed[4] *= 0.8  # a whole chain
    changed[5, 0] *= 1.3  # one segment by a factor
    diagonal = np.array([_block_diagonal(k) for k in kjj])
    out = tied_chain_stiffness(diagonal, kjj, changed)
    # on block diagonals: the changed blocks (round-off of T^T K T, 1e-12)
    assert _relative(out, np.array([_block_diagonal(k) for k in changed])) <= 1e-12
    chains = np.array([_spd(rng, 30, np.tile(UNITS, 5)) for _ in range(6)])
    out = tied_chain_stiffness(chains, kjj, changed)
    assert np.array_equal(out[[0, 2, 3]], chains[[0, 2, 3]])  # chains left as they were: to the bit
    assert _relative(out[4], 0.8 * chains[4]) <= 1e-12  # a whole chain's factor scales K_chain (round-off; 1e-12)
    S = np.diag(np.r_[np.full(6, np.sqrt(1.3)), np.ones(24)])
    assert _relative(out[5], S @ chains[5] @ S) <= 1e-12  # S^1/2 K_chain S^1/2 (round-off; 1e-12)
    T = np.eye(30)
    T[12:18, 12:18] = stiffness_congruence(kjj[1, 2], changed[1, 2])
    assert _relative(out[1], T.T @ chains[1] @ T) <= 1e-12  # as above
    assert _relative(out[1], chains[1]) > 1e-2  # and the change is there (a random new block)


def _coupled_provider(scale: float = 1.0):
    """The analytic provider with a coupled ``chain_stiffness`` (``scale`` x): the segments'
    compliance plus an axial compliance shared by the five (tests/test_structure_tied.py)."""
    base = analytic_provider()

    def provider(chain, x_start, x_end):
        return scale * base(chain, x_start, x_end)

    def chain_stiffness(chain):
        nodes = section_nodes(chain)
        K = _block_diagonal([base(chain, float(nodes[s]), float(nodes[s + 1]))[6:, 6:] for s in range(5)])
        a = np.zeros(30)
        a[0::6] = 1.0
        c = 0.01 * sum(np.linalg.inv(K[6 * s:6 * s + 6, 6 * s:6 * s + 6])[0, 0] for s in range(5))
        Ka = K @ a
        return scale * (K - c * np.outer(Ka, Ka) / (1.0 + c * a @ Ka))

    provider.chain_stiffness = chain_stiffness
    return provider


def test_a_chain_factor_on_tied_cuts_is_the_scaled_chain():
    """LargeDeflection scales whole chains by a factor that depends on the command: at a
    command where it is s = 1 + coefficient x bend for every chain, the tied prototype with the
    effect is the tied prototype whose K_chain (and K_jj) are s times larger. GravitySag
    (per-chain factors of the point's own loads) runs and moves the angles."""
    mechanism = reference_mechanism()
    transmissions = [ActuatorTransmission(initial_position=-0.20e-3, clearance=0.42e-3, hysteresis=0.83)] * 3
    command = np.array([[0.6e-3, -0.4e-3, 0.3e-3]])
    effect = LargeDeflection(coefficient=(0.05,) * 6)
    gain = np.asarray(reference_angle_gain()).reshape(3, 3)
    bend = float(np.sum((gain @ command[0]) ** 2)) / ANGLE_REFERENCE**2
    tied = build_prototype(mechanism, transmissions, _coupled_provider())
    scaled = build_prototype(mechanism, transmissions, _coupled_provider(1.0 + 0.05 * bend))
    with_effect = simulate(tied, command, effects=[effect])
    expected = simulate(scaled, command)
    plain = simulate(tied, command)
    # the same equilibrium to Newton's tolerances (< 1e-11 rad) and the congruence's round-off
    # (~1e-15 of K): measured 5e-15 rad; 1e-10 rad
    assert np.abs(with_effect.true_angles - expected.true_angles).max() <= 1e-10
    assert np.abs(with_effect.true_angles - plain.true_angles).max() > 1e-8  # the effect moves them (measured 4.7e-6 rad)
    sag = simulate(tied, command, effects=[GravitySag(coefficient=(0.05,) * 6)])
    assert np.abs(sag.true_angles - plain.true_angles).max() > 1e-8  # and so does a load-dependent one (1.3e-5 rad)
    blocks = frame_stiffness(tied, tied.segment_stiffness * 1.1).blocks
    assert _relative(blocks, 1.1 * tied.chain_stiffness) <= 1e-12  # round-off of the congruence; 1e-12
