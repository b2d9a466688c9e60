"""The mount file: a whole mount in one TOML file, in display units (mm, kg, N, GPa, MPa).

One module reads and writes it; inside flexcal the mount is ``MechanismParams`` (SI) and
nothing else. ``read_mount(path)`` gives the ``MechanismParams`` of a file,
``mount_text(mechanism)`` the file of a ``MechanismParams`` (every key with a comment),
``mount_table`` / ``mount_from_table`` the same as a dict (the measurement sidecar carries
it). ``flexcal mount --example`` prints the reference mount's file; docs/mount.md explains
every key. Each number is written as the display value that converts back to the SI value
exactly when one exists (``_display``): the reference mount and any mount read from a file
come back as the same floats; a value no double in mm converts back to exactly (the double
grids of m and mm do not line up everywhere) comes back within one unit in the last place.

The family is the paper's: three load chains L1-L3 forming the remote centre and three
drives D1-D3, each chain two leaf flexures turned 90 deg at each end of a strut
(``FlexureChain``). Any other chain count, a role that does not match the name, an unknown
key, a value of the wrong type and an impossible dimension are refused with one line
naming the file, the key or chain and what it must be (``flexcal.geometry.schema``).
"""

from __future__ import annotations

import math
import os
import sys
from typing import Annotated, Any, Callable, Literal

import msgspec
import numpy as np

from .params import ChainPlacement, ErrorRanges, FlexureChain, Material, MechanismParams
from .schema import FINITE, convert, read_toml

__all__ = ["MountFile", "read_mount", "mount_from_table", "mount_table", "mount_text", "mount_differences",
           "CHAIN_ORDER"]

CHAIN_ORDER = ("L1", "L2", "L3", "D1", "D2", "D3")
_STRICT = {"frozen": True, "forbid_unknown_fields": True, "kw_only": True}
POSITIVE = Annotated[float, msgspec.Meta(gt=0.0, le=sys.float_info.max)]
NONNEGATIVE = Annotated[float, msgspec.Meta(ge=0.0, le=sys.float_info.max)]
VECTOR3 = tuple[FINITE, FINITE, FINITE]
POSITIVE3 = tuple[POSITIVE, POSITIVE, POSITIVE]
RANGE = tuple[FINITE, FINITE]


class ChainTable(msgspec.Struct, **_STRICT):
    """One ``[[chains]]`` table: name L1-L3 (role "load": base end A fixed) or D1-D3 (role
    "drive": end A on an actuator moving along A->B); end points [mm] in the mount frame
    (origin O_C); roll_reference [-]: a vector fixing the chain's local y (leaf 1 is thin
    along it); leaf dimensions [mm] of every leaf of the chain (w width, a fillet radius,
    l segment length, t1 leaf-1 and t2 leaf-2 thickness); section_mm: side of the square
    strut, connector and end-block section; connector_mm between the two leaves of a
    flexure; end_block_mm at each end; length_mm: the chain's length, |B - A| to 1 um
    (optional: |B - A|). The strut fills the rest of the length."""

    name: str
    role: Literal["load", "drive"]
    point_a_mm: VECTOR3
    point_b_mm: VECTOR3
    roll_reference: VECTOR3
    w_mm: FINITE
    a_mm: FINITE
    l_mm: FINITE
    t1_mm: FINITE
    t2_mm: FINITE
    section_mm: FINITE
    connector_mm: FINITE
    end_block_mm: FINITE
    length_mm: FINITE | None = None


class PayloadTable(msgspec.Struct, **_STRICT):
    """``[payload]``: mass_kg; centre_of_gravity_mm from O_C; box_mm (x, y, z) it fills;
    inertia_kg_m2 (Ixx, Iyy, Izz) principal moments about the centre of gravity along the
    mount axes (optional: from the box if absent); box_centre_mm: where the box sits, for
    the collision check and pictures (optional: not placed, not checked)."""

    mass_kg: NONNEGATIVE
    centre_of_gravity_mm: VECTOR3
    box_mm: POSITIVE3
    inertia_kg_m2: POSITIVE3 | None = None
    box_centre_mm: VECTOR3 | None = None


class MaterialTable(msgspec.Struct, **_STRICT):
    """``[material]`` of every chain: Young's modulus [GPa], Poisson's ratio [-], density
    [kg/m^3], yield strength [MPa]."""

    youngs_modulus_gpa: POSITIVE
    poisson_ratio: FINITE
    density_kg_m3: POSITIVE
    yield_strength_mpa: POSITIVE


class ActuatorsTable(msgspec.Struct, **_STRICT):
    """``[actuators]`` of D1-D3: axial stiffness of screw + coupling [N/mm]; half stroke
    [mm] either side of zero; the error-source ranges of the initial position x0 [mm], the
    equivalent clearance CL [mm] and the hysteresis coefficient mu [-], each (low, high)."""

    axial_stiffness_n_per_mm: POSITIVE
    half_stroke_mm: POSITIVE
    initial_position_mm: RANGE
    clearance_mm: RANGE
    hysteresis: RANGE


class WorkspaceTable(msgspec.Struct, **_STRICT):
    """``[workspace]``: half-ranges of theta_x, theta_y, theta_z [mrad]."""

    half_range_mrad: POSITIVE3


class ErrorsTable(msgspec.Struct, **_STRICT):
    """``[errors]``: +- dimension_tolerance_percent on every leaf dimension; offset_radius_mm:
    the circle a load chain's base end A sits in."""

    dimension_tolerance_percent: POSITIVE
    offset_radius_mm: POSITIVE


class MountFile(msgspec.Struct, **_STRICT):
    """A mount file (module docstring; docs/mount.md). Every table is required: a mount
    file says the whole mount (``flexcal mount --example`` prints one to start from)."""

    name: str
    gravity_m_s2: VECTOR3
    payload: PayloadTable
    material: MaterialTable
    actuators: ActuatorsTable
    workspace: WorkspaceTable
    errors: ErrorsTable
    chains: list[ChainTable]


# display unit -> (SI from display, display from SI); every conversion in this module
_UNITS: dict[str, tuple[Callable[[float], float], Callable[[float], float]]] = {
    "mm": (lambda d: d / 1e3, lambda v: v * 1e3),
    "mrad": (lambda d: d / 1e3, lambda v: v * 1e3),
    "gpa": (lambda d: d * 1e9, lambda v: v / 1e9),
    "mpa": (lambda d: d * 1e6, lambda v: v / 1e6),
    "n_per_mm": (lambda d: d * 1e3, lambda v: v / 1e3),
    "percent": (lambda d: d / 1e2, lambda v: v * 1e2),
    "": (lambda d: d, lambda v: v),
}


def _si(value: float, unit: str) -> float:
    return float(_UNITS[unit][0](float(value)))


def _display(value: float, unit: str) -> float:
    """The display value of ``value`` [SI] that converts back to exactly ``value``
    (the nearest one to ``value * scale`` within a few ulps; that one if none does)."""
    to_si, from_si = _UNITS[unit]
    value = float(value)
    first = float(from_si(value))
    up = down = first
    for _ in range(8):  # the correctly rounded product is within an ulp or two of a round-tripping one
        for candidate in (up, down):
            if to_si(candidate) == value:
                return candidate
        up, down = math.nextafter(up, math.inf), math.nextafter(down, -math.inf)
    return first


def _vector(values, unit: str) -> tuple[float, ...]:
    return tuple(_si(v, unit) for v in values)


def _shown(values, unit: str) -> list[float]:
    return [_display(v, unit) for v in values]


# --- reading ---------------------------------------------------------------------------

def read_mount(path: str | os.PathLike) -> MechanismParams:
    """The ``MechanismParams`` [SI] of the mount file ``path``; one-line ValueError naming
    the file otherwise (size, encoding, TOML, keys, types, chains, dimensions)."""
    raw = read_toml(path, what="mount file")
    return mount_from_table(raw, source=str(path))


def mount_from_table(raw: Any, *, source: str) -> MechanismParams:
    """The ``MechanismParams`` of a decoded mount table (a file or a sidecar's ``mount``)."""
    typed = convert(raw, MountFile, source=source)
    try:
        return _mechanism(typed)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def _mechanism(typed: MountFile) -> MechanismParams:
    names = [c.name for c in typed.chains]
    if names != list(CHAIN_ORDER):
        raise ValueError(f"chains {', '.join(names) or '(none)'}: a mount has six [[chains]], "
                         f"{', '.join(CHAIN_ORDER)} in that order (three load chains forming the remote "
                         f"centre, three drives; other families are not modelled)")
    chains = tuple(_placement(c) for c in typed.chains)
    payload, material, actuators = typed.payload, typed.material, typed.actuators
    inertia = None if payload.inertia_kg_m2 is None else tuple(float(v) for v in payload.inertia_kg_m2)
    errors = ErrorRanges(dimension_tolerance=_si(typed.errors.dimension_tolerance_percent, "percent"),
                         offset_radius=_si(typed.errors.offset_radius_mm, "mm"),
                         hysteresis=_vector(actuators.hysteresis, ""),
                         clearance=_vector(actuators.clearance_mm, "mm"),
                         initial_position=_vector(actuators.initial_position_mm, "mm"))
    return MechanismParams(
        chains=chains,
        payload_mass=float(payload.mass_kg),
        centre_of_gravity=_vector(payload.centre_of_gravity_mm, "mm"),
        gravity=_vector(typed.gravity_m_s2, ""),
        material=Material(youngs_modulus=_si(material.youngs_modulus_gpa, "gpa"),
                          poisson_ratio=float(material.poisson_ratio), density=float(material.density_kg_m3),
                          yield_strength=_si(material.yield_strength_mpa, "mpa")),
        actuator_stiffness=_si(actuators.axial_stiffness_n_per_mm, "n_per_mm"),
        payload_box=_vector(payload.box_mm, "mm"),
        payload_inertia=inertia,
        payload_box_centre=None if payload.box_centre_mm is None else _vector(payload.box_centre_mm, "mm"),
        actuator_half_stroke=_si(actuators.half_stroke_mm, "mm"),
        workspace=_vector(typed.workspace.half_range_mrad, "mrad"),
        errors=errors,
    )


def _placement(table: ChainTable) -> ChainPlacement:
    role = "load" if table.name.startswith("L") else "drive"
    if table.role != role:
        raise ValueError(f"chain {table.name}: role = {table.role!r} must be {role!r} (L1-L3 are load chains, "
                         f"D1-D3 drives)")
    point_a, point_b = _vector(table.point_a_mm, "mm"), _vector(table.point_b_mm, "mm")
    if float(np.linalg.norm(table.roll_reference)) == 0.0:
        raise ValueError(f"chain {table.name}: roll_reference = [0, 0, 0] must be a direction (not along A->B)")
    length = float(np.linalg.norm(np.subtract(point_b, point_a))) if table.length_mm is None \
        else _si(table.length_mm, "mm")
    try:
        chain = FlexureChain(length=length, hinge_length=_si(table.l_mm, "mm"), width=_si(table.w_mm, "mm"),
                             fillet=_si(table.a_mm, "mm"), thickness_1=_si(table.t1_mm, "mm"),
                             thickness_2=_si(table.t2_mm, "mm"), section=_si(table.section_mm, "mm"),
                             connector_length=_si(table.connector_mm, "mm"),
                             end_block_length=_si(table.end_block_mm, "mm"))
        placement = ChainPlacement(name=table.name, chain=chain, point_a=point_a, point_b=point_b,
                                   roll_reference=_vector(table.roll_reference, ""))
        placement.rotation  # a roll reference along the chain axis fails here, named below
    except (ValueError, np.linalg.LinAlgError) as error:
        raise ValueError(f"chain {table.name}: {_file_words(str(error))}") from None
    return placement


_FILE_KEYS = {"hinge_length": "l_mm", "width": "w_mm", "fillet": "a_mm", "thickness_1": "t1_mm",
              "thickness_2": "t2_mm", "section": "section_mm", "connector_length": "connector_mm",
              "end_block_length": "end_block_mm", "length": "length_mm"}


def _file_words(message: str) -> str:
    """A parameter type's message with the file's key names (``fillet=7 mm`` -> ``a_mm=7 mm``)."""
    head, sep, rest = message.partition("=")
    key = _FILE_KEYS.get(head.strip().split(".")[-1])
    return f"{key}{sep}{rest}" if key and sep else message


# --- writing ---------------------------------------------------------------------------

def mount_table(mechanism: MechanismParams, *, name: str = "mount") -> dict[str, Any]:
    """The mount file's table of ``mechanism`` (display units; ``mount_from_table`` gives
    ``mechanism`` back exactly)."""
    errors = mechanism.errors
    payload: dict[str, Any] = {"mass_kg": float(mechanism.payload_mass),
                               "centre_of_gravity_mm": _shown(mechanism.centre_of_gravity, "mm"),
                               "box_mm": _shown(mechanism.payload_box, "mm")}
    if mechanism.payload_inertia is not None:
        payload["inertia_kg_m2"] = [float(v) for v in mechanism.payload_inertia]
    if mechanism.payload_box_centre is not None:
        payload["box_centre_mm"] = _shown(mechanism.payload_box_centre, "mm")
    material = mechanism.material
    return {
        "name": name,
        "gravity_m_s2": [float(v) for v in mechanism.gravity],
        "payload": payload,
        "material": {"youngs_modulus_gpa": _display(material.youngs_modulus, "gpa"),
                     "poisson_ratio": float(material.poisson_ratio), "density_kg_m3": float(material.density),
                     "yield_strength_mpa": _display(material.yield_strength, "mpa")},
        "actuators": {"axial_stiffness_n_per_mm": _display(mechanism.actuator_stiffness, "n_per_mm"),
                      "half_stroke_mm": _display(mechanism.actuator_half_stroke, "mm"),
                      "initial_position_mm": _shown(errors.initial_position, "mm"),
                      "clearance_mm": _shown(errors.clearance, "mm"),
                      "hysteresis": [float(v) for v in errors.hysteresis]},
        "workspace": {"half_range_mrad": _shown(mechanism.workspace, "mrad")},
        "errors": {"dimension_tolerance_percent": _display(errors.dimension_tolerance, "percent"),
                   "offset_radius_mm": _display(errors.offset_radius, "mm")},
        "chains": [_chain_table(p) for p in mechanism.chains],
    }


def _chain_table(placement: ChainPlacement) -> dict[str, Any]:
    chain = placement.chain
    return {"name": placement.name, "role": "drive" if placement.is_driving else "load",
            "point_a_mm": _shown(placement.point_a, "mm"), "point_b_mm": _shown(placement.point_b, "mm"),
            "roll_reference": [float(v) for v in placement.roll_reference],
            "w_mm": _display(chain.width, "mm"), "a_mm": _display(chain.fillet, "mm"),
            "l_mm": _display(chain.hinge_length, "mm"), "t1_mm": _display(chain.thickness_1, "mm"),
            "t2_mm": _display(chain.thickness_2, "mm"), "section_mm": _display(chain.section, "mm"),
            "connector_mm": _display(chain.connector_length, "mm"),
            "end_block_mm": _display(chain.end_block_length, "mm"), "length_mm": _display(chain.length, "mm")}


_COMMENTS = {  # key -> the comment written beside it (docs/mount.md says more)
    "name": "a name for reports (a chain's: L1-L3 load, D1-D3 drives)",
    "gravity_m_s2": "gravity vector [m/s^2] in the mount frame (x along the optic's normal, z up)",
    "mass_kg": "payload mass [kg] (optic + its frame)",
    "centre_of_gravity_mm": "payload centre of gravity [mm] from the remote centre O_C",
    "box_mm": "the box the payload fills (x, y, z) [mm]: its inertia about the centre of gravity",
    "inertia_kg_m2": "principal moments (Ixx, Iyy, Izz) [kg m^2] about the CoG; replaces the box's",
    "box_centre_mm": "where the box's centre sits [mm]: chains are checked against the box (optional)",
    "youngs_modulus_gpa": "Young's modulus E [GPa]",
    "poisson_ratio": "Poisson's ratio nu [-]",
    "density_kg_m3": "density [kg/m^3]",
    "yield_strength_mpa": "yield strength [MPa] (stress checks of flexcal structure)",
    "axial_stiffness_n_per_mm": "axial stiffness of ball screw + coupling of each drive [N/mm]",
    "half_stroke_mm": "travel of each actuator either side of zero [mm]",
    "initial_position_mm": "range (low, high) of the unknown initial position x0 [mm]",
    "clearance_mm": "range (low, high) of the equivalent clearance CL [mm]",
    "hysteresis": "range (low, high) of the hysteresis coefficient mu [-] (nominal 1)",
    "half_range_mrad": "workspace half-ranges of theta_x, theta_y, theta_z [mrad]",
    "dimension_tolerance_percent": "+- tolerance on every leaf dimension w, a, l, t1, t2 [%]",
    "offset_radius_mm": "radius of the circle a load chain's base end A sits in [mm]",
    "role": "load (base end A fixed) or drive (end A on the actuator, moving along A->B)",
    "point_a_mm": "end A (base / actuator side) [mm]",
    "point_b_mm": "end B (payload-frame side) [mm]",
    "roll_reference": "fixes local y: leaf 1 is thin along it, bends about local z",
    "w_mm": "leaf width w [mm]",
    "a_mm": "leaf fillet radius a [mm]",
    "l_mm": "leaf segment length l [mm]",
    "t1_mm": "thickness t1 of leaf 1 [mm]",
    "t2_mm": "thickness t2 of leaf 2 (turned 90 deg) [mm]",
    "section_mm": "side of the square strut / connector / end-block section [mm]",
    "connector_mm": "connector between the two leaves of a flexure [mm]",
    "end_block_mm": "end block at each end [mm]; the strut fills the rest of the length",
    "length_mm": "chain length [mm]: |B - A| to 1 um (optional: |B - A|)",
}


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return msgspec.json.encode(value).decode()  # a JSON string is a TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(float(value))


def _lines(table: dict[str, Any]) -> list[str]:
    width = max(len(f"{k} = {_toml_value(v)}") for k, v in table.items())
    return [f"{f'{k} = {_toml_value(v)}':<{width}}  # {_COMMENTS[k]}" for k, v in table.items()]


def mount_text(mechanism: MechanismParams, *, name: str = "mount") -> str:
    """The mount file of ``mechanism``: TOML, display units, every key commented."""
    table = mount_table(mechanism, name=name)
    out = ["# flexcal mount file (docs/mount.md): the whole mount in display units.",
           "# Frame: origin O_C (the remote centre) at the optic's front-surface centre; x along its",
           "# normal into the mount, z up. Read by --mount FILE; checked by 'flexcal mount FILE'.", ""]
    out += _lines({k: table[k] for k in ("name", "gravity_m_s2")})
    for section in ("payload", "material", "actuators", "workspace", "errors"):
        out += ["", f"[{section}]", *_lines(table[section])]
    for chain in table["chains"]:
        out += ["", "[[chains]]", *_lines(chain)]
    return "\n".join(out) + "\n"


def mount_differences(before: MechanismParams, after: MechanismParams) -> list[str]:
    """The keys of the mount file where ``after`` differs from ``before``, one line each:
    ``"chains.L1.t1_mm: 4.0 -> 3.5"`` (display units)."""
    flat_before, flat_after = _flatten(mount_table(before)), _flatten(mount_table(after))
    keys = list(flat_before) + [k for k in flat_after if k not in flat_before]
    return [f"{k}: {_words(flat_before.get(k))} -> {_words(flat_after.get(k))}" for k in keys
            if k != "name" and flat_before.get(k) != flat_after.get(k)]


def _flatten(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in table.items():
        if key == "chains":
            for chain in value:
                out.update(_flatten({k: v for k, v in chain.items() if k != "name"}, f"chains.{chain['name']}."))
        elif isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[prefix + key] = value
    return out


def _words(value: Any) -> str:
    if value is None:
        return "(absent)"
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:.6g}" for v in value) + "]"
    return f"{value:.6g}" if isinstance(value, float) else str(value)
