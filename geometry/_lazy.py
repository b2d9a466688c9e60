"""Lazy public names for the flexcal packages (PEP 562).

Each package's ``__init__`` maps its public names to the module that defines them; a
name is imported on first use, so ``import flexcal.model`` never loads CadQuery or VTK.
Lives in ``geometry`` because every other package may import from it.
"""

from __future__ import annotations

import importlib
from typing import Callable


def lazy_exports(package: str, exports: dict[str, str]) -> tuple[Callable, Callable, list[str]]:
    """(``__getattr__``, ``__dir__``, ``__all__``) for ``package`` whose public names are
    ``exports`` (name -> module inside the package)."""
    names = sorted(exports)

    def __getattr__(name: str):
        if name in exports:
            return getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return names

    return __getattr__, __dir__, names
