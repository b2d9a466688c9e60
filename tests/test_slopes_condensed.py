"""The compliance slopes by the condensation's derivative (session 16): dK_c/dp = U^T (dK_r/dp) U
from one factorisation (fem/condense.py ``chain_stiffness_derivative``,
validation/runs/model_correction.py ``segment_stiffness_slopes``)."""

import dataclasses

import numpy as np

from flexcal.model.parameters import parameter_space
from flexcal.validation.prototype.fem_provider import canonical_segment
from flexcal.validation.prototype.segments import section_nodes
from flexcal.validation.runs.model_correction import _slopes_parts, segment_stiffness_slopes

STEEL_CHAIN = parameter_space().mechanism.chains[3].chain  # a driving chain (150 mm), its first leaf segment


def _whole_mesh_build(segment, material) -> np.ndarray:
    """(12, 12) [SI] one full FEM build of ``segment`` on the slopes' own discretisation: the
    whole mapped mesh of ``FAST_CHAIN_OPTIONS`` at 2 through, meshed, assembled and factorised
    on its own (not the provider's, which is on the prototype's grid and its mirror part since
    session 17: another discretisation, 0.3-0.4 % apart)."""
    from flexcal.fem.condense import solve_chain
    from flexcal.fem.mesh_mapped_chain import FAST_CHAIN_OPTIONS, mapped_mesh_chain
    from flexcal.geometry.exact import end_planes, reference_points

    mesh = mapped_mesh_chain(segment, elements_through_thickness=2, measure=False, quality=False,
                             **FAST_CHAIN_OPTIONS)[0]
    planes, points = end_planes(segment), reference_points(segment)
    stiffness = solve_chain(mesh, material, planes["A"], points["A"], planes["B"], points["B"]).stiffness
    return 0.5 * (stiffness + stiffness.T)


def _scaled(matrix: np.ndarray, length: float) -> np.ndarray:
    """Every entry in [N/m]: rotations as length x angle (``rigid_mode_defect``'s scaling)."""
    scale = np.tile(np.r_[np.ones(3), np.full(3, 1.0 / length)], 2)
    return scale[:, None] * matrix * scale[None, :]


def test_condensed_derivative_matches_full_builds(tmp_path):
    """The derivative of the first leaf segment's stiffness per relative change of t1, w and l
    (which moves the cut too) against the central difference of two full FEM builds at +-h,
    each meshed, assembled and factorised on its own on the same whole FAST_CHAIN_OPTIONS mesh
    (2 through, to be quick; the same mesh connectivity at +-h, so the difference is of one
    discretisation)."""
    chain = STEEL_CHAIN
    fields = {"t1": "thickness_1", "w": "width", "l": "hinge_length"}
    h = 1e-3
    out = segment_stiffness_slopes(chain, 0, tuple(fields), material=parameter_space().mechanism.material,
                                   elements_through_thickness=2, cache_directory=tmp_path)
    length = section_nodes(chain)[1]
    for k, (symbol, field) in enumerate(fields.items()):
        built = {}
        for sign in (1, -1):
            moved = dataclasses.replace(chain, **{field: getattr(chain, field) * (1 + sign * h)})
            segment, _ = canonical_segment(moved, *section_nodes(moved)[:2])
            built[sign] = _whole_mesh_build(segment, parameter_space().mechanism.material)
        difference = _scaled((built[1] - built[-1]) / (2 * h), length)
        derivative = _scaled(out["slopes"][k], length)
        assert np.max(np.abs(derivative)) > 1e-3 * np.max(np.abs(_scaled(out["stiffness"], length)))  # it moves
        # relative to the largest entry: the full builds' difference is the derivative to O(h^2)
        # (~1e-6 of it) plus the factorisations' rounding over 2h (~1e-12 / 2e-3 of K); measured
        # 1.7e-7 (t1), 4.0e-7 (w), 9.5e-7 (l) on 2026-11-27; 1e-5 is 10x the truncation
        error = np.max(np.abs(derivative - difference)) / np.max(np.abs(difference))
        assert error < 1e-5, (symbol, error)  # 10x the O(h^2) truncation (above; measured <= 9.5e-7)


def test_the_slopes_cache_key_names_the_method():
    chain = STEEL_CHAIN
    material = parameter_space().mechanism.material
    parts = _slopes_parts(chain, 0, ("t1",), material, 6.0, "mapped", 1e-4)
    assert parts["kind"] == "chain_segment_stiffness_slopes" and "U^T dK_r U" in parts["method"]
    from flexcal.fem.cache import cache_key
    from flexcal.validation.prototype.fem_provider import segment_cache_key

    segment, _ = canonical_segment(chain, *section_nodes(chain)[:2])
    assert cache_key(parts) != segment_cache_key(segment, material, elements_through_thickness=6.0)
    assert cache_key(parts) != cache_key(_slopes_parts(chain, 0, ("t1",), material, 6.0, "mapped", 1e-5))
    assert cache_key(parts) != cache_key({**parts, "method": "builds"})
