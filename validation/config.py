"""Command configuration files (TOML): read, check against a command's defaults, print.

A command declares its defaults as a module-level ``DEFAULT_CONFIG: dict`` of TOML
values (str, int, float, bool, lists of them, and tables). A user file may set any of
those keys and nothing else; each value must have the default's type (an int is
accepted where the default is a float, nothing else is converted; tables are checked key
by key): ``config_schema(defaults)`` is that schema as a frozen ``msgspec.Struct``, and
``flexcal.geometry.schema`` turns a refusal into one line naming the file, the key, the
expected type and the value. The effective configuration is the defaults, updated by
the file, updated by the command line.

    >>> merge_config({"particles": 300, "pso": {"w": 0.9}}, {"pso": {"w": 0.5}}, source="a.toml")
    {'particles': 300, 'pso': {'w': 0.5}}
"""

from __future__ import annotations

import keyword
import math
import os
from pathlib import Path
from typing import Any, Mapping

import msgspec

from flexcal.geometry.schema import FINITE, convert, read_toml

__all__ = ["read_config_file", "merge_config", "config_schema", "check_default_config", "format_config"]

_SCALARS = (bool, int, float, str)


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


def config_schema(defaults: Mapping[str, Any], name: str = "Config") -> type:
    """A frozen ``msgspec.Struct`` type whose fields are the keys of ``defaults``, each of
    its default's type (a float default: a finite number, an int accepted; a table: a
    nested schema; a list: a list of its first entry's type, any scalar if empty) and
    default; any other key is refused."""
    fields = []
    for number, (key, value) in enumerate(defaults.items()):
        # Python name of the field; the file's key is its encode name (keys need not be identifiers)
        python_name = key if key.isidentifier() and not keyword.iskeyword(key) else f"key_{number}"
        if isinstance(value, dict):
            kind = config_schema(value, f"{name}_{number}")
            default = msgspec.field(default_factory=kind, name=key)
        elif isinstance(value, list):
            kind = list[_scalar_type(value[0])] if value else list[bool | int | FINITE | str]
            default = msgspec.field(default_factory=lambda value=value: list(value), name=key)
        else:
            kind, default = _scalar_type(value), msgspec.field(default=value, name=key)
        fields.append((python_name, kind, default))
    return msgspec.defstruct(name, fields, frozen=True, forbid_unknown_fields=True, kw_only=True)


def _scalar_type(value: Any) -> Any:
    if isinstance(value, bool):
        return bool
    if isinstance(value, float):
        return FINITE
    return type(value)


def merge_config(defaults: Mapping[str, Any], overrides: Mapping[str, Any], *, source: str,
                 prefix: str = "") -> dict[str, Any]:
    """``defaults`` updated by ``overrides`` (a deep copy; tables merged key by key).

    ``overrides`` is checked against ``config_schema(defaults)``: a ValueError of one
    line naming ``source``, the key, the expected type and the value for an unknown key
    or a value of the wrong type (``flexcal.geometry.schema``). Ints given for float
    defaults become floats. (``prefix`` is kept for callers; keys are named in full.)"""
    typed = convert(dict(overrides), config_schema(defaults), source=source)
    return _as_dict(typed)


def _as_dict(typed: Any) -> dict[str, Any]:
    """A config struct as a plain dict in the defaults' key order (encode names)."""
    out = {}
    for python_name, key in zip(typed.__struct_fields__, typed.__struct_encode_fields__):
        value = getattr(typed, python_name)
        out[key] = _as_dict(value) if isinstance(value, msgspec.Struct) else (list(value) if isinstance(value, list)
                                                                               else value)
    return out


def read_config_file(path: str | os.PathLike, defaults: Mapping[str, Any]) -> dict[str, Any]:
    """The effective configuration: ``defaults`` updated by the TOML file at ``path``
    (at most MAX_SETTINGS_BYTES, UTF-8; every refusal one line naming ``--config`` and the file)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--config {path}: no such file")
    try:
        table = read_toml(path, what="configuration file")
        return merge_config(defaults, table, source=f"--config {path}")
    except ValueError as error:
        message = str(error)
        raise ValueError(message if message.startswith("--config") else f"--config {message}") from None


def format_config(config: Mapping[str, Any], *, header: str = "") -> str:
    """``config`` as TOML text (keys in the defaults' order), with ``header`` as comments."""
    import tomli_w

    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    body = tomli_w.dumps(dict(config))
    return ("\n".join(lines) + "\n" if lines else "") + body
