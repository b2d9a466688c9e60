"""The mapped hinge mesher's converged compliance against an independent reference (issue 26,
"Verification"; docs/hinge-verification.md, "Independent reference (session 17)").

Circular notch hinges R 5 mm, b 10 mm, blocks 5 mm, t given. Mapped: ``mapped_mesh_part``'s
own steps on its grid at ``mapped_base`` cells through with every cell split into r^3
(``nested_mapped_mesh``: nested levels, h = 1 / r), condensed by ``flexcal.fem.condense``.
Reference: 27-node hexahedra (``flexcal.fem.reference_hex``: another element family, its own
grid, geometry, assembly and end conditions) at ``ref_base`` cells through, refinement r.
``richardson`` fits rate and limit over three levels of each. The reference's uncertainty:
with four levels, the difference between the limits of the finest three and of the
coarsest three; with three, half the spread of the two-level limits at rates p -+ 1.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

__all__ = ["AGREEMENT", "notch", "nested_mapped_mesh", "mapped_compliance", "default_compliance",
           "reference_compliance", "reference_limit", "compare"]

NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")
LOADS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
AGREEMENT = 1e-3
"""The issue's agreement: |mapped limit - reference limit| <= 0.1 % of the reference."""


def notch(thickness_mm: float):
    from flexcal.geometry.profiles.circular import CircularNotchHinge

    return CircularNotchHinge(radius=5e-3, thickness=thickness_mm * 1e-3, width=10e-3, block_length=5e-3)


def nested_mapped_mesh(hinge, n_base: int, refinement: int):
    """The mapped mesher's mesh (``flexcal.fem.mesh_mapped.mapped_mesh_part``'s steps: grid,
    y scaled by the local height, ``snap_to_part``, isoparametric mid-nodes) on its grid at
    ``n_base`` through with every cell split into refinement^3 (nested levels, h = 1 / r)."""
    from flexcal.fem.mesh_mapped import hinge_outline, isoparametric_mesh, mapped_grid
    from flexcal.fem.mesh_snap import snap_to_part
    from flexcal.fem.structured import grid_tet_mesh

    r = int(refinement)
    lines = []
    for axis in mapped_grid(hinge, n_base):
        a, b = axis[:-1, None], axis[1:, None]
        lines.append(np.append((a + (b - a) * np.arange(r)[None, :] / r).ravel(), axis[-1]))
    outline = hinge_outline(hinge)
    grid = grid_tet_mesh(*lines)
    used, tets4 = np.unique(grid.tets[:, :4], return_inverse=True)
    nodes = grid.nodes[used].copy()
    nodes[:, 1] *= outline.height(nodes[:, 0])
    tolerance = 0.3 * outline.neck_thickness / (n_base * r)  # as mapped_mesh_part: 0.3 of a neck cell
    snapped, _ = snap_to_part(hinge, nodes, tets4.reshape(-1, 4), tolerance=tolerance, project=True, morph=False)
    mesh, _ = isoparametric_mesh(snapped, outline.height)
    return mesh


def mapped_compliance(hinge, n_base: int, refinement: int) -> tuple[np.ndarray, int]:
    from flexcal.fem.condense import hinge_compliance
    from flexcal.geometry.exact import end_planes
    from flexcal.geometry.params import STEEL

    mesh = nested_mapped_mesh(hinge, n_base, refinement)
    planes = end_planes(hinge)
    return hinge_compliance(mesh, STEEL, planes["fixed"], planes["free"], planes["free"][0]), mesh.n_dof


def default_compliance(hinge, elements_through: float) -> tuple[np.ndarray, int]:
    """The compliance ``flexcal hinge`` computes (``mapped_mesh_part`` at ``elements_through``;
    its default is ``DEFAULT_CONFIG`` of ``flexcal.validation.cli.hinge``, which the benchmark
    passes: numerics do not import the command line)."""
    from flexcal.fem.condense import hinge_compliance
    from flexcal.fem.mesh_mapped import mapped_mesh_part
    from flexcal.geometry.exact import end_planes
    from flexcal.geometry.params import STEEL
    from flexcal.geometry.solids import hinge_solid

    mesh, _ = mapped_mesh_part(hinge_solid(hinge), elements_through_thickness=elements_through)
    planes = end_planes(hinge)
    return hinge_compliance(mesh, STEEL, planes["fixed"], planes["free"], planes["free"][0]), mesh.n_dof


def reference_compliance(hinge, n_base: int, refinement: int, width_cells: int | None = None
                         ) -> tuple[np.ndarray, int]:
    from flexcal.fem.reference_hex import hex27_hinge_compliance

    return hex27_hinge_compliance(hinge, n_through=n_base, refinement=refinement, aspect=2.0,
                                  width_cells=width_cells)


def _rate_spread(h, values, rate) -> np.ndarray:
    """Half the spread of the finest two levels' limits at rates p -+ 1 (p >= 0.5; p = 2 where
    the three levels gave no rate)."""
    p = np.where(np.isfinite(rate), rate, 2.0)
    ratio = h[-2] / h[-1]
    low = values[-1] + (values[-1] - values[-2]) / (ratio ** np.maximum(p - 1.0, 0.5) - 1.0)
    high = values[-1] + (values[-1] - values[-2]) / (ratio ** (p + 1.0) - 1.0)
    return 0.5 * np.abs(low - high)


def reference_limit(levels, values) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rate, limit, uncertainty, rate spread) of the reference levels: the limit of the
    finest three; the uncertainty is the difference from the limit of the three before them
    (four levels or more) or else the rate spread (``_rate_spread``), which is also returned."""
    from flexcal.fem.convergence import richardson

    h = 1.0 / np.asarray(levels, float)
    fine = richardson(h[-3:], values[-3:])
    spread = _rate_spread(h, values, fine.rate)
    if len(levels) >= 4:
        coarse = richardson(h[-4:-1], values[-4:-1])
        return fine.rate, fine.limit, np.abs(fine.limit - coarse.limit), spread
    return fine.rate, fine.limit, spread, spread


# the modules of flexcal.validation whose code computes a level of these studies (this one's,
# ``chain_reference``'s and the prototype's segments they compare): with flexcal.fem and
# flexcal.geometry (``flexcal.fem.cache.code_version``) the version each stored level keeps
LEVEL_CODE = ("flexcal.validation.reports.hinge_reference", "flexcal.validation.reports.chain_reference",
              "flexcal.validation.reports.chain_cuts", "flexcal.validation.prototype.tied_chains",
              "flexcal.validation.prototype.cut_fields", "flexcal.validation.prototype.fem_provider",
              "flexcal.validation.prototype.segments")


def _level_version() -> str:
    from flexcal.fem.cache import code_version, sources_digest

    return f"{code_version()}+{sources_digest(*LEVEL_CODE)}"


def _cached(folder: Path | None, tag: str, compute) -> np.ndarray:
    """compute() -> (array, DOF), stored as folder/<tag>.npz with the code version that computed it
    (``_level_version``) and reused while that is this code's; a level of other code (a study
    resumed in the same folder after an edit) is computed again, not mixed in. No folder: computed."""
    from flexcal.geometry.atomic import atomic_path

    if folder is None:
        return compute()[0]
    path, version = folder / f"{tag}.npz", _level_version()
    if path.exists():
        with np.load(path) as stored:
            if str(stored["code_version"]) == version:
                return stored["value"]
        print(f"{tag}: stored by other code ({path.name}), computed again", flush=True)
    cpu, wall = time.process_time(), time.perf_counter()
    c, dof = compute()
    with atomic_path(path) as temporary:
        with open(temporary, "wb") as handle:
            np.savez(handle, value=c, code_version=np.array(version))
    print(f"{tag}: {dof} DOF, {time.process_time() - cpu:.1f} s CPU, {time.perf_counter() - wall:.1f} s wall "
          f"(load {os.getloadavg()[0]:.1f})", flush=True)
    return np.asarray(c)


def compare(thickness_mm: float, folder: Path | None, mapped_base: int, mapped_levels, ref_base: int, ref_levels,
            default: float | None = None, ref_width: int | None = None):
    """Rows (entry, mapped rate, mapped limit, reference rate, reference limit, its
    uncertainty, (mapped limit - reference limit) / |reference limit|, (finest mapped -
    reference limit) / |reference limit|, and with ``default`` cells through (``flexcal hinge``'s mesh at that n -
    reference limit) / |reference limit| (else NaN)) for every dominant entry (``DOMINANT_FRACTION`` on
    the finest reference), and the reference's rate spread, of the upper triangle of the 6 x 6 compliance [SI]."""
    from flexcal.fem.convergence import dominant_entries, richardson
    from flexcal.validation.reports.fem import DOMINANT_FRACTION

    hinge = notch(thickness_mm)
    stem = f"notch_t{thickness_mm:g}"
    mapped = np.array([_cached(folder, f"mapped_{stem}_n{mapped_base}_r{r}",
                               lambda r=r: mapped_compliance(hinge, mapped_base, r)) for r in mapped_levels])
    width = "" if ref_width is None else f"_w{ref_width}"
    reference = np.array([_cached(folder, f"hex27_{stem}_n{ref_base}{width}_r{r}",
                                  lambda r=r: reference_compliance(hinge, ref_base, r, ref_width)) for r in ref_levels])
    dflt = None if default is None else _cached(folder, f"default{default:g}_{stem}",
                                                lambda: default_compliance(hinge, default))
    fit = richardson(1.0 / np.asarray(mapped_levels[-3:], float), mapped[-3:])
    ref_rate, ref_lim, ref_unc, ref_spread = reference_limit(ref_levels, reference)
    mask = np.triu(dominant_entries(reference[-1], DOMINANT_FRACTION))
    rows = []
    for i, j in zip(*np.nonzero(mask)):
        diff = (fit.limit[i, j] - ref_lim[i, j]) / abs(ref_lim[i, j])
        rows.append((f"{NAMES[i]}/{LOADS[j]}", fit.rate[i, j], fit.limit[i, j], ref_rate[i, j], ref_lim[i, j],
                     ref_unc[i, j], diff, (mapped[-1, i, j] - ref_lim[i, j]) / abs(ref_lim[i, j]),
                     np.nan if dflt is None else (dflt[i, j] - ref_lim[i, j]) / abs(ref_lim[i, j]),
                     ref_spread[i, j]))
    return rows


