"""FEM chain segments for the structural checks: Guyan stiffness and mass, and the stress
fields of unit node motions, cached.

Each canonical segment (``flexcal.validation.prototype.fem_provider.canonical_segment``:
a slice in a chain's second half is the mirror image of one in its first) is meshed with
quadratic tets and reduced onto its two section nodes with
``flexcal.fem.guyan.guyan_reduce_part``: stiffness and consistent mass (12 x 12, chain
axes) and, for each of the 12 unit node motions, the nodal Cauchy stress
(``flexcal.fem.results.nodal_stress``, float32 to keep the cache entry at ~12 x 6 x 4
bytes per node). Two meshers (``MESHERS``): "mapped" (default; the prototype's
deterministic multi-block mesher ``flexcal.fem.mesh_mapped_chain``, from the segment's
parameters, 6 cells through the thinnest leaf's neck) and "tetwild" (fTetWild on the
CadQuery solid, ``flexcal.fem.mesh.mesh_part``, 2 tets through). Stored with
``flexcal.fem.cache.cached`` under a key of the segment, material and mesh setting, so a
segment is built once; ``FemSegments.prepare`` builds the missing ones side by side on
threads of this process (as the prototype's ``fem_provider``).

The stress at a prototype state follows by linearity from the segment's deformation
twist xi (``superelement.segment_deformation``): node motions u = (0, xi) (start node
held, end node moved by xi in its own axes), mapped onto the canonical segment for a
mirrored one. Von Mises is invariant under the mirror's rotation.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from typing import Any, Iterable

import numpy as np

from flexcal.geometry.params import STEEL, ChainSegment, FlexureChain, Material

from ..prototype.fem_provider import _TURN_Z, canonical_segment
from ..prototype.mechanism import N_CHAINS, N_SEGMENTS, Prototype, frame_stiffness
from ..prototype.superelement import relative_pose, segment_deformation

__all__ = ["DEFAULT_ELEMENTS_THROUGH", "DEFAULT_MESHER", "MESHERS", "REFINE_STEP", "segment_structure", "mirror_map",
           "FemSegments", "chain_peak_stress_fem", "stress_twists",
           "peak_von_mises_of", "von_mises_quadratic_form", "VON_MISES_FORM"]

MESHERS = ("mapped", "tetwild")
DEFAULT_MESHER = "mapped"
DEFAULT_ELEMENTS_THROUGH = {"mapped": 6.0, "tetwild": 2.0}
"""Cells through the thinnest leaf by mesher. mapped: 6 cells through the neck, the
prototype's default (docs/meshing.md: the D-chain leaf segments' dominant stiffness
entries within 0.51 % of their Richardson limit, the L chain's within 1.1 %); on the
mount's figures n = 6 is 0.07-0.11 % stiffer than n = 8, i.e. ~0.2-0.3 % above the
converged support stiffness at the segments' rate 2 (<= 0.7 % with the slowest rate fitted
to n = 4, 6, 8), the payload modes within 0.13 % (docs/structure.md, "Mapped segments:
mesh density"). tetwild: 2 quadratic tets through
the leaf, ~1 % of the converged compliance (docs/meshing.md), half the DOFs of 3."""
REFINE_STEP = {"mapped": 2.0, "tetwild": 1.0}
"""One refinement (``--refine``): mapped 6 -> 8 cells through the neck (every cell of the
segment 3/4 the size: the convergence ladder 4, 6, 8 of docs/meshing.md); tetwild one tet
more through the leaf."""


def mirror_map() -> np.ndarray:
    """P (12, 12): a mirrored segment's node motions u give the canonical segment's
    P^T u (its matrices are P K P^T; ``fem_provider.mirror_segment_stiffness``)."""
    T = np.kron(np.eye(4), _TURN_Z)
    swap = np.block([[np.zeros((6, 6)), np.eye(6)], [np.eye(6), np.zeros((6, 6))]])
    return swap @ T


def _check_mesher(mesher: str) -> None:
    if mesher not in MESHERS:
        raise ValueError(f"mesher={mesher!r} must be one of {', '.join(MESHERS)}")


def _mesh(segment: ChainSegment, elements_through: float, mesher: str, threads: int):
    """(mesh, end planes, reference points) of the segment."""
    if mesher == "mapped":
        from flexcal.fem.mesh_mapped_chain import FAST_CHAIN_OPTIONS, mapped_mesh_chain
        from flexcal.geometry.exact import end_planes, reference_points

        mesh, _ = mapped_mesh_chain(segment, elements_through_thickness=elements_through, measure=False,
                                    **FAST_CHAIN_OPTIONS)  # session 13's grid (docs/structure.md figures)
        return mesh, end_planes(segment), reference_points(segment)
    from flexcal.fem.mesh import mesh_part
    from flexcal.geometry.solids import segment_solid

    from ..prototype.fem_provider import _CAD_LOCK

    with _CAD_LOCK:  # CadQuery's dispatch is not safe for two threads at once (fem_provider)
        part = segment_solid(segment)
    mesh, _ = mesh_part(part, elements_through_thickness=elements_through, num_threads=threads)
    return mesh, part.end_planes, part.reference_points


def _compute(segment: ChainSegment, material: Material, elements_through: float, mesher: str,
             threads: int = 0) -> dict[str, np.ndarray]:
    from flexcal.fem.guyan import guyan_reduce_part
    from flexcal.fem.results import nodal_stress

    start = time.perf_counter()
    mesh, planes, points = _mesh(segment, elements_through, mesher, threads)
    reduced = guyan_reduce_part(mesh, material, planes["A"], points["A"], planes["B"], points["B"])
    fields = reduced.solution.unit_motion_fields
    stress = np.stack([nodal_stress(mesh, material, fields[k]) for k in range(12)]).astype(np.float32)
    return {"stiffness": 0.5 * (reduced.stiffness + reduced.stiffness.T), "mass": reduced.mass,
            "unit_stress": stress, "nodes": np.asarray(mesh.nodes, float), "n_dof": np.array(3 * len(mesh.nodes)),
            "total_mass": np.array(reduced.total_mass), "wall_s": np.array(time.perf_counter() - start)}


# the modules of flexcal.validation whose code computes a structure segment's cache entry (its key's
# "code", as ``prototype.fem_provider.SEGMENT_CODE``; fem_provider lends fTetWild's CAD lock)
STRUCTURE_SEGMENT_CODE = ("flexcal.validation.structure.fem_segments", "flexcal.validation.prototype.fem_provider")


def _parts(segment: ChainSegment, material: Material, elements_through: float, mesher: str) -> dict[str, Any]:
    """The cache key's parts. "layout" 2: the entries hold the mesh nodes too (where a peak
    stress sits); "code": the sources of ``STRUCTURE_SEGMENT_CODE``; tetwild's mesh entry has
    no "mesher" (as before the mapped mesher came)."""
    from flexcal.fem.cache import sources_digest

    mesh: dict[str, Any] = {"elements_through_thickness": float(elements_through)}
    if mesher != "tetwild":
        from flexcal.fem.mesh_mapped_chain import FAST_CHAIN_OPTIONS

        mesh = {"mesher": mesher, **mesh, "options": FAST_CHAIN_OPTIONS}
    return {"kind": "structure_segment", "code": sources_digest(*STRUCTURE_SEGMENT_CODE), "layout": 2,
            "segment": segment, "material": material, "mesh": mesh}


def _canonical(chain: FlexureChain, x_start: float, x_end: float) -> tuple[ChainSegment, bool]:
    # the chain's length to 1 pm, like the cuts: L1-L3 are the same chain but their lengths,
    # |B - A| of rotated points, differ in the last bits, which would give three cache keys
    chain = dataclasses.replace(chain, length=round(chain.length, 12))
    return canonical_segment(chain, x_start, x_end)


def segment_structure(chain: FlexureChain, x_start: float, x_end: float, material: Material = STEEL, *,
                      elements_through: float | None = None, mesher: str = DEFAULT_MESHER, cache_directory=None,
                      threads: int = 0) -> tuple[dict[str, np.ndarray], bool]:
    """(arrays of the canonical segment, mirrored?) for the slice [x_start, x_end] [m]:
    "stiffness", "mass" (12, 12), "unit_stress" (12, n_nodes, 6) [Pa per unit motion] and
    "nodes" (n_nodes, 3) [m] (chain axes, x from the chain's end A) of the canonical
    segment (module docstring); built or read from the cache. elements_through: None for
    the mesher's default (``DEFAULT_ELEMENTS_THROUGH``); threads: fTetWild's (0: all
    cores; not in the key)."""
    from flexcal.fem.cache import cached

    _check_mesher(mesher)
    n = float(elements_through if elements_through is not None else DEFAULT_ELEMENTS_THROUGH[mesher])
    segment, mirrored = _canonical(chain, x_start, x_end)
    return cached(_parts(segment, material, n, mesher), lambda: _compute(segment, material, n, mesher, threads),
                  cache_directory), mirrored


def _build_job(segment: ChainSegment, *, material: Material, elements_through: float, mesher: str, cache_directory,
               cores: int) -> dict[str, Any]:
    """One segment build on a job thread owning ``cores`` cores (PARDISO and fTetWild)."""
    import contextlib

    from flexcal.fem.solve import solver_threads

    start = time.perf_counter()
    with solver_threads(cores) if cores else contextlib.nullcontext():
        arrays, _ = segment_structure(segment.chain, segment.x_start, segment.x_end, material,
                                      elements_through=elements_through, mesher=mesher,
                                      cache_directory=cache_directory, threads=cores)
    return {"n_dof": int(arrays["n_dof"]), "wall_s": time.perf_counter() - start}


class FemSegments:
    """The FEM segments of a mechanism's chains, as a stiffness provider for
    ``build_prototype`` (``provider(chain, x_start, x_end) -> (12, 12)``, with a
    ``prepare(slices)`` hook that builds the missing segments side by side) and as a
    source of segment masses and stresses. mesher: "mapped" or "tetwild" (``MESHERS``);
    elements_through: None for the mesher's default (``DEFAULT_ELEMENTS_THROUGH``);
    workers: build threads for ``prepare`` (None: one per usable core, at most one per
    missing segment and per ``BUILD_MEMORY_BYTES`` of free memory; 0: one after the
    other, as asked for); ``progress``: print one line per segment built (stderr)."""

    def __init__(self, material: Material = STEEL, *, elements_through: float | None = None,
                 mesher: str = DEFAULT_MESHER, cache_directory=None, progress: bool = False, workers: int | None = None):
        _check_mesher(mesher)
        self.material, self.mesher = material, mesher
        self.elements_through = float(elements_through if elements_through is not None
                                      else DEFAULT_ELEMENTS_THROUGH[mesher])
        self.cache_directory, self.progress, self.workers = cache_directory, progress, workers
        self.description = (f"FEM segments (Guyan K and M), {mesher} mesh, {self.elements_through:g} elements through "
                            "the thinnest leaf")
        self._memo: dict = {}  # slice -> (arrays, mirrored): asked for at every state
        self._arrays: dict = {}  # canonical segment -> its arrays
        self._flat: dict = {}  # canonical segment -> (unit stress float64, its von Mises forms), once

    def refined(self) -> "FemSegments":
        """The same segments one mesh refinement finer (``REFINE_STEP``)."""
        return FemSegments(self.material, elements_through=self.elements_through + REFINE_STEP[self.mesher],
                           mesher=self.mesher, cache_directory=self.cache_directory, progress=self.progress,
                           workers=self.workers)

    def _log(self, text: str) -> None:
        if self.progress:
            print(text, file=sys.stderr, flush=True)

    def prepare(self, slices: Iterable[tuple[FlexureChain, float, float]]) -> int:
        """Build the segments of ``slices`` [(chain, x_start [m], x_end [m])] that the cache
        lacks, on job threads of this process, longest first; returns how many were built."""
        import psutil

        from flexcal.fem.cache import cache_key, load_cached

        from ..executor import run_jobs, usable_cores, where
        from ..prototype.fem_provider import plan_local_builds, segment_build_cost

        if self.workers == 0:
            return 0  # built lazily, one after the other, by the calls that follow
        missing: dict[str, ChainSegment] = {}
        for chain, x_start, x_end in slices:
            segment, _ = _canonical(chain, float(x_start), float(x_end))
            key = cache_key(_parts(segment, self.material, self.elements_through, self.mesher))
            if key not in missing and load_cached(key, self.cache_directory) is None:
                missing[key] = segment
        if not missing:
            return 0
        threads, cores = plan_local_builds(self.workers, len(missing), cores=usable_cores(),
                                           available_bytes=psutil.virtual_memory().available)
        self._log(f"  FEM segments: {len(missing)} to build on {where(threads, None, True)}")
        start, names = time.perf_counter(), {id(s): k[:16] for k, s in missing.items()}
        built: list[str] = []

        def on_done(segment: ChainSegment, result: dict[str, Any]) -> None:
            built.append(names[id(segment)])
            self._log(f"  segment [{segment.x_start * 1e3:.4g}, {segment.x_end * 1e3:.4g}] mm of a "
                      f"{segment.chain.length * 1e3:.4g} mm chain: {result['n_dof']} DOF, {result['wall_s']:.1f} s "
                      f"({len(built)}/{len(missing)}, {time.perf_counter() - start:.0f} s elapsed)")

        options = {"material": self.material, "elements_through": self.elements_through, "mesher": self.mesher,
                   "cache_directory": self.cache_directory, "cores": cores}
        ordered = sorted(missing.values(), key=segment_build_cost, reverse=True)  # longest first
        failures = run_jobs(ordered, _build_job, on_done, key=lambda s: names[id(s)], workers=threads,
                            job_options=options, task_prefix="structure-segment", in_threads=threads > 0)
        if failures:
            text = next(iter(failures.values()))
            raise RuntimeError(f"{len(failures)} FEM segment build(s) failed, e.g. {text}; the {len(built)} finished "
                               "segment(s) are cached, run the same command again to retry")
        return len(built)

    def _get(self, chain: FlexureChain, x_start: float, x_end: float):
        key = (chain, float(x_start), float(x_end))
        if key not in self._memo:
            segment, mirrored = _canonical(chain, float(x_start), float(x_end))
            if segment not in self._arrays:  # read once for a segment and its mirror image
                start = time.perf_counter()
                arrays, _ = segment_structure(chain, x_start, x_end, self.material,
                                              elements_through=self.elements_through, mesher=self.mesher,
                                              cache_directory=self.cache_directory)
                if time.perf_counter() - start > 1.0:
                    self._log(f"  segment [{x_start * 1e3:.4g}, {x_end * 1e3:.4g}] mm of a {chain.length * 1e3:.4g} "
                              f"mm chain: {int(arrays['n_dof'])} DOF, {time.perf_counter() - start:.1f} s")
                self._arrays[segment] = arrays
            self._memo[key] = (self._arrays[segment], mirrored)
        return self._memo[key]

    def _unit_stress(self, chain: FlexureChain, x_start: float, x_end: float):
        """(unit stress (12, n_nodes, 6) float64 [Pa per unit motion], form_of(h) -> the
        von Mises form of node h's motions (``von_mises_quadratic_form``)) of the slice's
        canonical segment, each computed once (a segment and its mirror image share them)."""
        key = _canonical(chain, float(x_start), float(x_end))[0]
        if key not in self._flat:
            unit = np.asarray(self._get(chain, x_start, x_end)[0]["unit_stress"], float)
            forms: dict[int, np.ndarray] = {}

            def form_of(h: int) -> np.ndarray:
                if h not in forms:
                    forms[h] = von_mises_quadratic_form(unit[6 * h:6 * h + 6])
                return forms[h]

            self._flat[key] = (unit, form_of)
        return self._flat[key]

    def _matrix(self, name: str, chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        arrays, mirrored = self._get(chain, x_start, x_end)
        P = mirror_map()
        return P @ arrays[name] @ P.T if mirrored else np.array(arrays[name])

    def __call__(self, chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        return self._matrix("stiffness", chain, x_start, x_end)

    def mass(self, chain: FlexureChain, x_start: float, x_end: float) -> np.ndarray:
        """Guyan mass (12, 12) [kg, kg m, kg m^2] of the slice, chain axes."""
        return self._matrix("mass", chain, x_start, x_end)

    def peak_von_mises(self, chain: FlexureChain, x_start: float, x_end: float, motion: np.ndarray) -> float:
        """Largest nodal von Mises stress [Pa] of the slice under node motions (12,) [m, rad]."""
        return self.peak_von_mises_at(chain, x_start, x_end, motion)[0]

    def peak_von_mises_at(self, chain: FlexureChain, x_start: float, x_end: float, motion: np.ndarray
                          ) -> tuple[float, np.ndarray]:
        """(largest nodal von Mises stress [Pa], where (3,) [m]: that node in chain axes)
        of the slice under node motions (12,) [m, rad]; a mirrored slice's node is turned
        back into place (x -> L - x, y -> -y)."""
        arrays, mirrored = self._get(chain, x_start, x_end)
        u = mirror_map().T @ motion if mirrored else np.asarray(motion, float)
        unit, form_of = self._unit_stress(chain, x_start, x_end)
        value, k = peak_von_mises_of(unit, u, form_of)
        where = np.array(arrays["nodes"][k], float)
        if mirrored:
            where = _TURN_Z @ where + np.array([chain.length, 0.0, 0.0])
        return value, where


# von Mises squared as a quadratic form of the Voigt stress (xx, yy, zz, yz, xz, xy):
# sxx^2 + syy^2 + szz^2 - sxx syy - syy szz - szz sxx + 3 (syz^2 + sxz^2 + sxy^2)
VON_MISES_FORM = np.block([[np.full((3, 3), -0.5) + 1.5 * np.eye(3), np.zeros((3, 3))],
                           [np.zeros((3, 3)), 3.0 * np.eye(3)]])
_UPPER = np.triu_indices(6)


def von_mises_quadratic_form(unit_stress: np.ndarray) -> np.ndarray:
    """Q (n_nodes, 21) [Pa^2 per unit^2] of the stresses (6, n_nodes, 6) of one node's six
    unit motions: the von Mises stress at each node under motions v (6,) is
    sqrt(Q @ w), w the products v_i v_j (i <= j, row-major ``np.triu_indices``)."""
    S = np.asarray(unit_stress, float)
    full = np.einsum("kna,ab,lnb->nkl", S, VON_MISES_FORM, S)
    return full[:, _UPPER[0], _UPPER[1]] * np.where(_UPPER[0] == _UPPER[1], 1.0, 2.0)


def peak_von_mises_of(unit_stress: np.ndarray, motion: np.ndarray, form_of=None) -> tuple[float, int]:
    """(largest nodal von Mises stress [Pa], its node) under node motions (12,) [m, rad],
    for the stresses (12, n_nodes, 6) of the 12 unit motions [Pa per unit].

    A segment's motions at a prototype state move one of its nodes only (``(0, xi)``,
    or ``(xi', 0)`` mirrored): then the node is found from von Mises squared as a
    quadratic form of that node's six motions (``von_mises_quadratic_form``: 21 numbers a
    node against the whole field's 72, the product that dominated a warm run), and the
    value is the stress at that node (``flexcal.fem.results.von_mises``). ``form_of(h)``
    gives Q of the unit motions 6h..6h+5 (cached by the caller; None: computed here).
    Motions of both nodes take the whole field. The node is the whole field's argmax
    unless two nodes' peaks agree to round-off (~1e-13)."""
    from flexcal.fem.results import von_mises

    u = np.asarray(motion, float)
    moving = [h for h in (0, 1) if np.any(u[6 * h:6 * h + 6])]
    if len(moving) != 1:
        values = von_mises(np.einsum("k,kni->ni", u, unit_stress))
        k = int(np.argmax(values))
        return float(values[k]), k
    h = moving[0]
    v = u[6 * h:6 * h + 6]
    Q = form_of(h) if form_of is not None else von_mises_quadratic_form(unit_stress[6 * h:6 * h + 6])
    k = int(np.argmax(Q @ np.outer(v, v)[_UPPER]))
    return float(von_mises(v @ unit_stress[6 * h:6 * h + 6, k])), k


def stress_twists(prototype: Prototype, poses: np.ndarray, segments: FemSegments) -> np.ndarray:
    """(6, 5, 6) [m, rad]: the end-node motion of each of ``segments``' slices (start held) whose
    stress field is the segment's at body ``poses``: its deformation twist xi
    (``superelement.segment_deformation``); with tied cuts (``Prototype.chain_stiffness``) the
    twist under which the slice carries the segment's share of its chain's wrench, K_jj^-1
    (K_chain Xi)_s, K_jj the slice's own (its cuts held rigid, as its stress fields are): away
    from the cuts, where the leaves are, the field of the same load (Saint-Venant)."""
    from ..prototype.equilibrium import node_poses

    a = prototype.assembly
    nodes = node_poses(a, poses)
    rel = relative_pose(nodes[a.segment_nodes[:, 0]], nodes[a.segment_nodes[:, 1]])
    xi = segment_deformation(rel, a.segment_reference_inverse)
    if prototype.chain_stiffness is None:
        return xi.reshape(N_CHAINS, N_SEGMENTS, 6)
    wrench = frame_stiffness(prototype, prototype.segment_stiffness).wrench(xi).reshape(N_CHAINS, N_SEGMENTS, 6)
    out = np.zeros((N_CHAINS, N_SEGMENTS, 6))
    for c, placement in enumerate(prototype.mechanism.chains):
        xs = prototype.section_x[c]
        for s in range(N_SEGMENTS):
            own = segments(placement.chain, float(xs[s]), float(xs[s + 1]))[6:, 6:]
            out[c, s] = np.linalg.solve(own, wrench[c, s])
    return out


def chain_peak_stress_fem(prototype: Prototype, poses: np.ndarray, segments: FemSegments) -> np.ndarray:
    """Peak nodal von Mises stress (6,) [Pa] of each chain at body ``poses`` (FEM
    segments; module docstring; ``stress_twists``)."""
    xi = stress_twists(prototype, poses, segments)
    out = np.zeros(N_CHAINS)
    for c, placement in enumerate(prototype.mechanism.chains):
        xs = prototype.section_x[c]
        for s in range(N_SEGMENTS):
            motion = np.r_[np.zeros(6), xi[c, s]]
            out[c] = max(out[c], segments.peak_von_mises(placement.chain, xs[s], xs[s + 1], motion))
    return out
