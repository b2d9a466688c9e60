"""The profile registry: every module of a profiles folder, keyed by its name.

``discover`` imports each public module of a package folder (names not starting with
"_") and collects one attribute of each, keyed by the module's name, so that adding a
profile is adding a module. ``flexcal.model.profiles`` and ``flexcal.fem.profiles`` use it
for their own per-profile parts.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from typing import Any

__all__ = ["discover", "hinge_types", "hinge_type", "profile_names"]


@functools.lru_cache(maxsize=None)
def discover(package: str, attribute: str) -> dict[str, Any]:
    """``{module name: module.<attribute>}`` over the public modules of ``package`` (a
    dotted name), sorted by name. Raises ``RuntimeError`` if a module lacks the attribute."""
    module = importlib.import_module(package)
    out = {}
    for info in sorted(pkgutil.iter_modules(module.__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.name in ("protocol", "registry"):
            continue
        found = importlib.import_module(f"{package}.{info.name}")
        if not hasattr(found, attribute):
            raise RuntimeError(f"{package}.{info.name} defines no {attribute}; every profile module must")
        out[info.name] = getattr(found, attribute)
    return out


def hinge_types() -> dict[str, type]:
    """``{profile name: hinge class}`` of every profile ("circular", "leaf", ...)."""
    types = discover("flexcal.geometry.profiles", "HINGE")
    for name, cls in types.items():
        if cls.profile_name != name:
            raise RuntimeError(f"profile module {name!r} holds a hinge named {cls.profile_name!r}; they must agree")
    return types


def profile_names() -> tuple[str, ...]:
    """The registered profile names, sorted."""
    return tuple(hinge_types())


def hinge_type(name: str) -> type:
    """The hinge class of profile ``name``; ``ValueError`` naming the known ones otherwise."""
    types = hinge_types()
    if name not in types:
        raise ValueError(f"hinge profile {name!r} is unknown; choose one of {', '.join(types)}")
    return types[name]
