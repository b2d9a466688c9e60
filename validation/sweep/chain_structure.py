"""A sweep's structural columns of one flexure chain (issue "the mount as a structure"):
what a mount designer checks of a chain before its compliance.

All from the chain's FEM (quadratic tets, end faces on planes A and B, chain along x from
A to B, ``geometry.solids.chain_solid``):

* **first clamped frequency** [Hz]: the lowest natural frequency with the end face A
  clamped (its nodes held) and the rest free, by shift-invert Lanczos on the full mesh
  (``fem.eigen.natural_modes``, consistent mass ``fem.mass``). Every chain-internal mode is
  in it (the strut swinging between its leaves), not only the end-node motions a Guyan
  reduction keeps.
* **peak stress per lateral stroke** [Pa/m], each lateral direction y and z: end B moved
  sideways by a unit length with its turning held (the chain swaying as in the mount,
  where the frame holds B's rotation; its axial motion free), the largest nodal von Mises
  stress in the leaves (their fillets included) per metre of the motion. The rigid end
  blocks are left out: the rigidly coupled end faces concentrate stress singularly there.
* **sway buckling load** [N]: the axial compression at which the chain, end A clamped,
  end B turning held and free sideways, loses its lateral stiffness: the force carried
  between A and B tilts by delta / L when B moves sideways by delta
  (``fem.geometric.axial_link_geometric_stiffness``), so N_cr = L k_lat with k_lat the
  smaller lateral stiffness of B (its rotations held, its axial motion free) from the
  condensed 12 x 12. For a rigid strut between two pivots of rotational stiffness k this
  is the closed form N = 2 k / L (tests/test_sweep_structure.py).
"""

from __future__ import annotations

import numpy as np

__all__ = ["chain_structure"]


def _leaf_nodes(mesh, chain) -> np.ndarray:
    """Boolean (n_nodes,): nodes whose x lies in a leaf piece (fillets included)."""
    x = mesh.nodes[:, 0]
    inside = np.zeros(len(x), bool)
    for kind, a, b in chain.segments():
        if kind.startswith("leaf"):
            inside |= (x >= a) & (x <= b)
    return inside


def _guided_lateral(stiffness_b: np.ndarray, direction: int) -> tuple[np.ndarray, float]:
    """(motion of B (6,) for a unit sideways move along ``direction`` (1: y, 2: z) with
    the rotations held and the axial motion free, the force that takes [N/m])."""
    k = stiffness_b[:3, :3]
    motion = np.zeros(6)
    motion[direction] = 1.0
    motion[0] = -k[0, direction] / k[0, 0]  # no axial force
    return motion, float((k @ motion[:3])[direction])


def chain_structure(mesh, material, part, chain, solution, stiffness_matrix) -> dict[str, np.ndarray]:
    """Structural figures of a chain (module docstring): ``first_frequency_clamped_hz``,
    ``stress_per_m_lateral`` (2,) [Pa/m] for y and z, ``lateral_stiffness`` (2,) [N/m],
    ``buckling_load_sway`` [N]. ``solution``: its ``solve_chain`` condensation (A then B,
    mesh axes); ``stiffness_matrix``: the assembled K (3 n_nodes)^2 it used."""
    import scipy.sparse as sp

    from flexcal.fem.condense import chain_displacement
    from flexcal.fem.coupling import select_plane_nodes
    from flexcal.fem.eigen import natural_modes
    from flexcal.fem.mass import assemble_mass
    from flexcal.fem.results import nodal_stress, von_mises

    K_c = 0.5 * (solution.stiffness + solution.stiffness.T)
    k_bb = K_c[6:, 6:]
    leaves = _leaf_nodes(mesh, chain)
    stress, lateral = np.zeros(2), np.zeros(2)
    for i, direction in enumerate((1, 2)):
        motion, lateral[i] = _guided_lateral(k_bb, direction)
        u = chain_displacement(solution, np.r_[np.zeros(6), motion])
        stress[i] = von_mises(nodal_stress(mesh, material, u))[leaves].max()
    length = float(np.linalg.norm(part.reference_points["B"] - part.reference_points["A"]))

    held = select_plane_nodes(mesh, part.end_planes["A"])
    free = np.setdiff1d(np.arange(3 * len(mesh.nodes)), (3 * held[:, None] + np.arange(3)).ravel())
    K = sp.csr_matrix(stiffness_matrix)[free][:, free]
    M = assemble_mass(mesh, material)[free][:, free]
    first = natural_modes(K, M, 1).frequencies[0]
    return {"first_frequency_clamped_hz": np.array(first), "stress_per_m_lateral": stress,
            "lateral_stiffness": lateral, "buckling_load_sway": np.array(length * lateral.min())}
