"""Typed input files: read a bounded text file, decode TOML or JSON, check it against a
schema (a frozen ``msgspec.Struct``), and turn every refusal into one line.

The concrete schemas live beside their owners (the scenario in
``validation/prototype/scenario.py``, the measurement sidecar in ``validation/sidecar.py``,
command configurations in ``validation/config.py``; the mount file of ``geometry/`` next);
this module is the part they share. It lives in ``geometry`` because ``geometry`` imports
nothing of flexcal and every other package may import it (as ``_lazy.py``).

Checks are strict: an int is accepted where a number (float) is expected, nothing else is
converted (``seed = 1.7`` for an integer, ``draw_unset = "no"`` for a boolean, ``"3"`` for
a number are refused), and a key the schema does not name is refused. A refusal is a
``ValueError`` of one line naming the file, the key path, what was expected and the
value given::

    scenario.toml: seed = 1.7 must be an integer, not a decimal number
    scenario.toml: unknown key 'mechanism.colour' (= "red"); allowed in mechanism: centre_of_gravity_mm, payload_mass_kg

Sizes are bounded before reading: ``read_text`` looks at the file's size first.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import msgspec

__all__ = ["MAX_SETTINGS_BYTES", "FINITE", "read_text", "read_toml", "read_json", "convert", "load_toml",
           "load_json", "type_name"]

T = TypeVar("T")

# A settings file (scenario, configuration, mount, measurement sidecar) is a few kB; the
# largest one flexcal writes is the sidecar of a MAX_POINTS-point curve (docs/reliability.md:
# one "S1"-style class per point, ~0.7 MB for 1e5 points). 4 MiB leaves room for that and
# is parsed in well under a second; a larger file is a wrong file, not a bigger setting.
MAX_SETTINGS_BYTES = 4 * 2**20
# A number that must be finite: NaN fails both bounds, +-inf one of them.
FINITE = typing.Annotated[float, msgspec.Meta(ge=-sys.float_info.max, le=sys.float_info.max)]

_KINDS = {  # msgspec's names of JSON-like kinds -> words
    "int": "an integer", "float": "a number", "bool": "a boolean (true or false)", "str": "a string",
    "array": "a list", "object": "a table", "null": "nothing (null)", "datetime": "a date-time",
    "date": "a date", "time": "a time",
}


def type_name(value: Any) -> str:
    """'an integer', 'a string', ... for a decoded TOML/JSON value."""
    for kind, name in ((bool, "a boolean"), (int, "an integer"), (float, "a decimal number"), (str, "a string"),
                       (list, "a list"), (dict, "a table"), (type(None), "nothing (null)")):
        if isinstance(value, kind):
            return name
    return f"a {type(value).__name__}"


def read_text(path: str | os.PathLike, *, max_bytes: int, what: str = "file") -> str:
    """The UTF-8 text of ``path`` (a byte-order mark dropped), refused before reading if it
    holds more than ``max_bytes`` bytes. ``FileNotFoundError`` if it is not a file,
    ``ValueError`` naming the file for a size or an encoding it cannot be."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} {path} does not exist")
    size = path.stat().st_size
    if size > max_bytes:
        raise ValueError(f"{path}: {size:,} bytes is more than a {what} may hold ({max_bytes:,} bytes); "
                         f"is it the right file?")
    with path.open("rb") as handle:
        data = handle.read(max_bytes + 1)  # a file that grew since stat() is still bounded
    if len(data) > max_bytes:
        raise ValueError(f"{path}: more than a {what} may hold ({max_bytes:,} bytes); is it the right file?")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b"\n") + 1
        raise ValueError(f"{path}: not UTF-8 text (byte {error.start}, line {line}: {data[error.start:error.start + 1]!r}"
                         f"); save it as UTF-8 (Latin-1 and other encodings are not read)") from None


def read_toml(path: str | os.PathLike, *, max_bytes: int | None = None, what: str = "TOML file") -> dict:
    """The decoded TOML table of ``path`` (bounded, UTF-8), or a ValueError naming the file."""
    text = read_text(path, max_bytes=MAX_SETTINGS_BYTES if max_bytes is None else max_bytes, what=what)
    try:
        return tomllib.loads(text)
    except (ValueError, RecursionError) as error:  # TOMLDecodeError is a ValueError, as is a 5000-digit int
        raise ValueError(f"{path}: not valid TOML ({_one_line(error)})") from None


def read_json(path: str | os.PathLike, *, max_bytes: int | None = None, what: str = "JSON file") -> Any:
    """The decoded JSON value of ``path`` (bounded, UTF-8), or a ValueError naming the file."""
    text = read_text(path, max_bytes=MAX_SETTINGS_BYTES if max_bytes is None else max_bytes, what=what)
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as error:
        raise ValueError(f"{path}: not valid JSON ({_one_line(error)})") from None


def load_toml(path: str | os.PathLike, schema: type[T], *, max_bytes: int | None = None,
              what: str = "TOML file") -> tuple[dict, T]:
    """(the decoded table, the same checked against ``schema``) of a TOML file."""
    raw = read_toml(path, max_bytes=max_bytes, what=what)
    return raw, convert(raw, schema, source=str(path))


def load_json(path: str | os.PathLike, schema: type[T], *, max_bytes: int | None = None,
              what: str = "JSON file") -> tuple[Any, T]:
    """(the decoded value, the same checked against ``schema``) of a JSON file."""
    raw = read_json(path, max_bytes=max_bytes, what=what)
    return raw, convert(raw, schema, source=str(path), table_word="an object")


def convert(raw: Any, schema: type[T], *, source: str, table_word: str = "a table") -> T:
    """``raw`` (decoded TOML/JSON) as ``schema``, strictly; a ValueError of one line
    ``"<source>: <key path> = <value> must be <what was expected>, not <what it is>"``
    (or ``"<source>: unknown key '<key path>' (= <value>); allowed ...: <keys>"``) otherwise."""
    try:
        return msgspec.convert(raw, schema, strict=True)
    except msgspec.ValidationError as error:
        explained = _explain(str(error), raw, schema, table_word).replace("\n", "\\n")  # one line, always
        raise ValueError(f"{source}: {explained}") from None


# --- turning msgspec's message into one line that names the key and the value ----------

_PATH_TOKEN = re.compile(r"\.([^.\[]+)|\[(\d+)\]|\[(\.\.\.)\]")


def _explain(message: str, raw: Any, schema: Any, table_word: str) -> str:
    text, _, where = message.rpartition(" - at `$") if " - at `$" in message else (message, "", "")
    tokens = [(m.group(1), m.group(2), m.group(3)) for m in _PATH_TOKEN.finditer(where.removesuffix("`"))]
    names: list[str] = []
    value, tp = raw, schema
    for field, index, any_key in tokens:
        try:
            if field is not None:
                names.append(_key(field, first=not names))
                value, tp = value[field], _member(tp, field)
            elif index is not None:
                names.append(f"[{index}]")
                value, tp = value[int(index)], _item(tp, int(index))
            else:
                key, value, tp = _failing_entry(value, tp)
                names.append(_key(key, first=not names))
        except (KeyError, IndexError, TypeError):
            break
    path = "".join(names)
    kinds = {**_KINDS, "object": table_word}

    unknown = re.match(r"Object contains unknown field `(.*)`$", text, re.S)
    if unknown:
        field = unknown.group(1)
        allowed = ", ".join(_fields(tp)) or "(none)"
        key = (path + "." if path else "") + _key(field, first=True)
        shown = value.get(field) if isinstance(value, dict) else None
        return f"unknown key {key!r} (= {_show(shown)}); allowed {'in ' + path if path else 'here'}: {allowed}"
    missing = re.match(r"Object missing required field `(.*)`$", text, re.S)
    if missing:
        return f"{path or 'the file'} lacks the required key {missing.group(1)!r}"
    enum = re.match(r"Invalid enum value (.*)$", text, re.S)
    if enum:
        choices = ", ".join(repr(c) for c in _literal_choices(tp))
        return f"{path} = {_show(value)} must be one of {choices}"
    mismatch = re.match(r"Expected `(.*?)`, got `(.*?)`$", text)
    if mismatch:
        options = [k.strip() for k in mismatch.group(1).split("|")]
        options = [k for k in options if k != "null"] or options  # optional keys: leave the key out instead
        wanted = " or ".join(kinds.get(k, k) for k in options)
        return f"{path or 'the file'} = {_show(value)} must be {wanted}, not {type_name(value)}"
    bound = re.match(r"Expected `(.*?)` (.*)$", text)
    if bound:
        kind, condition = bound.group(1), bound.group(2)
        if isinstance(value, float) and not math.isfinite(value):
            return f"{path} = {_show(value)} must be a finite number"
        return f"{path} = {_show(value)} must be {kinds.get(kind, kind)} {condition}"
    return f"{path or 'the file'} = {_show(value)}: {text}"


def _key(name: Any, *, first: bool) -> str:
    name = str(name)
    shown = name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)
    return shown if first else "." + shown


def _show(value: Any, limit: int = 60) -> str:
    """``value`` as the file wrote it (JSON notation: true, "no", [1, 2]), shortened."""
    try:
        text = json.dumps(value, default=str, ensure_ascii=False)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split()) or type(error).__name__


def _strip(tp: Any) -> Any:
    """``tp`` without Annotated/Optional wrappers' metadata."""
    while typing.get_origin(tp) is typing.Annotated:
        tp = typing.get_args(tp)[0]
    return tp


def _options(tp: Any) -> list[Any]:
    tp = _strip(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return [_strip(t) for t in typing.get_args(tp)]
    return [tp]


def _member(tp: Any, field: str) -> Any:
    for option in _options(tp):
        if isinstance(option, type) and issubclass(option, msgspec.Struct):
            names = dict(zip(option.__struct_encode_fields__, option.__struct_fields__))
            return typing.get_type_hints(option, include_extras=True)[names[field]]
        if typing.get_origin(option) is dict:
            return typing.get_args(option)[1]
    return Any


def _item(tp: Any, index: int) -> Any:
    for option in _options(tp):
        origin, args = typing.get_origin(option), typing.get_args(option)
        if origin is list and args:
            return args[0]
        if origin is tuple and args:
            return args[-1] if args[-1] is ... or index >= len(args) else args[index]
    return Any


def _failing_entry(mapping: dict, tp: Any) -> tuple[Any, Any, Any]:
    """(key, value, value type) of the first entry of ``mapping`` that fails its type
    (msgspec names a dict entry ``[...]``; it checks them in order)."""
    value_type = next((typing.get_args(o)[1] for o in _options(tp) if typing.get_origin(o) is dict), Any)
    for key, value in mapping.items():
        try:
            msgspec.convert(value, value_type, strict=True)
        except msgspec.ValidationError:
            return key, value, value_type
    raise KeyError("no failing entry")


def _fields(tp: Any) -> list[str]:
    for option in _options(tp):
        if isinstance(option, type) and issubclass(option, msgspec.Struct):
            return list(option.__struct_encode_fields__)
    return []


def _literal_choices(tp: Any) -> list[Any]:
    for option in _options(tp):
        if typing.get_origin(option) is typing.Literal:
            return list(typing.get_args(option))
    return []
