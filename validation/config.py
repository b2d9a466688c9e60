"""Command configuration files (TOML): read, check against a command's defaults, print.

A command declares its defaults as a module-level ``DEFAULT_CONFIG: dict`` of TOML
values (str, int, float, bool, lists of them, and tables). A user file may set any of
those keys and nothing else; each value must have the default's type (an int is
accepted where the default is a float; tables are checked key by key). The effective
configuration is the defaults, updated by the file, updated by the command line.

    >>> merge_config({"particles": 300, "pso": {"w": 0.9}}, {"pso": {"w": 0.5}}, source="a.toml")
    {'particles': 300, 'pso': {'w': 0.5}}
"""

from __future__ import annotations

import copy
import math
import os
import tomllib
from pathlib import Path
from typing import Any, Mapping

__all__ = ["read_config_file", "merge_config", "check_default_config", "format_config"]

_SCALARS = (bool, int, float, str)


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean (true/false)"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def _same_kind(default: Any, value: Any) -> bool:
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(default, bool) and isinstance(value, bool)
    if isinstance(default, float):
        return isinstance(value, (int, float))
    return isinstance(value, type(default))


def check_default_config(defaults: Mapping[str, Any], where: str = "DEFAULT_CONFIG") -> None:
    """``ValueError`` unless ``defaults`` is TOML-able (no None, finite floats, str keys)."""
    for key, value in defaults.items():
        if not isinstance(key, str):
            raise ValueError(f"{where}: key {key!r} must be a string")
        if isinstance(value, dict):
            check_default_config(value, f"{where}.{key}")
        elif isinstance(value, list):
            if not all(isinstance(v, _SCALARS) for v in value):
                raise ValueError(f"{where}.{key}: lists may hold only strings, numbers and booleans")
        elif not isinstance(value, _SCALARS):
            raise ValueError(f"{where}.{key} = {value!r}: TOML has no {type(value).__name__} (use a default "
                             f"that TOML can write, e.g. 0 or \"\" instead of None)")
        elif isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{where}.{key} = {value!r} must be finite")


def merge_config(defaults: Mapping[str, Any], overrides: Mapping[str, Any], *, source: str,
                 prefix: str = "") -> dict[str, Any]:
    """``defaults`` updated by ``overrides`` (a deep copy; tables merged key by key).

    ``ValueError`` naming ``source`` and the key for an unknown key or a value of the
    wrong type. Ints given for float defaults become floats."""
    merged = copy.deepcopy(dict(defaults))
    for key, value in overrides.items():
        name = f"{prefix}{key}"
        if key not in defaults:
            known = ", ".join(sorted(defaults)) or "(none)"
            raise ValueError(f"{source}: unknown key {name!r}; known keys here: {known}")
        default = defaults[key]
        if isinstance(default, dict):
            if not isinstance(value, dict):
                raise ValueError(f"{source}: {name} must be a table ([{name}]), got {_type_name(value)}")
            merged[key] = merge_config(default, value, source=source, prefix=f"{name}.")
            continue
        if isinstance(default, list):
            if not isinstance(value, list):
                raise ValueError(f"{source}: {name} must be a list, got {_type_name(value)}")
            if default and not all(_same_kind(default[0], v) for v in value):
                raise ValueError(f"{source}: every entry of {name} must be {_type_name(default[0])}")
            merged[key] = [float(v) if default and isinstance(default[0], float) else v for v in value]
            continue
        if not _same_kind(default, value):
            raise ValueError(f"{source}: {name} = {value!r} must be {_type_name(default)}")
        merged[key] = float(value) if isinstance(default, float) else value
    return merged


def read_config_file(path: str | os.PathLike, defaults: Mapping[str, Any]) -> dict[str, Any]:
    """The effective configuration: ``defaults`` updated by the TOML file at ``path``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--config {path}: no such file")
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"--config {path}: not valid TOML ({error})") from None
    except UnicodeDecodeError:
        raise ValueError(f"--config {path}: not a text file") from None
    return merge_config(defaults, table, source=f"--config {path}")


def format_config(config: Mapping[str, Any], *, header: str = "") -> str:
    """``config`` as TOML text (keys in the defaults' order), with ``header`` as comments."""
    import tomli_w

    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    body = tomli_w.dumps(dict(config))
    return ("\n".join(lines) + "\n" if lines else "") + body
