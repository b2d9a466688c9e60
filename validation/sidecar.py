"""The measurement sidecar (``curves.json`` beside ``curves.csv``): its schema and reader.

``flexcal truth`` writes every key below; a sidecar of a real measurement may hold any
of them (all are optional) and its own provenance under ``notes`` (free-form). Any other
key, or a value of the wrong type, is refused with one line naming the file, the key, what
was expected and the value given (``flexcal.geometry.schema``). Display units, as
written: mm, µrad, N, kg.

The ``mount`` entry is the whole mount the data came from, as the mount file's table
(``flexcal.geometry.mount.MountFile``, docs/mount.md); the commands that model the data use
that mount (``--mount FILE`` replaces it and lists the differences). An older sidecar's
``mechanism`` entry (``MechanismOverrides``: centre of gravity, payload mass) changes the
reference mount instead.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Any

import msgspec
import numpy as np

from flexcal.geometry.mount import MountFile
from flexcal.geometry.schema import FINITE, load_json

__all__ = ["Sidecar", "MechanismOverrides", "PresetError", "read_sidecar", "stated_sensor_noise_urad"]

_STRICT = {"frozen": True, "forbid_unknown_fields": True, "kw_only": True}
# Within +-2 m of O_C: the metre-scale mount's frame (paper: a 1400 mm grating); a centre of
# gravity farther away is a unit slip (m vs mm), not a mount.
COG_COMPONENT_MM = Annotated[float, msgspec.Meta(ge=-2000.0, le=2000.0)]
# 0 to 100 t: the reference payload is 300 kg; anything heavier is not a flexure mount's.
PAYLOAD_KG = Annotated[float, msgspec.Meta(ge=0.0, le=1e5)]
VECTOR3 = tuple[FINITE, FINITE, FINITE]


class MechanismOverrides(msgspec.Struct, **_STRICT):
    """Where a mount differs from the reference one (``[mechanism]`` of a scenario, the
    sidecar's ``mechanism``): centre_of_gravity_mm (x, y, z) [mm] of the payload from
    O_C; payload_mass_kg [kg]. Absent keys keep the reference values."""

    centre_of_gravity_mm: tuple[COG_COMPONENT_MM, COG_COMPONENT_MM, COG_COMPONENT_MM] | None = None
    payload_mass_kg: PAYLOAD_KG | None = None


class PresetError(msgspec.Struct, **_STRICT):
    """One error source as the truth set it: value in its display unit (mm, rad, -)."""

    name: str
    unit: str
    value: FINITE
    explicit: bool


class SensorSettings(msgspec.Struct, **_STRICT):
    noise_urad: VECTOR3 = (0.0, 0.0, 0.0)
    offset_urad: VECTOR3 = (0.0, 0.0, 0.0)


class TransmissionSettings(msgspec.Struct, **_STRICT):
    breakaway_force_n: FINITE = 2.0


class PrototypeRun(msgspec.Struct, **_STRICT):
    max_force_residual_n: FINITE
    max_moment_residual_nm: FINITE
    newton_iterations_total: int
    point_class: list[str]


class Sidecar(msgspec.Struct, **_STRICT):
    """Provenance of a measurement (every key optional). n_points: the CSV's data rows
    (``read_measurement`` refuses a sidecar that disagrees)."""

    generator: str | None = None
    provider: str | None = None
    scenario: str | None = None
    seed: Annotated[int, msgspec.Meta(ge=0)] | None = None
    preset_errors: list[PresetError] | None = None
    sensors: SensorSettings | None = None
    transmission: TransmissionSettings | None = None
    effects: list[dict[str, Any]] | None = None
    n_points: Annotated[int, msgspec.Meta(ge=1)] | None = None
    mechanism: MechanismOverrides | None = None
    mount: MountFile | None = None
    injected_effects: list[Any] | None = None
    prototype: PrototypeRun | None = None
    notes: dict[str, Any] | None = None


def read_sidecar(path: str | os.PathLike, *, n_rows: int | None = None) -> dict[str, Any]:
    """The sidecar at ``path`` as decoded (a dict: the commands read it with ``.get``),
    checked against ``Sidecar``; with ``n_rows``, its ``n_points`` must equal it.

    ``ValueError`` naming the file for anything else (size, encoding, JSON, keys, types)."""
    path = Path(path)
    raw, sidecar = load_json(path, Sidecar, what="measurement sidecar")
    if n_rows is not None and sidecar.n_points is not None and sidecar.n_points != n_rows:
        raise ValueError(f"{path}: n_points = {sidecar.n_points}, but {path.with_suffix('.csv').name} has {n_rows} "
                         f"data rows; the sidecar belongs to another measurement (fix or remove it)")
    if sidecar.prototype is not None and n_rows is not None and len(sidecar.prototype.point_class) != n_rows:
        raise ValueError(f"{path}: prototype.point_class has {len(sidecar.prototype.point_class)} entries, but "
                         f"{path.with_suffix('.csv').name} has {n_rows} data rows; the sidecar belongs to another "
                         f"measurement (fix or remove it)")
    return raw


def stated_sensor_noise_urad(metadata: dict[str, Any]) -> np.ndarray | None:
    """(3,) the sensor noise [urad] per channel a measurement's sidecar states
    (``sensors.noise_urad``, as ``read_sidecar`` decoded it), or None when it states none (no
    sidecar, no ``sensors`` entry or no noise in it). Each reader says what "none" means for
    it: a bench that simulates the sensors adds no noise, the model-form floor calls the
    noise unknown, the profile bars' default is off (``cli.options.declared_noise_urad``)."""
    stated = (metadata.get("sensors") or {}).get("noise_urad")
    return None if stated is None else np.asarray(stated, dtype=float)
