"""A chain of segments joined through section fields, as one coupled stiffness on the
segments' deformation twists (issue 26; docs/meshing.md, "Session 24: the tied-cut frame").

The virtual prototype joins its five segments at four interior section bodies. Joined
through a field q (n_q DOFs, ``flexcal.fem.interface``) instead of a rigid tie, each cut's
field is split into the section body's rigid motion r and the cut's warping w:

    q = E r + N w                                                             (1)

E (n_q, 6): the six rigid motions' coefficients in the field basis (the motion u = t +
theta x (x - c) of the face about its centre c); N (n_q, n_q - 6): a basis of the complement
of E that is orthogonal to it in the face's L2 inner product, N^T G E = 0, G the Gram matrix
of the field basis on the cut face, the full square |y|, |z| <= ``scale`` (the chains'
square section; Legendre's basis is orthogonal there, so G is diagonal). Then r = (E^T G
E)^-1 E^T G q is the face's least-squares rigid motion, the section body of the frame.

A segment's stiffness vanishes on its rigid motions, which have w = 0 at both ends and the
end body's r carried rigidly from the start body's. Its energy is therefore a fixed
quadratic form in (w_start, xi, w_end), xi = r_end - Ad(D) r_start (linearised) its
deformation twist: the segment's stiffness on (r, w) at both ends with the start's r rows
and columns dropped (the start clamped). Summed over the chain, each cut's w shared by the
two segments meeting there, and every w condensed out, this leaves one 6 n x 6 n stiffness
on the n segments' twists Xi = (xi_1, ..., xi_n): energy 1/2 Xi^T K_chain Xi. With rigid
ties (no w) it is the block diagonal of the segments' end blocks K_jj, the prototype's frame
today.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.linalg

from .interface import RIGID, n_interface_dofs, polynomial_exponents, section_modes

__all__ = ["rigid_field_coefficients", "section_gram_diagonal", "warping_basis", "chain_twist_stiffness",
           "rigid_part_stiffness", "clamped_end_stiffness"]


@functools.lru_cache(maxsize=64)
def rigid_field_coefficients(order, scale: float) -> np.ndarray:
    """E (n_q, 6) [m / (m or rad)]: the coefficients of the six rigid motions (ux, uy, uz, rx,
    ry, rz about the section centre, ``RigidCoupling``'s) in the section field of ``order``
    (``RIGID``: the identity), polynomials in (y, z) / ``scale`` [m]. Found by least squares
    on the face's points; exact, since the rigid motions lie in every field of order >= 1.
    Remembered per (order, scale), read-only (a chain's join asks for each cut's several times:
    ~0.2 s a tied chain, session 40)."""
    return _read_only(_rigid_field_coefficients(order, scale))


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _rigid_field_coefficients(order, scale: float) -> np.ndarray:
    if order == RIGID:
        return np.eye(6)
    side = np.linspace(-scale, scale, int(order) + 3)
    y, z = np.meshgrid(side, side, indexing="ij")
    points = np.column_stack([np.zeros(y.size), y.ravel(), z.ravel()])
    field = section_modes(points, np.zeros(3), order, scale).reshape(-1, n_interface_dofs(order))
    rigid = section_modes(points, np.zeros(3), RIGID, scale).reshape(-1, 6)
    coefficients, *_ = np.linalg.lstsq(field, rigid, rcond=None)
    return coefficients


def section_gram_diagonal(order) -> np.ndarray:
    """(n_q,): the Gram matrix of the section field's basis P_a(y/s) P_b(z/s) e_i on the square
    |y|, |z| <= s, divided by s^2: 4 / ((2a + 1) (2b + 1)) (Legendre's orthogonality; the
    matrix is diagonal). ``RIGID`` has no field basis and is refused."""
    if order == RIGID:
        raise ValueError("a rigid tie has no warping; its Gram matrix is not needed")
    exponents = polynomial_exponents(order)
    per_function = 4.0 / ((2 * exponents[:, 0] + 1) * (2 * exponents[:, 1] + 1))
    return np.repeat(per_function, 3)


@functools.lru_cache(maxsize=64)
def warping_basis(order, scale: float) -> np.ndarray:
    """N (n_q, n_q - 6): an orthonormal basis (in the plain coefficient norm) of the section
    fields of ``order`` whose L2 projection on the rigid motions vanishes (N^T G E = 0,
    ``section_gram_diagonal``, ``rigid_field_coefficients``); (6, 0) for ``RIGID``. Remembered
    per (order, scale), read-only."""
    if order == RIGID:
        return _read_only(np.zeros((6, 0)))
    rigid = rigid_field_coefficients(order, scale)
    return _read_only(scipy.linalg.null_space((rigid * section_gram_diagonal(order)[:, None]).T))


def chain_twist_stiffness(segments, cut_orders, scale: float) -> np.ndarray:
    """K_chain (6 n, 6 n) [SI] on the n segments' deformation twists (module docstring).

    segments: n matrices in chain order, segment k's stiffness on its start section's DOFs
    then its end section's (the chain's two ends rigid, 6 DOFs; cut k (between segments k and
    k + 1) a field of ``cut_orders[k]``: ``RIGID`` or p, ``n_interface_dofs``), each section's
    DOFs about its own centre, in the chain's frame (as ``flexcal.fem.interface.series_stiffness``
    joins them); scale [m]: the fields' length. Twist DOFs per segment: ux, uy, uz, rx, ry, rz
    of its end section relative to its start section carried rigidly."""
    segments = [np.asarray(k, float) for k in segments]
    sizes = [6] + [n_interface_dofs(order) for order in cut_orders] + [6]
    if len(sizes) != len(segments) + 1 or any(k.shape != (a + b, a + b) for k, a, b in
                                              zip(segments, sizes[:-1], sizes[1:])):
        raise ValueError(f"segment shapes {[k.shape for k in segments]} do not match cut orders {list(cut_orders)}")
    bases = [np.eye(6)] + [np.hstack([rigid_field_coefficients(o, scale), warping_basis(o, scale)])
                           for o in cut_orders] + [np.eye(6)]
    n_twist = 6 * len(segments)
    n_warp = [b.shape[1] - 6 for b in bases]
    warp_start = n_twist + np.concatenate([[0], np.cumsum(n_warp)])
    K = np.zeros((warp_start[-1], warp_start[-1]))
    for k, segment in enumerate(segments):
        start, end = bases[k], bases[k + 1]
        transformed = scipy.linalg.block_diag(start, end).T @ segment @ scipy.linalg.block_diag(start, end)
        # local DOFs (r_start | w_start | r_end | w_end): drop r_start (the start clamped)
        kept = np.r_[6:sizes[k] + sizes[k + 1]]
        local = transformed[np.ix_(kept, kept)]
        targets = np.r_[warp_start[k]:warp_start[k + 1], 6 * k:6 * k + 6, warp_start[k + 1]:warp_start[k + 2]]
        K[np.ix_(targets, targets)] += local
    twist, warp = np.arange(n_twist), np.arange(n_twist, K.shape[0])
    coupling = K[np.ix_(twist, warp)]
    out = K[np.ix_(twist, twist)] - coupling @ np.linalg.solve(K[np.ix_(warp, warp)], coupling.T) if warp.size \
        else K
    return 0.5 * (out + out.T)


def rigid_part_stiffness(segments, cut_orders, scale: float) -> np.ndarray:
    """(n, 12, 12) [SI]: each of the n ``segments`` (as ``chain_twist_stiffness`` takes them) on
    the rigid motions of its two end sections only, E^T K E with E = blockdiag(E_start, E_end)
    (``rigid_field_coefficients``): the segment with each cut's field held to a rigid motion
    (q = E r, no warping), DOFs ux..rz of its start section then its end section, each about its
    centre. For a kinematic field that is the face tied rigidly (the field's motions include the
    rigid ones, so restricting them is tying the face), for a distributing one the face's L2
    projection held rigid; ``RIGID`` ends stay as they are (E = I). Their end blocks, side by
    side, are ``chain_twist_stiffness``'s before the warping is condensed out (w = 0)."""
    segments = [np.asarray(k, float) for k in segments]
    orders = [RIGID] + list(cut_orders) + [RIGID]
    if len(orders) != len(segments) + 1:
        raise ValueError(f"{len(segments)} segments need {len(segments) - 1} cut orders, got {len(cut_orders)}")
    out = np.zeros((len(segments), 12, 12))
    for k, segment in enumerate(segments):
        rigid = scipy.linalg.block_diag(rigid_field_coefficients(orders[k], scale),
                                        rigid_field_coefficients(orders[k + 1], scale))
        if segment.shape != (rigid.shape[0],) * 2:
            raise ValueError(f"segment {k} has shape {segment.shape}; its ends' orders need {rigid.shape[0]} DOFs")
        restricted = rigid.T @ segment @ rigid
        out[k] = 0.5 * (restricted + restricted.T)
    return out


def clamped_end_stiffness(twist_stiffness: np.ndarray, lengths) -> np.ndarray:
    """(6, 6) [SI]: the end block (start clamped) of a chain whose n segments of ``lengths``
    (n,) [m] along x carry ``twist_stiffness`` (6 n, 6 n) on their twists, linearised in the
    section bodies' twists r_1..r_n (xi_s = r_s - Ad(D_s) r_(s-1), r_0 = 0, D_s the translation
    by -lengths[s]), the n - 1 interior bodies condensed out. For ``chain_twist_stiffness`` it
    is the end block of the segments joined through their cuts (``series_stiffness``)."""
    from flexcal.geometry.frames import se3_adjoint, translation_pose

    lengths = np.asarray(lengths, float)
    n = len(lengths)
    if twist_stiffness.shape != (6 * n, 6 * n):
        raise ValueError(f"twist stiffness {twist_stiffness.shape} does not match {n} segments")
    B = np.eye(6 * n)
    for s in range(1, n):
        B[6 * s:6 * s + 6, 6 * (s - 1):6 * s] = -se3_adjoint(translation_pose(np.array([-lengths[s], 0.0, 0.0])))
    K = B.T @ twist_stiffness @ B
    inner, end = np.arange(6 * (n - 1)), np.arange(6 * (n - 1), 6 * n)
    out = K[np.ix_(end, end)] - K[np.ix_(end, inner)] @ np.linalg.solve(K[np.ix_(inner, inner)], K[np.ix_(inner, end)])
    return 0.5 * (out + out.T)
