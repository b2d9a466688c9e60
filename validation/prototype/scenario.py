"""Scenarios of the virtual prototype: preset errors, sensors, trajectory, seed (TOML).

A scenario file::

    name = "my-mount"
    seed = 7
    draw_unset = true          # draw every error source not listed within its range
    [errors]                   # display units: mm, rad, - (docs/parameters.md)
    "D1.x0" = -0.20
    "D1.CL" = 0.42
    [sensors]
    noise_urad = 0.5           # one value, or [x, y, z]
    offset_urad = [0, 0, 0]
    [transmission]
    breakaway_force_n = 2.0
    mount = "my.mount.toml"    # the mount file (docs/mount.md), relative to this file; default: the reference
    [mechanism]                # optional changes to that mount
    centre_of_gravity_mm = [150, 0, 0]
    payload_mass_kg = 300
    [trajectory]
    kind = "standard"          # or "file" with file = "inputs.csv" (columns xa1_mm, xa2_mm, xa3_mm[, leg])
    n_points = 77
    dwell_s = 2.0              # time between points
    [[effects]]                # injected unmodelled effects (gap diagnosis, docs/effects.md)
    name = "drift"
    rate = [5e-8, 5e-8, 1.5e-7]  # injector fields in SI (flexcal.validation.effects.injectors)
    [[effects]]
    name = "lead_error"
    magnitude_urad = 8.0       # or: a drawn injector of that size (effects.library.make_injector)
    seed = 3

Every key is typed (``ScenarioFile`` and its tables, frozen ``msgspec.Struct`` types):
a value of another type (``seed = 1.7``, ``draw_unset = "no"``) or a key not listed above
is refused with one line naming the file, the key, the expected type and the value
(``flexcal.geometry.schema``); ``n_points`` is at most ``measurements.MAX_POINTS``.

The built-in scenarios read their mount from ``examples/`` (``table1.mount.toml``, the
reference mount of DESIGN.md, for ``table1`` and ``nominal``; ``paper.mount.toml`` for
``paper``) through ``flexcal.geometry.mount.read_mount``, like any scenario's ``mount``.
A ``mount`` argument of ``load_scenario`` (``--mount FILE``) replaces the scenario's.

The built-in scenario ``table1`` uses the paper's Table 1 presets (initial positions
−0.20, 0.32, 0.40 mm; CL 0.42, 0.25, 0.10 mm; μ 0.83, 0.87, 0.93) and draws every other
source within its range from the seed. Like the paper's simulation it is noise-free
unless a noise level is given.

The built-in scenario ``paper`` is the same mount and presets with the payload's centre of
gravity at the remote centre O_C instead of 150 mm behind it: the weight then no longer
preloads the tip/tilt drives D1 and D2, and all three drives pass through their clearance
on the backward moves, as in the paper's Fig. 12 (chains 1 and 2 enter the clearance
zone), so every Table 1 drive row can show (docs/verification-table1.md). The mount of a
scenario travels whole in the measurement's sidecar (``provenance()["mount"]``, the mount
file's table), and ``mechanism_from_metadata`` gives it back to the commands that model
the data (an older sidecar's ``mechanism`` overrides apply to the reference mount).
"""

from __future__ import annotations

import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec
import numpy as np

from flexcal.geometry.schema import FINITE, convert, read_toml
from flexcal.model.parameters import ParameterSpace, parameter_space
from flexcal.model.trajectory import standard_trajectory

from ..measurements import MAX_POINTS
from ..sidecar import MechanismOverrides

__all__ = ["Scenario", "load_scenario", "BUILTIN_SCENARIOS", "scenario_trajectory", "read_trajectory",
           "mechanism_from_metadata", "mechanism_overrides"]

TABLE1_PRESETS = {  # paper Table 1, display units (mm, -)
    "D1.x0": -0.20, "D2.x0": 0.32, "D3.x0": 0.40,
    "D1.CL": 0.42, "D2.CL": 0.25, "D3.CL": 0.10,
    "D1.mu": 0.83, "D2.mu": 0.87, "D3.mu": 0.93,
}
EXAMPLES_DIR = Path(__file__).resolve().parents[2] / "examples"  # the mount files of the built-in scenarios
BUILTIN_SCENARIOS: dict[str, dict[str, Any]] = {
    "table1": {"name": "table1", "seed": 1, "draw_unset": True, "errors": TABLE1_PRESETS,
               "mount": str(EXAMPLES_DIR / "table1.mount.toml")},
    "nominal": {"name": "nominal", "seed": 0, "draw_unset": False, "errors": {},
                "mount": str(EXAMPLES_DIR / "table1.mount.toml")},
    "paper": {"name": "paper", "seed": 1, "draw_unset": True, "errors": TABLE1_PRESETS,
              "mount": str(EXAMPLES_DIR / "paper.mount.toml")},
}
_STRICT = {"frozen": True, "forbid_unknown_fields": True, "kw_only": True}
NONNEGATIVE = Annotated[float, msgspec.Meta(ge=0.0, le=sys.float_info.max)]


class SensorsTable(msgspec.Struct, **_STRICT):
    """``[sensors]``: noise (standard deviation) and offset [urad], one value or (x, y, z);
    finite and (noise) >= 0 are checked by ``_per_channel`` (msgspec 0.22 crashes in the
    garbage collector on a union of a constrained float and a tuple, so no Meta here)."""

    noise_urad: float | tuple[float, float, float] = 0.0
    offset_urad: float | tuple[float, float, float] = 0.0


class TransmissionTable(msgspec.Struct, **_STRICT):
    """``[transmission]``: breakaway_force_n [N] of the drives' friction."""

    breakaway_force_n: NONNEGATIVE = 2.0


class TrajectoryTable(msgspec.Struct, **_STRICT):
    """``[trajectory]``: the standard one of n_points points, or a CSV file; dwell_s [s]."""

    kind: Literal["standard", "file"] = "standard"
    file: str | None = None
    n_points: Annotated[int, msgspec.Meta(ge=1, le=MAX_POINTS)] = 77
    dwell_s: Annotated[float, msgspec.Meta(gt=0.0, le=sys.float_info.max)] = 2.0


class EffectEntry(msgspec.Struct, frozen=True, kw_only=True):
    """One ``[[effects]]`` table: the keys every effect shares; its injector's own fields
    (any other key) are checked by ``effects.library.effects_from_scenario``."""

    name: str
    magnitude_urad: FINITE | None = None
    seed: Annotated[int, msgspec.Meta(ge=0)] | None = None


class ScenarioFile(msgspec.Struct, **_STRICT):
    """The keys of a scenario file (module docstring), typed; any other key is refused."""

    name: str = "scenario"
    seed: Annotated[int, msgspec.Meta(ge=0)] = 0
    draw_unset: bool = True
    mount: str | None = None
    errors: dict[str, FINITE] = {}
    sensors: SensorsTable = SensorsTable()
    transmission: TransmissionTable = TransmissionTable()
    mechanism: MechanismOverrides = MechanismOverrides()
    trajectory: TrajectoryTable = TrajectoryTable()
    effects: list[EffectEntry] = []


def mechanism_overrides(table: dict[str, Any], *, source: str = "[mechanism]") -> dict[str, Any]:
    """MechanismParams fields (SI) from a ``[mechanism]`` table (display units), checked
    (``MechanismOverrides``; a ValueError naming ``source`` and the key otherwise)."""
    overrides = convert(table, MechanismOverrides, source=source)
    out: dict[str, Any] = {}
    if overrides.centre_of_gravity_mm is not None:
        out["centre_of_gravity"] = tuple(float(v) * 1e-3 for v in overrides.centre_of_gravity_mm)
    if overrides.payload_mass_kg is not None:
        out["payload_mass"] = float(overrides.payload_mass_kg)
    return out


def mechanism_from_metadata(metadata: dict[str, Any]):
    """The mount of a measurement's sidecar: its ``mount`` table (``flexcal.geometry.mount``),
    else the reference mount with an older sidecar's ``mechanism`` overrides (if any); where
    those change the mount, one warning says which mount models the data."""
    import dataclasses

    from flexcal.geometry.mount import mount_from_table
    from flexcal.geometry.params import reference_mechanism

    if metadata.get("mount") is not None:
        return mount_from_table(metadata["mount"], source="the sidecar's mount")
    reference = reference_mechanism()
    table = dict(metadata.get("mechanism") or {})
    mechanism = dataclasses.replace(reference, **mechanism_overrides(table, source="the sidecar's mechanism"))
    if (mechanism.centre_of_gravity, mechanism.payload_mass) != (reference.centre_of_gravity,
                                                                 reference.payload_mass):
        logging.getLogger("flexcal.scenario").warning(
            "the data's mount differs from the reference one: %s (reference: %s); the model uses the data's mount "
            "(the sidecar's 'mechanism')", _mount_words(mechanism), _mount_words(reference))
    return mechanism


def _mount_words(mechanism) -> str:
    cog = ", ".join(f"{v * 1e3:g}" for v in mechanism.centre_of_gravity)
    return f"centre of gravity ({cog}) mm, payload {mechanism.payload_mass:g} kg"


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """Everything the prototype needs to make one synthetic measurement.

    values (45,) [SI] all error sources (explicit presets and drawn ones); preset_names:
    the ones the scenario set explicitly; noise (3,) [rad] sensor noise standard deviation
    per channel; offset (3,) [rad] sensor offsets; breakaway_force [N]; inputs (n, 3) [m]
    and leg (n,) the trajectory; dwell [s] between points; effects: ({"name": ..., params});
    space: the error sources of the mount (``space.mechanism``: the mount, SI).
    """

    name: str
    seed: int
    values: np.ndarray
    preset_names: tuple[str, ...]
    noise: np.ndarray
    offset: np.ndarray
    breakaway_force: float
    inputs: np.ndarray
    leg: np.ndarray
    dwell: float
    effects: tuple[dict[str, Any], ...] = ()
    space: ParameterSpace = field(default_factory=parameter_space)

    def with_trajectory(self, path: str | Path) -> "Scenario":
        """The scenario driven along the trajectory file ``path`` (``flexcal design``'s
        trajectory.csv: columns xa1_mm, xa2_mm, xa3_mm[, leg])."""
        import dataclasses

        inputs, leg = read_trajectory(path)
        return dataclasses.replace(self, inputs=inputs, leg=leg)

    def provenance(self) -> dict[str, Any]:
        """The scenario as JSON-ready data (display units), for the sidecar; ``mount``: the
        mount file's table (``flexcal.geometry.mount.mount_table``)."""
        from flexcal.geometry.mount import mount_table

        display = self.space.to_display(self.values)
        return {
            "scenario": self.name,
            "seed": self.seed,
            "preset_errors": [
                {"name": p.name, "unit": p.display_unit, "value": float(v), "explicit": p.name in self.preset_names}
                for p, v in zip(self.space.parameters, display)
            ],
            "sensors": {"noise_urad": (self.noise * 1e6).tolist(), "offset_urad": (self.offset * 1e6).tolist()},
            "transmission": {"breakaway_force_n": self.breakaway_force},
            "effects": list(self.effects),
            "n_points": int(self.inputs.shape[0]),
            "mount": mount_table(self.space.mechanism, name=self.name),
        }


def _per_channel(value: Any, what: str) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        array = np.full(3, float(array))
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{what} must be one number or three (x, y, z), got {value!r}")
    return array


def read_trajectory(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(inputs (n, 3) [m], leg (n,)) of a trajectory file: columns xa1_mm, xa2_mm, xa3_mm
    [mm] and optionally leg (default 1), e.g. ``flexcal design``'s trajectory.csv
    (``flexcal.validation.measurements.read_trajectory``)."""
    from ..measurements import read_trajectory as read_trajectory_csv

    return read_trajectory_csv(path)


def scenario_trajectory(spec: dict[str, Any], space: ParameterSpace, base: Path) -> tuple[np.ndarray, np.ndarray]:
    """(inputs (n, 3) [m], leg (n,)) from a ``[trajectory]`` table (``TrajectoryTable``)."""
    table = convert(spec, TrajectoryTable, source="[trajectory]")
    if table.kind == "standard":
        trajectory = standard_trajectory(space.mechanism, n_points=table.n_points)
        return trajectory.inputs, trajectory.leg
    if table.file is None:
        raise ValueError("[trajectory] kind = 'file' needs file = 'inputs.csv'")
    return read_trajectory((base / table.file).resolve())


def _from_table(table: dict[str, Any], *, base: Path, seed: int | None, noise_urad: float | None,
                space: ParameterSpace, source: str, mount=None, keep_space: bool = False) -> Scenario:
    typed = convert(table, ScenarioFile, source=source)
    seed = typed.seed if seed is None else int(seed)
    if mount is not None:
        space = parameter_space(mount)
    elif typed.mount is not None and not keep_space:
        from flexcal.geometry.mount import read_mount

        space = parameter_space(read_mount((base / typed.mount).resolve()))
    mechanism_table = dict(table.get("mechanism", {}))
    if mechanism_table:
        import dataclasses

        space = parameter_space(dataclasses.replace(space.mechanism, **mechanism_overrides(mechanism_table)))
    if seed < 0:
        raise ValueError(f"seed={seed} must be >= 0")
    errors = dict(typed.errors)
    explicit = space.build_values(errors, display_units=True)  # checks names and ranges
    values = explicit.copy()
    if typed.draw_unset:
        rng = np.random.default_rng([seed, 1])  # stream 1: error draws (stream 2: sensor noise)
        drawn = rng.uniform(np.array([p.lower for p in space.parameters]), np.array([p.upper for p in space.parameters]))
        unset = np.array([p.name not in errors for p in space.parameters])
        values[unset] = drawn[unset]
    noise = _per_channel(typed.sensors.noise_urad if noise_urad is None else noise_urad, "noise_urad") * 1e-6
    if np.any(noise < 0):
        raise ValueError(f"noise_urad must be >= 0, got {noise * 1e6}")
    offset = _per_channel(typed.sensors.offset_urad, "offset_urad") * 1e-6
    inputs, leg = scenario_trajectory(dict(table.get("trajectory", {})), space, base)
    effects = tuple(dict(e) for e in table.get("effects", []))
    from ..effects.library import effects_from_scenario

    effects_from_scenario(effects)  # the injectors' own fields: refused now, not after the first FEM build
    return Scenario(name=typed.name, seed=seed, values=values, preset_names=tuple(errors),
                    noise=noise, offset=offset, breakaway_force=typed.transmission.breakaway_force_n, inputs=inputs,
                    leg=leg, dwell=typed.trajectory.dwell_s, effects=effects, space=space)


def load_scenario(name_or_path: str, *, seed: int | None = None, noise_urad: float | None = None,
                  space: ParameterSpace | None = None, mount=None) -> Scenario:
    """A built-in scenario by name (``table1``, ``nominal``, ``paper``) or a TOML file.

    ``seed`` and ``noise_urad`` override the file's values (command-line options), ``mount``
    (``MechanismParams``, ``--mount FILE``) the scenario's mount; a ``space`` given (a
    sweep's design, ``flexcal design``'s scenario space) does too, unless ``mount`` is. A file
    is checked against ``ScenarioFile`` (bounded size, UTF-8, known keys of the right
    types); every refusal is a ValueError of one line naming the file.
    """
    keep_space = space is not None
    space = space or parameter_space()
    if name_or_path in BUILTIN_SCENARIOS:
        return _from_table(BUILTIN_SCENARIOS[name_or_path], base=Path.cwd(), seed=seed, noise_urad=noise_urad,
                           space=space, source=f"built-in scenario {name_or_path!r}", mount=mount,
                           keep_space=keep_space)
    path = Path(name_or_path)
    if not path.is_file():
        raise FileNotFoundError(f"scenario {name_or_path!r} is neither a built-in ({', '.join(BUILTIN_SCENARIOS)}) "
                                f"nor an existing TOML file")
    table = read_toml(path, what="scenario file")
    try:
        return _from_table(table, base=path.parent, seed=seed, noise_urad=noise_urad, space=space, source=str(path),
                           mount=mount, keep_space=keep_space)
    except (ValueError, FileNotFoundError) as error:  # checks after the schema name the key, not always the file
        if str(path) in str(error):
            raise
        raise ValueError(f"{path}: {error}") from None
