"""Reading parameter files: TOML or JSON mapping error-source names to display-unit values.

Example (TOML)::

    "D1.CL" = 0.25      # mm
    "D1.mu" = 0.83      # -
    "L2.phi" = 1.2      # rad

A top-level ``[parameters]`` table (or JSON object ``{"parameters": {...}}``) is accepted
too. Names and units: docs/parameters.md. I/O only; the values are checked by
``ParameterSpace.build_values``.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

from flexcal.geometry.schema import MAX_SETTINGS_BYTES, read_text

__all__ = ["read_parameter_file"]


def read_parameter_file(path) -> dict[str, float]:
    """{name: value in display units} from a .toml or .json file.

    Raises ``FileNotFoundError`` if it is missing and ``ValueError`` naming the file if it
    is larger than a settings file may be, not UTF-8, or not a flat mapping of names to
    finite numbers (the bounded read of ``geometry.schema``, shared by every input file).
    """
    path = Path(path)
    text = read_text(path, max_bytes=MAX_SETTINGS_BYTES, what="parameter file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".json":
            data = json.loads(text)
        elif suffix == ".toml":
            data = tomllib.loads(text)
        else:
            try:
                data = json.loads(text)
            except json.JSONDecodeError:
                data = tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as error:
        raise ValueError(f"parameter file {path} is neither valid JSON nor TOML: {error}") from None
    if isinstance(data, dict) and set(data) == {"parameters"} and isinstance(data["parameters"], dict):
        data = data["parameters"]
    if not isinstance(data, dict):
        raise ValueError(f"parameter file {path} must map parameter names to numbers, e.g. \"D1.CL\" = 0.25")
    out = {}
    for name, value in data.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"parameter file {path}: {name} = {value!r} is not a number "
                             f"(names look like 'D1.CL'; a nested table per chain is not supported)")
        if not math.isfinite(value):
            raise ValueError(f"parameter file {path}: {name} = {value!r} must be a finite number")
        out[str(name)] = float(value)
    return out
