"""Parameter types of flexure hinges, flexure chains and the reference mechanism.

Pure data: frozen dataclasses validated on construction, no CadQuery. Everything is
SI ([m], [Pa], [kg]); the command line converts from mm at the edge. The analytic model
(``flexcal.model``) imports these types and nothing else of ``geometry``.

Frames
------
Hinge frame: x along the hinge (from the fixed end to the free end), y across the
thin direction (thickness t), z along the width. The origin is the centre of the thin
section; the hinge spans x in [-length/2, +length/2] and the blocks extend beyond.

Chain frame: x along the strut from end A (base or actuator side, x = 0) to end B
(payload-frame side, x = L). Leaf 1 of each biaxial flexure is thin in local y (it
bends about local z); leaf 2 is the same leaf turned 90 deg about x (thin in local z,
bends about local y). The order from A to B is
``block | leaf1 | connector | leaf2 | strut | leaf2 | connector | leaf1 | block``
(mirror-symmetric about the strut's middle).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .checks import require, require_finite
from .frames import chain_rotation
from .profiles.circular import CircularNotchHinge
from .profiles.leaf import LeafHinge

__all__ = [
    "Material",
    "STEEL",
    "CircularNotchHinge",
    "LeafHinge",
    "FlexureChain",
    "ChainSegment",
    "ChainPlacement",
    "ErrorRanges",
    "MechanismParams",
    "reference_mechanism",
]


_require = require
_finite = require_finite


@dataclass(frozen=True, kw_only=True)
class Material:
    """Linear-elastic isotropic material.

    youngs_modulus [Pa], poisson_ratio [-], density [kg/m^3], yield_strength [Pa]
    (used only to judge stresses: ``flexcal structure``). Default yield: structural
    steel S355J2 (EN 10025-2), minimum upper yield strength R_eH = 335 MPa for products
    40-63 mm thick (the chains are cut from a 50 mm section; 355 MPa holds only up to
    16 mm). A flexure steel of higher strength (e.g. quenched and tempered 42CrMo4) is
    the usual choice; set its value here.
    """

    youngs_modulus: float = 206e9
    poisson_ratio: float = 0.29
    density: float = 7850.0
    yield_strength: float = 335e6

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            _finite(f.name, getattr(self, f.name))
        _require(self.youngs_modulus > 0, "youngs_modulus", self.youngs_modulus, "> 0 Pa", unit="Pa")
        _require(-1.0 < self.poisson_ratio < 0.5, "poisson_ratio", self.poisson_ratio, "in (-1, 0.5)", unit="")
        _require(self.density > 0, "density", self.density, "> 0 kg/m^3", unit="kg/m^3")
        _require(self.yield_strength > 0, "yield_strength", self.yield_strength, "> 0 Pa", unit="Pa")

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + nu)) [Pa]."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))


STEEL = Material()


@dataclass(frozen=True, kw_only=True)
class FlexureChain:
    """A strut with a biaxial flexure (two leaf hinges in series, the second turned 90 deg)
    at each end. See the module docstring for the layout and frame.

    length L [m]: distance between the end faces A and B; hinge_length l [m], width w [m],
    fillet a [m] of every leaf; thickness_1 t1 [m] (leaf thin in local y) and
    thickness_2 t2 [m] (leaf thin in local z); section [m]: side of the square cross-section
    of blocks, connectors and strut (>= w and >= t + 2a); connector_length [m] between
    the two leaves of a flexure; end_block_length [m] at each end.
    """

    length: float
    hinge_length: float = 0.020
    width: float = 0.040
    fillet: float = 0.006
    thickness_1: float = 0.004
    thickness_2: float = 0.004
    section: float = 0.050
    connector_length: float = 0.010
    end_block_length: float = 0.010

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            _finite(f.name, getattr(self, f.name))
        for name in ("length", "hinge_length", "width", "thickness_1", "thickness_2", "section",
                     "connector_length", "end_block_length"):
            _require(getattr(self, name) > 0, name, getattr(self, name), "> 0 mm")
        _require(self.fillet >= 0, "fillet", self.fillet, ">= 0 mm")
        _require(2 * self.fillet <= self.hinge_length, "fillet", self.fillet,
                 f"<= hinge_length/2 = {self.hinge_length * 500:.6g} mm (both fillets must fit the segment)")
        _require(self.section >= self.width - 1e-12, "section", self.section,
                 f">= width = {self.width * 1e3:.6g} mm")
        for name in ("thickness_1", "thickness_2"):
            t = getattr(self, name)
            _require(t + 2 * self.fillet <= self.section + 1e-12, name, t,
                     f"<= section - 2*fillet = {(self.section - 2 * self.fillet) * 1e3:.6g} mm")
        _require(self.strut_length > 0, "length", self.length,
                 f"> 2*end_block + 4*hinge_length + 2*connector = {self.minimum_length * 1e3:.6g} mm")

    @property
    def minimum_length(self) -> float:
        return 2 * self.end_block_length + 4 * self.hinge_length + 2 * self.connector_length

    @property
    def strut_length(self) -> float:
        """Length of the rigid-ish strut between the two biaxial flexures [m]."""
        return self.length - self.minimum_length

    def leaf(self, which: int) -> LeafHinge:
        """Leaf hinge 1 (thin in y) or 2 (thin in z), as a stand-alone ``LeafHinge``."""
        if which not in (1, 2):
            raise ValueError(f"leaf index {which!r} must be 1 or 2")
        return LeafHinge(
            length=self.hinge_length,
            thickness=self.thickness_1 if which == 1 else self.thickness_2,
            width=self.width,
            fillet=self.fillet,
            block_length=self.connector_length,
            block_height=self.section,
        )

    def segments(self) -> tuple[tuple[str, float, float], ...]:
        """The segments from A to B as ``(kind, x_start, x_end)`` [m], kind in
        {"block", "leaf1", "leaf2", "connector", "strut"}."""
        e, l, c, s = self.end_block_length, self.hinge_length, self.connector_length, self.strut_length
        kinds_lengths = [("block", e), ("leaf1", l), ("connector", c), ("leaf2", l), ("strut", s),
                         ("leaf2", l), ("connector", c), ("leaf1", l), ("block", e)]
        out, x = [], 0.0
        for kind, length in kinds_lengths:
            out.append((kind, x, x + length))
            x += length
        return tuple(out)

    @property
    def pivot_distance(self) -> float:
        """L_d of paper Eq. 4: distance between the centres of the two biaxial flexures [m]."""
        return self.length - 2 * self.end_block_length - 2 * self.hinge_length - self.connector_length


@dataclass(frozen=True, kw_only=True)
class ChainSegment:
    """The part of a ``FlexureChain`` between two cross-sections x_start < x_end [m]
    (chain frame). The cuts must lie in rigid segments (end blocks, connectors, strut),
    never inside a leaf, so every segment is a hinge between two blocks. Its end faces are
    named "A" (at x_start) and "B" (at x_end), like a chain's. The virtual prototype
    condenses each segment to a 12 x 12 superelement (docs/prototype.md).
    """

    chain: FlexureChain
    x_start: float
    x_end: float

    def __post_init__(self) -> None:
        _finite("x_start", self.x_start)
        _finite("x_end", self.x_end)
        length = self.chain.length
        _require(0.0 <= self.x_start < self.x_end, "x_start", self.x_start, f">= 0 and < x_end = {self.x_end * 1e3:.6g} mm")
        _require(self.x_end <= length + 1e-12, "x_end", self.x_end, f"<= chain length = {length * 1e3:.6g} mm")
        for name, x in (("x_start", self.x_start), ("x_end", self.x_end)):
            for kind, a, b in self.chain.segments():
                if kind.startswith("leaf") and a + 1e-12 < x < b - 1e-12:
                    raise ValueError(f"{name}={x * 1e3:.6g} mm cuts through a leaf ({a * 1e3:.6g}-{b * 1e3:.6g} mm); "
                                     f"cut in a block, connector or the strut")

    @property
    def length(self) -> float:
        return self.x_end - self.x_start

    def segments(self) -> tuple[tuple[str, float, float], ...]:
        """The chain's segments clipped to [x_start, x_end], empty ones dropped."""
        out = []
        for kind, a, b in self.chain.segments():
            a, b = max(a, self.x_start), min(b, self.x_end)
            if b - a > 1e-12:
                out.append((kind, a, b))
        return tuple(out)


@dataclass(frozen=True, kw_only=True)
class ChainPlacement:
    """One chain of the mechanism: its geometry and where its two ends sit.

    name: "L1".."L3" (load chains, base end fixed) or "D1".."D3" (driving chains, end A
    on an actuator that moves along the chain axis). point_a, point_b [m] in the
    mechanism frame (origin O_C); roll_reference: a vector fixing local y (see
    ``chain_rotation``). The chain's length is |point_b - point_a|; ``chain.length`` must
    agree to 1 um.
    """

    name: str
    chain: FlexureChain
    point_a: tuple[float, float, float]
    point_b: tuple[float, float, float]
    roll_reference: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if not (self.name[:1] in ("L", "D") and self.name[1:].isdigit()):
            raise ValueError(f"chain name {self.name!r} must be L<n> (load) or D<n> (driving)")
        distance = float(np.linalg.norm(np.subtract(self.point_b, self.point_a)))
        _require(abs(distance - self.chain.length) <= 1e-6, f"{self.name}.chain.length", self.chain.length,
                 f"equal to |point_b - point_a| = {distance * 1e3:.6g} mm")

    @property
    def is_driving(self) -> bool:
        return self.name.startswith("D")

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) columns = local axes in the mechanism frame."""
        return chain_rotation(np.array(self.point_a), np.array(self.point_b), np.array(self.roll_reference))


def _load_chain(name: str, angle_deg: float, chain: FlexureChain | None = None) -> ChainPlacement:
    phi = math.radians(angle_deg)
    direction = np.array([0.0, math.cos(phi), math.sin(phi)])
    point_a = np.array([0.600, 0, 0]) + 0.300 * direction
    point_b = np.array([0.200, 0, 0]) + 0.100 * direction
    length = float(np.linalg.norm(point_b - point_a))
    chain = chain or FlexureChain(length=length)
    # local y tangential to the circle: bending about local z swings the strut radially
    tangent = np.array([0.0, -math.sin(phi), math.cos(phi)])
    return ChainPlacement(name=name, chain=dataclasses.replace(chain, length=length),
                          point_a=tuple(point_a), point_b=tuple(point_b), roll_reference=tuple(tangent))


def _default_chains() -> tuple[ChainPlacement, ...]:
    driving = FlexureChain(length=0.150, thickness_1=0.003, thickness_2=0.003)
    return (
        _load_chain("L1", 90.0),
        _load_chain("L2", 210.0),
        _load_chain("L3", 330.0),
        # D1/D2 sit in front of their frame points (actuator at x = 50 mm) so that the
        # payload's weight compresses them: see docs/model.md, "Reference mechanism".
        ChainPlacement(name="D1", chain=driving, point_a=(0.050, 0.600, -0.150), point_b=(0.200, 0.600, -0.150),
                       roll_reference=(0.0, 1.0, 0.0)),
        ChainPlacement(name="D2", chain=driving, point_a=(0.050, -0.600, -0.150), point_b=(0.200, -0.600, -0.150),
                       roll_reference=(0.0, 1.0, 0.0)),
        ChainPlacement(name="D3", chain=driving, point_a=(0.200, 0.600, 0.150), point_b=(0.200, 0.600, 0.0),
                       roll_reference=(1.0, 0.0, 0.0)),
    )


@dataclass(frozen=True, kw_only=True)
class ErrorRanges:
    """The ranges of the error sources (paper Sec. 3.1, Eq. 9; ``flexcal.model.parameters``).

    dimension_tolerance [-]: every leaf dimension (w, a, l, t1, t2) varies by +- this
    fraction of its nominal (paper: 10 %); offset_radius [m]: a load chain's base end A
    sits anywhere inside a circle of this radius (paper: 2 mm); hysteresis (low, high) [-]:
    range of the drives' hysteresis coefficient mu (paper: 0.75-1, nominal 1);
    clearance (low, high) [m]: range of the drives' equivalent clearance CL (paper: 0-0.5 mm,
    nominal 0); initial_position (low, high) [m]: range of the drives' unknown initial
    position x0 (nominal 0).
    """

    dimension_tolerance: float = 0.10
    offset_radius: float = 2e-3
    hysteresis: tuple[float, float] = (0.75, 1.0)
    clearance: tuple[float, float] = (0.0, 0.5e-3)
    initial_position: tuple[float, float] = (-0.5e-3, 0.5e-3)

    def __post_init__(self) -> None:
        _require(0 < self.dimension_tolerance < 1, "dimension_tolerance", self.dimension_tolerance, "in (0, 1)",
                 unit="")
        _require(self.offset_radius > 0, "offset_radius", self.offset_radius, "> 0 mm")
        for name, nominal, floor, ceiling in (("hysteresis", 1.0, 0.0, 1.0), ("clearance", 0.0, 0.0, math.inf),
                                              ("initial_position", 0.0, -math.inf, math.inf)):
            low, high = getattr(self, name)
            _finite(f"{name}[0]", low)
            _finite(f"{name}[1]", high)
            if not (floor <= low <= nominal <= high <= ceiling and low < high):
                raise ValueError(f"{name} range ({low:.6g}, {high:.6g}) must hold its nominal {nominal:g} with "
                                 f"low < high, inside [{floor:g}, {ceiling:g}] (SI)")


@dataclass(frozen=True, kw_only=True)
class MechanismParams:
    """The six-chain remote-centre mount of DESIGN.md.

    chains: six ``ChainPlacement`` (L1-L3 then D1-D3); payload_mass [kg];
    centre_of_gravity [m] in the mechanism frame; gravity [m/s^2] vector;
    material; actuator_stiffness [N/m]: axial stiffness of ball screw + coupling in
    series with each driving chain; payload_box (x, y, z) [m]: the box the payload fills
    (its inertia about the centre of gravity, unless payload_inertia gives the principal
    moments (Ixx, Iyy, Izz) [kg m^2] along the mechanism axes); payload_box_centre [m]:
    where the box sits in the mechanism frame (for the collision check and pictures only;
    None: not placed, the chains are not checked against it); actuator_half_stroke [m]:
    travel of each actuator either side of its zero; workspace (theta_x, theta_y, theta_z)
    [rad]: half-ranges of the pose (paper Sec. 4.2); errors: the error sources' ranges.
    A mount file (``flexcal.geometry.mount``) holds all of it in display units.
    """

    chains: tuple[ChainPlacement, ...] = field(default_factory=_default_chains)
    payload_mass: float = 300.0
    centre_of_gravity: tuple[float, float, float] = (0.150, 0.0, 0.0)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    material: Material = STEEL
    actuator_stiffness: float = 2.0e8
    payload_box: tuple[float, float, float] = (0.200, 1.400, 0.420)
    payload_inertia: tuple[float, float, float] | None = None
    payload_box_centre: tuple[float, float, float] | None = None
    actuator_half_stroke: float = 5e-3
    workspace: tuple[float, float, float] = (1e-3, 5e-3, 3e-3)
    errors: ErrorRanges = ErrorRanges()

    def __post_init__(self) -> None:
        names = [c.name for c in self.chains]
        if names != ["L1", "L2", "L3", "D1", "D2", "D3"]:
            raise ValueError(f"chains must be L1, L2, L3, D1, D2, D3 in that order, got {names}")
        _require(self.payload_mass >= 0, "payload_mass", self.payload_mass, ">= 0 kg", unit="kg")
        _require(self.actuator_stiffness > 0, "actuator_stiffness", self.actuator_stiffness, "> 0 N/m", unit="N/m")
        for i, side in enumerate(self.payload_box):
            _require(side > 0, f"payload_box[{i}]", side, "> 0 mm")
        for i, moment in enumerate(self.payload_inertia or ()):
            _require(moment > 0, f"payload_inertia[{i}]", moment, "> 0 kg m^2", unit="kg m^2")
        for i, coordinate in enumerate(self.payload_box_centre or ()):
            _finite(f"payload_box_centre[{i}]", coordinate)
        _require(self.actuator_half_stroke > 0, "actuator_half_stroke", self.actuator_half_stroke, "> 0 mm")
        for i, half_range in enumerate(self.workspace):
            _require(half_range > 0, f"workspace[{i}]", half_range, "> 0 rad", unit="rad")

    @property
    def load_chains(self) -> tuple[ChainPlacement, ...]:
        return self.chains[:3]

    @property
    def driving_chains(self) -> tuple[ChainPlacement, ...]:
        return self.chains[3:]


def reference_mechanism() -> MechanismParams:
    """The default mechanism of DESIGN.md (1400 mm x 420 mm grating, 300 kg)."""
    return MechanismParams()
