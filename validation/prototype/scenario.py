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
    [mechanism]                # the mount itself, where it differs from the reference one
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

The built-in scenario ``table1`` uses the paper's Table 1 presets (initial positions
−0.20, 0.32, 0.40 mm; CL 0.42, 0.25, 0.10 mm; μ 0.83, 0.87, 0.93) and draws every other
source within its range from the seed. Like the paper's simulation it is noise-free
unless a noise level is given.

The built-in scenario ``paper`` is the same mount and presets with the payload's centre of
gravity at the remote centre O_C instead of 150 mm behind it: the weight then no longer
preloads the tip/tilt drives D1 and D2, and all three drives pass through their clearance
on the backward moves, as in the paper's Fig. 12 (chains 1 and 2 enter the clearance
zone), so every Table 1 drive row can show (docs/verification-table1.md). The mechanism
of a scenario travels in the measurement's sidecar (``provenance()["mechanism"]``), and
``mechanism_from_metadata`` gives it back to the commands that model the data.
"""

from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexcal.model.parameters import ParameterSpace, parameter_space
from flexcal.model.trajectory import standard_trajectory

__all__ = ["Scenario", "load_scenario", "BUILTIN_SCENARIOS", "scenario_trajectory", "read_trajectory",
           "mechanism_from_metadata", "mechanism_overrides"]

TABLE1_PRESETS = {  # paper Table 1, display units (mm, -)
    "D1.x0": -0.20, "D2.x0": 0.32, "D3.x0": 0.40,
    "D1.CL": 0.42, "D2.CL": 0.25, "D3.CL": 0.10,
    "D1.mu": 0.83, "D2.mu": 0.87, "D3.mu": 0.93,
}
BUILTIN_SCENARIOS: dict[str, dict[str, Any]] = {
    "table1": {"name": "table1", "seed": 1, "draw_unset": True, "errors": TABLE1_PRESETS},
    "nominal": {"name": "nominal", "seed": 0, "draw_unset": False, "errors": {}},
    "paper": {"name": "paper", "seed": 1, "draw_unset": True, "errors": TABLE1_PRESETS,
              "mechanism": {"centre_of_gravity_mm": [0.0, 0.0, 0.0]}},
}
_TOP_KEYS = {"name", "seed", "draw_unset", "errors", "sensors", "transmission", "trajectory", "effects", "mechanism"}
_MECHANISM_KEYS = {"centre_of_gravity_mm", "payload_mass_kg"}


def mechanism_overrides(table: dict[str, Any]) -> dict[str, Any]:
    """MechanismParams fields (SI) from a ``[mechanism]`` table (display units), checked."""
    unknown = set(table) - _MECHANISM_KEYS
    if unknown:
        raise ValueError(f"[mechanism] has unknown key(s) {sorted(unknown)}; allowed: {sorted(_MECHANISM_KEYS)}")
    out: dict[str, Any] = {}
    if "centre_of_gravity_mm" in table:
        cog = np.asarray(table["centre_of_gravity_mm"], dtype=float)
        if cog.shape != (3,) or not np.all(np.isfinite(cog)) or np.any(np.abs(cog) > 2000.0):
            raise ValueError(f"[mechanism] centre_of_gravity_mm={table['centre_of_gravity_mm']!r} must be three "
                             f"finite numbers within +-2000 mm of O_C")
        out["centre_of_gravity"] = tuple(float(v) * 1e-3 for v in cog)
    if "payload_mass_kg" in table:
        mass = float(table["payload_mass_kg"])
        if not (math.isfinite(mass) and 0.0 <= mass <= 1e5):
            raise ValueError(f"[mechanism] payload_mass_kg={mass} must be in [0, 1e5] kg")
        out["payload_mass"] = mass
    return out


def mechanism_from_metadata(metadata: dict[str, Any]):
    """The reference mechanism with a measurement sidecar's ``mechanism`` overrides (if any)."""
    import dataclasses

    from flexcal.geometry.params import reference_mechanism

    table = dict(metadata.get("mechanism") or {})
    return dataclasses.replace(reference_mechanism(), **mechanism_overrides(table))


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """Everything the prototype needs to make one synthetic measurement.

    values (45,) [SI] all error sources (explicit presets and drawn ones); preset_names:
    the ones the scenario set explicitly; noise (3,) [rad] sensor noise standard deviation
    per channel; offset (3,) [rad] sensor offsets; breakaway_force [N]; inputs (n, 3) [m]
    and leg (n,) the trajectory; dwell [s] between points; effects: ({"name": ..., params}).
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
    mechanism: dict[str, Any] = field(default_factory=dict)

    def with_trajectory(self, path: str | Path) -> "Scenario":
        """The scenario driven along the trajectory file ``path`` (``flexcal design``'s
        trajectory.csv: columns xa1_mm, xa2_mm, xa3_mm[, leg])."""
        import dataclasses

        inputs, leg = read_trajectory(path)
        return dataclasses.replace(self, inputs=inputs, leg=leg)

    def provenance(self) -> dict[str, Any]:
        """The scenario as JSON-ready data (display units), for the sidecar."""
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
            "mechanism": dict(self.mechanism),
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
    [mm] and optionally leg (default 1), e.g. ``flexcal design``'s trajectory.csv."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trajectory file {path} does not exist")
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"trajectory file {path}: no rows")
    for column in ("xa1_mm", "xa2_mm", "xa3_mm"):
        if column not in rows[0]:
            raise ValueError(f"trajectory file {path}: row 1 lacks column {column!r}")
    inputs, legs = [], []
    for number, row in enumerate(rows, start=2):
        try:
            inputs.append([float(row[c]) * 1e-3 for c in ("xa1_mm", "xa2_mm", "xa3_mm")])
            legs.append(int(float(row.get("leg", 1) or 1)))
        except ValueError:
            raise ValueError(f"trajectory file {path}: row {number} has a value that is not a number") from None
    inputs = np.array(inputs)
    if not np.all(np.isfinite(inputs)):
        raise ValueError(f"trajectory file {path}: inputs must be finite")
    return inputs, np.array(legs)


def scenario_trajectory(spec: dict[str, Any], space: ParameterSpace, base: Path) -> tuple[np.ndarray, np.ndarray]:
    """(inputs (n, 3) [m], leg (n,)) from a ``[trajectory]`` table."""
    kind = spec.get("kind", "standard")
    if kind == "standard":
        trajectory = standard_trajectory(space.mechanism, n_points=int(spec.get("n_points", 77)))
        return trajectory.inputs, trajectory.leg
    if kind == "file":
        if "file" not in spec:
            raise ValueError("[trajectory] kind = 'file' needs file = 'inputs.csv'")
        return read_trajectory((base / spec["file"]).resolve())
    raise ValueError(f"[trajectory] kind={kind!r} must be 'standard' or 'file'")


def _from_table(table: dict[str, Any], *, base: Path, seed: int | None, noise_urad: float | None,
                space: ParameterSpace) -> Scenario:
    unknown = set(table) - _TOP_KEYS
    if unknown:
        raise ValueError(f"scenario has unknown key(s) {sorted(unknown)}; allowed: {sorted(_TOP_KEYS)}")
    seed = int(table.get("seed", 0) if seed is None else seed)
    mechanism_table = dict(table.get("mechanism", {}))
    if mechanism_table:
        import dataclasses

        space = parameter_space(dataclasses.replace(space.mechanism, **mechanism_overrides(mechanism_table)))
    if seed < 0:
        raise ValueError(f"seed={seed} must be >= 0")
    errors = dict(table.get("errors", {}))
    explicit = space.build_values(errors, display_units=True)  # checks names and ranges
    values = explicit.copy()
    if table.get("draw_unset", True):
        rng = np.random.default_rng([seed, 1])  # stream 1: error draws (stream 2: sensor noise)
        drawn = rng.uniform(np.array([p.lower for p in space.parameters]), np.array([p.upper for p in space.parameters]))
        unset = np.array([p.name not in errors for p in space.parameters])
        values[unset] = drawn[unset]
    sensors = dict(table.get("sensors", {}))
    noise = _per_channel(sensors.get("noise_urad", 0.0) if noise_urad is None else noise_urad, "noise_urad") * 1e-6
    if np.any(noise < 0):
        raise ValueError(f"noise_urad must be >= 0, got {noise * 1e6}")
    offset = _per_channel(sensors.get("offset_urad", 0.0), "offset_urad") * 1e-6
    breakaway = float(dict(table.get("transmission", {})).get("breakaway_force_n", 2.0))
    if not (math.isfinite(breakaway) and breakaway >= 0):
        raise ValueError(f"breakaway_force_n={breakaway} must be >= 0")
    trajectory_spec = dict(table.get("trajectory", {}))
    inputs, leg = scenario_trajectory(trajectory_spec, space, base)
    dwell = float(trajectory_spec.get("dwell_s", 2.0))
    if not dwell > 0:
        raise ValueError(f"dwell_s={dwell} must be > 0")
    effects = tuple(dict(e) for e in table.get("effects", []))
    for effect in effects:
        if "name" not in effect:
            raise ValueError("every [[effects]] entry needs a name")
    return Scenario(name=str(table.get("name", "scenario")), seed=seed, values=values, preset_names=tuple(errors),
                    noise=noise, offset=offset, breakaway_force=breakaway, inputs=inputs, leg=leg, dwell=dwell,
                    effects=effects, space=space, mechanism=mechanism_table)


def load_scenario(name_or_path: str, *, seed: int | None = None, noise_urad: float | None = None,
                  space: ParameterSpace | None = None) -> Scenario:
    """A built-in scenario by name (``table1``, ``nominal``) or a TOML file.

    ``seed`` and ``noise_urad`` override the file's values (command-line options).
    """
    space = space or parameter_space()
    if name_or_path in BUILTIN_SCENARIOS:
        return _from_table(BUILTIN_SCENARIOS[name_or_path], base=Path.cwd(), seed=seed, noise_urad=noise_urad,
                           space=space)
    path = Path(name_or_path)
    if not path.is_file():
        raise FileNotFoundError(f"scenario {name_or_path!r} is neither a built-in ({', '.join(BUILTIN_SCENARIOS)}) "
                                f"nor an existing TOML file")
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: not valid TOML ({error})") from None
    return _from_table(table, base=path.parent, seed=seed, noise_urad=noise_urad, space=space)
