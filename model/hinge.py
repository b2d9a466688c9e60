"""6x6 compliance of flexure segments from beam theory over the real profile t(x).

One profile covers every segment of a flexure chain: a flat part of thickness ``t`` and
length ``2c`` with a quarter-circle fillet of radius ``rho`` at each end (thickness rising
to ``t + 2 rho``), width ``w`` (along z) constant. A corner-filleted leaf (paper Fig. 5c)
is ``c = l/2 - a, rho = a``; a right-circular notch is ``c = 0, rho = R``; a uniform
rectangular beam (blocks, connectors, strut) is ``rho = 0``.

Frame (geometry/params.py "hinge frame"): x along the segment from the fixed end
(x = -l/2) to the free end (x = +l/2), y across the thickness, z along the width. The
compliance is at the centre of the free end section, fixed end clamped, loads applied at
the free end; twists ``[ux, uy, uz, rx, ry, rz]``, wrenches ``[Fx, Fy, Fz, Mx, My, Mz]``.
With xi = l/2 - x the distance from the free end (REFERENCES.md "Hinge compliance"):

    C_ux,Fx   = 1/E  int dx/(w t)
    C_uy,Fy   = 12/E int xi^2/(w t^3) dx + int dx/(k G w t)      (+ shear, Timoshenko)
    C_uy,Mz   = 12/E int xi/(w t^3) dx        (= l/2 C_rz,Mz, symmetric profile)
    C_rz,Mz   = 12/E int dx/(w t^3)
    C_uz,Fz   = 12/E int xi^2/(w^3 t) dx + int dx/(k G w t)
    C_uz,My   = -12/E int xi/(w^3 t) dx       (negative: +Fz tips the end about -y)
    C_ry,My   = 12/E int dx/(w^3 t)  = (12/w^2) C_ux,Fx
    C_rx,Mx   = 1/G  int dx/J(t, w)

with the Saint-Venant torsion constant of a rectangle (long side b, short side h)
``J = b h^3 (1/3 - 0.21 (h/b)(1 - h^4/(12 b^4)))`` (Roark's Formulas, rectangle in
torsion, accurate to a few 0.1 %) and Cowper's shear coefficient of a rectangle
``k = 10 (1 + nu)/(12 + 11 nu)`` (Cowper 1966).

Closed forms (the published ones) are used where they exist:
- ``int dx/t^3`` over a circular arc pair: Paros & Weisbord (1965) / Lobontiu (2003)
  exact right-circular formula, ``C_rz,Mz = 12/(E w R^2) [2s^3(6s^2+4s+1)/((2s+1)(4s+1)^2)
  + 12 s^4 (2s+1)/(4s+1)^(5/2) arctan sqrt(4s+1)]``, s = R/t (REFERENCES.md; example
  R 5, t 1, w 10 mm, E 206 GPa -> 0.0149514 rad/(N m));
- ``int dx/t`` over the arc pair: the same authors' axial closed form
  ``[2(2s+1)/sqrt(4s+1) arctan sqrt(4s+1) - pi/2]`` (dimensionless);
- corner-filleted leaf: flat part ``12 (l - 2a)/(E w t^3)`` plus the circular formula with
  R = a (Lobontiu 2003): the two quarter-fillets together are one circular notch;
- first moments ``int u/t^n du`` over an arc: elementary antiderivatives (derived here,
  ``_arc_first_moments``).
The remaining arc integrals (second moments, torsion) have no tidy closed form in the
literature; they are evaluated with fixed Gauss-Legendre nodes after the
substitution x = R sin(phi), phi = 2 arctan(tau v), tau = sqrt(t/(t + 4R)), which makes
the integrand smooth and O(1)-wide in v; two panels split where t(x) = w (the torsion
formula switches long and short side there). The node count follows the batch's
smallest t/R (``gauss_node_count``); measured against 400 nodes the error is <= 4e-13 for
t/R from 0.01 to 1.5 (3e-14 unless t = w inside a fillet), and the tests hold every entry
to 1e-11 against ``scipy.integrate.quad``.

All functions broadcast over batches of dimensions (the PSO varies them per candidate).
"""

from __future__ import annotations

import functools

import numpy as np

from flexcal.geometry.params import Material

from . import kernel
from .profiles import closed_form_of
from .serial import serial_compliance

__all__ = [
    "segment_compliance",
    "segment_entries",
    "entries_from_integrals",
    "entries_to_matrix",
    "ENTRY_INDEX",
    "leaf_compliance",
    "circular_notch_compliance",
    "beam_compliance",
    "hinge_compliance_matrix",
    "profile_integrals",
    "profile_thickness",
    "torsion_constant",
    "shear_coefficient",
    "circular_notch_rotation_compliance",
    "closed_form_range_warnings",
]



COMPILED_MIN_ARCS = 512  # smaller batches use numpy (no numba import / compile for a few hinges)


@functools.lru_cache(maxsize=None)
def _gauss_legendre(n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    return np.polynomial.legendre.leggauss(n_nodes)


def gauss_node_count(v_end: np.ndarray) -> int:
    """Gauss-Legendre nodes per panel for a batch whose longest mapped interval is ``v_end``.

    In sigma = arcsinh(v) the integrands' poles sit at Im(sigma) = +-pi/2 and the interval
    grows like ln(V), V = sqrt(1 + 4R/t). Measured against 400 nodes, 3e-14 relative needs
    10-16 nodes at t/R = 0.3-1.5 (V <= 3.8; 18 where t = w inside the fillet), 18 at
    t/R = 0.1, 22 at t/R = 0.01: we take ``2 ceil((13 + 3 ln V)/2)`` for the worst arc
    (16 for the reference leaves; worst measured error 4e-13, at t = w crossings).
    """
    worst = float(np.max(v_end, initial=1.0))
    return int(2 * np.ceil((13.0 + 3.0 * np.log(worst)) / 2.0))


def shear_coefficient(poisson_ratio: float | np.ndarray) -> np.ndarray:
    """Cowper's Timoshenko shear coefficient of a rectangle, 10(1+nu)/(12+11nu) [-]."""
    nu = np.asarray(poisson_ratio, dtype=float)
    return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)


def torsion_constant(thickness: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Saint-Venant torsion constant J [m^4] of a thickness x width rectangle (Roark)."""
    t, w = np.asarray(thickness, dtype=float), np.asarray(width, dtype=float)
    short, long = np.minimum(t, w), np.maximum(t, w)
    ratio = short / long
    ratio2 = ratio * ratio
    return long * short * short * short * (1.0 / 3.0 - 0.21 * ratio * (1.0 - ratio2 * ratio2 / 12.0))


def profile_thickness(x: np.ndarray, flat_half_length, fillet, thickness) -> np.ndarray:
    """Thickness t(x) [m] of the profile at x [m] (hinge frame, |x| <= c + rho)."""
    u = np.maximum(np.abs(np.asarray(x, dtype=float)) - flat_half_length, 0.0)
    rho = np.asarray(fillet, dtype=float)
    return thickness + 2.0 * (rho - np.sqrt(np.maximum(rho**2 - u**2, 0.0)))


def _circular_pair_integrals(radius: np.ndarray, thickness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed forms of int dx/t and int dx/t^3 over a full circular notch (x in [-R, R]).

    Returns (int dx/t [-], int dx/t^3 [1/m^2]); zero where R = 0.
    """
    s = np.maximum(radius, 0.0) / thickness
    root = np.sqrt(4.0 * s + 1.0)
    arctan = np.arctan(root)
    inv_t = 2.0 * (2.0 * s + 1.0) / root * arctan - np.pi / 2.0
    # the published bracket / R^2, divided through by s^2 (= R^2/t^2) so that R -> 0 is safe
    bracket_over_s2 = (2.0 * s * (6.0 * s**2 + 4.0 * s + 1.0) / ((2.0 * s + 1.0) * (4.0 * s + 1.0) ** 2)
                       + 12.0 * s**2 * (2.0 * s + 1.0) / root**5 * arctan)
    inv_t3 = bracket_over_s2 / thickness**2
    positive = radius > 0
    return np.where(positive, inv_t, 0.0), np.where(positive, inv_t3, 0.0)


def circular_notch_rotation_compliance(radius, thickness, width, youngs_modulus) -> np.ndarray:
    """C_rz,Mz [rad/(N m)] of a right-circular notch, the exact Paros-Weisbord/Lobontiu formula."""
    radius, thickness = np.asarray(radius, dtype=float), np.asarray(thickness, dtype=float)
    return 12.0 / (youngs_modulus * np.asarray(width, dtype=float)) * _circular_pair_integrals(radius, thickness)[1]


def _arc_first_moments(radius: np.ndarray, thickness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed forms of int_0^R u/t du and int_0^R u/t^3 du over one quarter arc.

    With s = sqrt(R^2 - u^2) (u du = -s ds) and q = T - 2s, T = t + 2R, both become
    ``1/4 int_t^T (T - q)/q^n dq`` (elementary, derived here; checked against quad):
    n = 1: ``(T ln(T/t) - 2R)/4``; n = 3: ``(T/2 (1/t^2 - 1/T^2) - (1/t - 1/T))/4``.
    Returns ([m], [1/m]).
    """
    r, t = np.asarray(radius, dtype=float), np.asarray(thickness, dtype=float)
    big_t = t + 2.0 * r
    first_t1 = 0.25 * (big_t * np.log1p(2.0 * r / t) - 2.0 * r)
    first_t3 = 0.25 * (0.5 * big_t * (1.0 / t**2 - 1.0 / big_t**2) - (1.0 / t - 1.0 / big_t))
    return first_t1, first_t3


def _arc_quadrature(radius: np.ndarray, thickness: np.ndarray, width: np.ndarray) -> dict[str, np.ndarray]:
    """``_arc_quadrature_numpy``, compiled (``kernel.arc_quadrature_compiled``) when numba is there."""
    r, t, w = np.broadcast_arrays(np.asarray(radius, float), np.asarray(thickness, float), np.asarray(width, float))
    if r.size < COMPILED_MIN_ARCS or not kernel.available():
        return _arc_quadrature_numpy(r, t, w)
    tau = np.sqrt(t / (t + 4.0 * r))
    nodes, weights = _gauss_legendre(gauss_node_count(1.0 / tau[r > 0]))
    out = kernel.arc_quadrature_compiled(r, t, w, nodes, weights)
    return {"2,t1": out[..., 0], "2,t3": out[..., 1], "0,J": out[..., 2]}


def _arc_quadrature_numpy(radius: np.ndarray, thickness: np.ndarray, width: np.ndarray) -> dict[str, np.ndarray]:
    """Gauss-Legendre integrals over one quarter arc u in [0, R], t(u) = t + 2R - 2 sqrt(R^2 - u^2).

    Keys "2,t1" = int u^2/t du [m^2], "2,t3" = int u^2/t^3 du [1], "0,J" = int du/J(t, w)
    [1/m^3]. Shapes broadcast from the inputs. One panel, or two split where t = w if that
    happens anywhere in the batch (the torsion formula has a kink there).
    """
    r, t, w = np.broadcast_arrays(np.asarray(radius, float), np.asarray(thickness, float), np.asarray(width, float))
    tau = np.sqrt(t / (t + 4.0 * r))
    v_end = 1.0 / tau
    # t(v) = t (1 + v^2) / (1 + tau^2 v^2) reaches w at v^2 = (w - t) / (t - w tau^2)
    crosses = (w > t) & (w < t + 2.0 * r)
    if np.any(crosses):
        denom = np.where(crosses, t - w * tau**2, 1.0)
        v_split = np.where(crosses, np.sqrt(np.where(crosses, (w - t) / denom, 0.0)), v_end)
        lo = np.arcsinh(np.stack([np.zeros_like(v_split), v_split], axis=-1))[..., :, None]
        hi = np.arcsinh(np.stack([v_split, v_end], axis=-1))[..., :, None]
    else:
        lo, hi = np.zeros(v_end.shape + (1, 1)), np.arcsinh(v_end)[..., None, None]
    half = 0.5 * (hi - lo)
    nodes, weights = _gauss_legendre(gauss_node_count(v_end[r > 0]))
    tau_ = tau[..., None, None]
    # nodes in sigma = arcsinh(v) (moves the poles at v = +-i, +-i/tau to Im = +-pi/2):
    # v = sinh(sigma), dv = cosh(sigma) dsigma
    sigma = lo + half * (nodes + 1.0)  # (..., n_panels, n)
    v = np.sinh(sigma)
    tv2p1 = 1.0 + (tau_ * v) ** 2
    # u = R sin(phi), du = R cos(phi) dphi, phi = 2 arctan(tau v), dphi = 2 tau / (1 + tau^2 v^2) dv
    two_r_tau = (2.0 * r[..., None, None]) * tau_
    u = two_r_tau * v / tv2p1
    du = (half * weights) * np.cosh(sigma) * two_r_tau * (2.0 - tv2p1) / (tv2p1 * tv2p1)
    thick = t[..., None, None] * (1.0 + v * v) / tv2p1
    u2_t = u * u * du / thick
    axes = (-2, -1)
    return {"2,t1": np.sum(u2_t, axis=axes), "2,t3": np.sum(u2_t / (thick * thick), axis=axes),
            "0,J": np.sum(du / torsion_constant(thick, w[..., None, None]), axis=axes)}


def profile_integrals(flat_half_length, fillet, thickness, width) -> dict[str, np.ndarray]:
    """Integrals over the whole profile x in [-(c + rho), c + rho] (symmetric about x = 0).

    flat_half_length c [m], fillet rho [m] (>= 0), thickness t [m], width w [m] (broadcast).
    Returns "M0,f" = int f dx for f in {"t1", "t3", "J"} (1/t, 1/t^3, 1/J(t, w)) and
    "M2,f" = int x^2 f dx for f in {"t1", "t3"}. Arc parts: M0 of 1/t and 1/t^3 and the
    first moments are closed forms, the second moments and the torsion Gauss-Legendre.
    """
    c, rho, t, w = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (flat_half_length, fillet,
                                                                              thickness, width)))
    has_arc = rho > 0
    if np.any(has_arc):
        quad = _arc_quadrature(rho, t, w)
        pair_t1, pair_t3 = _circular_pair_integrals(rho, t)
        first_t1, first_t3 = _arc_first_moments(rho, t)
        arc = {"0,t1": 0.5 * pair_t1, "0,t3": 0.5 * pair_t3, "0,J": quad["0,J"],
               "1,t1": np.where(has_arc, first_t1, 0.0), "1,t3": np.where(has_arc, first_t3, 0.0),
               "2,t1": quad["2,t1"], "2,t3": quad["2,t3"]}
    else:  # uniform beams: no arcs, skip the quadrature
        arc = dict.fromkeys(("0,t1", "0,t3", "0,J", "1,t1", "1,t3", "2,t1", "2,t3"), 0.0)
    inv_t = 1.0 / t
    flat = {"t1": inv_t, "t3": inv_t * inv_t * inv_t, "J": 1.0 / torsion_constant(t, w)}
    out = {}
    for name, value in flat.items():
        out[f"M0,{name}"] = 2.0 * c * value + 2.0 * arc[f"0,{name}"]
    for name in ("t1", "t3"):
        # x = c + u on the arc: x^2 = c^2 + 2 c u + u^2
        out[f"M2,{name}"] = (2.0 * c**3 / 3.0 * flat[name]
                             + 2.0 * (c * c * arc[f"0,{name}"] + 2.0 * c * arc[f"1,{name}"] + arc[f"2,{name}"]))
    return out


ENTRY_INDEX = {"ux_Fx": (0, 0), "uy_Fy": (1, 1), "uy_Mz": (1, 5), "rz_Mz": (5, 5), "uz_Fz": (2, 2),
               "uz_My": (2, 4), "ry_My": (4, 4), "rx_Mx": (3, 3)}


def segment_entries(flat_half_length, fillet, thickness, width, youngs_modulus, poisson_ratio) -> dict[str, np.ndarray]:
    """The eight independent compliance entries of a profile segment at its free end.

    Keys of ``ENTRY_INDEX`` ("ux_Fx" [m/N], "uy_Fy" [m/N], "uy_Mz" [1/N], "rz_Mz" [1/(N m)],
    "uz_Fz", "uz_My", "ry_My", "rx_Mx"); symmetric partners are equal. Inputs as in
    ``segment_compliance``.
    """
    c, rho, t, w = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (flat_half_length, fillet,
                                                                              thickness, width)))
    return entries_from_integrals(profile_integrals(c, rho, t, w), c + rho, w, youngs_modulus, poisson_ratio)


def entries_from_integrals(ints: dict[str, np.ndarray], half, width, youngs_modulus, poisson_ratio
                           ) -> dict[str, np.ndarray]:
    """``segment_entries`` from the profile integrals of any symmetric profile.

    ints: "M0,t1", "M0,t3", "M0,J", "M2,t1", "M2,t3" as ``profile_integrals`` returns them
    (over x in [-half, half], x from the middle); half [m]: half the segment's length;
    width w [m]; youngs_modulus E [Pa], poisson_ratio nu [-].
    """
    w = np.asarray(width, dtype=float)
    e = float(youngs_modulus)
    g = e / (2.0 * (1.0 + float(poisson_ratio)))
    kappa = shear_coefficient(poisson_ratio)
    shear = ints["M0,t1"] / (kappa * g * w)
    bend_z0 = 12.0 * ints["M0,t3"] / (e * w)  # about z, thin direction
    bend_y0 = 12.0 * ints["M0,t1"] / (e * w**3)  # about y, wide direction
    xi2_t3 = half**2 * ints["M0,t3"] + ints["M2,t3"]  # int xi^2/t^3, xi = half - x
    xi2_t1 = half**2 * ints["M0,t1"] + ints["M2,t1"]
    return {
        "ux_Fx": ints["M0,t1"] / (e * w),
        "uy_Fy": 12.0 * xi2_t3 / (e * w) + shear,
        "uy_Mz": half * bend_z0,
        "rz_Mz": bend_z0,
        "uz_Fz": 12.0 * xi2_t1 / (e * w**3) + shear,
        "uz_My": -half * bend_y0,
        "ry_My": bend_y0,
        "rx_Mx": ints["M0,J"] / g,
    }


def entries_to_matrix(entries: dict[str, np.ndarray]) -> np.ndarray:
    """Assemble ``segment_entries`` into the symmetric (..., 6, 6) compliance."""
    shape = np.broadcast_shapes(*(np.shape(v) for v in entries.values()))
    out = np.zeros(shape + (6, 6))
    for key, (i, j) in ENTRY_INDEX.items():
        out[..., i, j] = out[..., j, i] = entries[key]
    return out


def segment_compliance(flat_half_length, fillet, thickness, width, youngs_modulus, poisson_ratio) -> np.ndarray:
    """6x6 compliance (..., 6, 6) of one profile segment at its free end (module docstring).

    flat_half_length c [m], fillet rho [m], thickness t [m] (along y, minimum), width w [m]
    (along z); youngs_modulus E [Pa], poisson_ratio nu [-]. Units of the entries: m/N,
    1/N (= rad/N = m/(N m)), rad/(N m).
    """
    return entries_to_matrix(segment_entries(flat_half_length, fillet, thickness, width, youngs_modulus,
                                             poisson_ratio))


def leaf_compliance(length, thickness, width, fillet, material: Material) -> np.ndarray:
    """Corner-filleted leaf (paper Fig. 5c) at the free end of its length-l segment.

    length l [m] (including both fillets), thickness t [m], width w [m], fillet a [m]
    (0 <= a <= l/2), all broadcast -> (..., 6, 6). C_rz,Mz = 12(l - 2a)/(E w t^3) +
    C_circ(R = a) (Lobontiu 2003); other entries as in the module docstring.
    """
    length, fillet = np.asarray(length, dtype=float), np.asarray(fillet, dtype=float)
    if np.any(fillet < 0) or np.any(2.0 * fillet > length * (1.0 + 1e-12)):
        raise ValueError("leaf fillet a must satisfy 0 <= a <= l/2 (both fillets must fit the segment)")
    return segment_compliance(np.maximum(0.5 * length - fillet, 0.0), fillet, thickness, width,
                              material.youngs_modulus, material.poisson_ratio)


def circular_notch_compliance(radius, thickness, width, material: Material) -> np.ndarray:
    """Right-circular notch (length 2R) at the free end of the notch, (..., 6, 6).

    radius R [m], minimum thickness t [m], width w [m], broadcast. C_rz,Mz and C_ux,Fx are
    the Paros-Weisbord/Lobontiu closed forms, the others Gauss-Legendre of the same integrals.
    """
    return segment_compliance(0.0, radius, thickness, width, material.youngs_modulus, material.poisson_ratio)


def beam_compliance(length, height, width, material: Material) -> np.ndarray:
    """Uniform Timoshenko beam of a height (y) x width (z) rectangle at its free end, (..., 6, 6).

    length [m], height [m], width [m]; e.g. C_uy,Fy = l^3/(3 E I_z) + l/(k G A).
    """
    return segment_compliance(0.5 * np.asarray(length, dtype=float), 0.0, height, width,
                              material.youngs_modulus, material.poisson_ratio)


def hinge_compliance_matrix(hinge, material: Material) -> np.ndarray:
    """(6, 6) compliance of a stand-alone hinge at its free-end reference point.

    The reference point is the centre of the free end face (x = +total_length/2 in the
    hinge frame of geometry/params.py); the face at -total_length/2 is clamped and both
    blocks are rigid, so the profile's closed form (``model.profiles``) is moved from
    x = +length/2 to the face by the adjoint transform (Eq. 1 with one element). This is
    what the FEM condenses.
    """
    local = closed_form_of(hinge).compliance(hinge, material)
    return serial_compliance(local[None], np.eye(3)[None], np.array([[0.5 * hinge.length, 0.0, 0.0]]),
                             np.array([0.5 * hinge.total_length, 0.0, 0.0]))


# Where the Euler-Bernoulli/Saint-Venant closed forms stop describing the solid hinge,
# from FEM runs with the deterministic mapped mesh (3 quadratic tets through the neck,
# ``compare_hinge(..., mesher="mapped")``, docs/reliability.md); each profile's own range
# (the notch's t/R) is in its module of ``model.profiles``:
# - torsion rx/Mx assumes free warping, a hinge much longer than wide: FEM / closed form
#   0.24 at length/width 0.5 (leaf l 20, w 40 mm), 0.26 at 1 (notch R 5, b 10 mm), 0.81 at
#   2.5, 0.95 at 10 (leaf l 400, w 40 mm): the blocks restrain the warping.
TORSION_MIN_LENGTH_OVER_WIDTH = 10.0


def closed_form_range_warnings(hinge, *, torsion: bool = True) -> list[str]:
    """Where the closed forms leave their range for this hinge: one sentence per
    problem, naming the parameter, its value and the range (empty: within range).
    ``torsion=False`` leaves out the torsion note, which holds for most practical (short,
    wide) hinges."""
    out = list(closed_form_of(hinge).range_warnings(hinge))
    length = hinge.length
    slenderness = length / hinge.width
    if torsion and slenderness < TORSION_MIN_LENGTH_OVER_WIDTH:
        out.append(f"hinge length {length * 1e3:.4g} mm over width {hinge.width * 1e3:.4g} mm is "
                   f"{slenderness:.3g}: the torsion closed form C_rx,Mx holds for length/width >= "
                   f"{TORSION_MIN_LENGTH_OVER_WIDTH:g}; below, the solid is stiffer in torsion (0.26x at 1)")
    return out
