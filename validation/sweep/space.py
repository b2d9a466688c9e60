"""The design space of a sweep: a TOML table -> a list of design dicts.

A sweep config (``examples/sweep_notch.toml``; every key and its default:
``flexcal sweep --print-config``)::

    [sweep]
    kind = "circular"        # a hinge profile (circular | leaf | ...) or chain: which table below is swept
    method = "grid"          # grid: every combination of the listed values
                             # lhs: n_samples Latin-hypercube points in [low, high] ranges
    n_samples = 8            # lhs only
    seed = 0                 # lhs only (scipy.stats.qmc.LatinHypercube)
    elements_through = 1.5   # quadratic tets through the thinnest section (mesh knob)

    [circular]               # dimensions [mm]: one value = fixed; more = swept
    radius_mm = [5.0]        #   (grid: each value; lhs: [low, high])
    thickness_mm = [0.5, 1.0, 1.5, 2.0]
    width_mm = [10.0]
    block_mm = [5.0]

    [identification]         # optional, off by default (sweep/identify.py)
    enabled = false

A design is a flat dict of plain numbers and strings: ``kind``, the kind's dimensions in
mm, ``elements_through`` (and the identification settings when enabled); its id is a
hash of exactly that dict, so equal designs share results.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from typing import Any

import numpy as np

from flexcal.calibration.sensitivity import check_n_base

__all__ = ["DEFAULT_CONFIG", "resolve_config", "designs_from_config", "design_id", "varied_names",
           "build_part_params"]

_IDENTIFICATION_DEFAULTS = {"enabled": False, "provider": "analytic", "scenario": "table1", "sobol_n": 64,
                            "particles": 40, "iterations": 30, "seed": 0}

def _hinge_types() -> dict[str, type]:
    from flexcal.geometry.profiles import hinge_types

    return hinge_types()


DEFAULT_CONFIG: dict[str, Any] = {
    "sweep": {"kind": "circular", "method": "grid", "n_samples": 8, "seed": 0, "elements_through": 1.5},
    # [mm]; one table per hinge profile (its ``sweep_defaults_mm``: the notch hinge of
    # docs/hinge-verification.md, a leaf of the mount, ...) and a driving chain of the mount
    **{name: {key: list(values) for key, values in cls.sweep_defaults_mm.items()}
       for name, cls in _hinge_types().items()},
    "chain": {"length_mm": [150.0], "hinge_length_mm": [20.0], "width_mm": [40.0], "fillet_mm": [6.0],
              "t1_mm": [3.0], "t2_mm": [3.0], "section_mm": [50.0], "connector_mm": [10.0],
              "end_block_mm": [10.0],
              # [N] compression the chain carries, for its buckling factor: the reference mount's
              # load chains L2 and L3 carry 3074-3077 N under the 300 kg payload (flexcal structure)
              "axial_load_n": [3080.0]},
    "identification": dict(_IDENTIFICATION_DEFAULTS),
}
KINDS = (*_hinge_types(), "chain")


def resolve_config(config: dict[str, Any], source: str = "sweep config") -> dict[str, Any]:
    """``DEFAULT_CONFIG`` updated by ``config`` (tables key by key; unknown keys and wrong
    types raise ValueError naming the key)."""
    from ..config import merge_config

    return merge_config(DEFAULT_CONFIG, config, source=source)


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ValueError(f"{where} = {value!r} must be a finite number")
    return float(value)


def _identification(table: dict[str, Any]) -> dict[str, Any]:
    merged = dict(table)
    if merged["provider"] not in ("analytic", "fem"):
        raise ValueError(f"[identification] provider = {merged['provider']!r} must be 'analytic' or 'fem'")
    for name in ("sobol_n", "particles", "iterations", "seed"):
        if not isinstance(merged[name], int) or merged[name] < 0:
            raise ValueError(f"[identification] {name} = {merged[name]!r} must be a non-negative integer")
    check_n_base(merged["sobol_n"], name="[identification] sobol_n")
    return merged


def _samples(dimensions: dict[str, list[float]], method: str, n_samples: int, seed: int, kind: str
             ) -> list[dict[str, float]]:
    names = list(dimensions)
    for name in names:
        if not dimensions[name]:
            raise ValueError(f"[{kind}] {name} is an empty list; give one value (fixed) or more (swept)")
    values = {name: [_number(v, f"[{kind}] {name}") for v in dimensions[name]] for name in names}
    if method == "grid":
        return [dict(zip(names, combo)) for combo in itertools.product(*(values[n] for n in names))]
    if method == "lhs":
        from scipy.stats import qmc

        swept = [n for n in names if len(values[n]) > 1]
        for name in swept:
            if len(values[name]) != 2 or not values[name][0] < values[name][1]:
                raise ValueError(f"[{kind}] {name} = {values[name]}: with method = 'lhs' give one value (fixed) "
                                 f"or a range [low, high] with low < high [mm]")
        if not isinstance(n_samples, int) or n_samples < 1:
            raise ValueError(f"[sweep] n_samples = {n_samples!r} must be a positive integer")
        if not swept:
            return [{n: values[n][0] for n in names}]
        unit = qmc.LatinHypercube(d=len(swept), seed=np.random.default_rng(seed)).random(n_samples)
        low, high = np.array([values[n] for n in swept]).T
        points = qmc.scale(unit, low, high)
        return [{**{n: values[n][0] for n in names}, **dict(zip(swept, map(float, row)))} for row in points]
    raise ValueError(f"[sweep] method = {method!r} must be 'grid' or 'lhs'")


def designs_from_config(config: dict[str, Any], *, seed: int | None = None,
                        mount: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """The designs of a sweep config (see the module docstring; missing keys take
    ``DEFAULT_CONFIG``); ``seed`` overrides ``[sweep] seed``; ``mount`` (a mount file's
    table, ``--mount``) is the identification's mount, part of each design (and its id). Each design is validated (its
    hinge or chain is built), so a bad config fails here, before any worker starts."""
    config = resolve_config(config)
    sweep = config["sweep"]
    kind = sweep["kind"]
    if kind not in KINDS:
        raise ValueError(f"[sweep] kind = {kind!r} must be one of {', '.join(KINDS)}")
    elements = _number(sweep["elements_through"], "[sweep] elements_through")
    if elements < 1:
        raise ValueError(f"[sweep] elements_through = {elements} must be >= 1")
    identification = _identification(config["identification"])
    if mount is not None:
        if not identification["enabled"]:
            raise ValueError("--mount sets the mount of the identification column: enable it ([identification] "
                             "enabled = true); the FEM-vs-closed-form columns are of the hinge or chain alone")
        identification = {**identification, "mount": mount}
    designs = []
    for sample in _samples(config[kind], sweep["method"], sweep["n_samples"],
                           sweep["seed"] if seed is None else seed, kind):
        design = {"kind": kind, **sample, "elements_through": elements}
        if identification["enabled"]:
            design["identification"] = identification
        params = build_part_params(design)  # raises ValueError with the dimension's name
        if identification["enabled"] and kind != "chain" and params.chain_dimensions() is None:
            raise ValueError("[identification] needs kind = 'leaf' or 'chain' (the mount's chains are leaf flexures)")
        designs.append(design)
    return designs


def varied_names(config: dict[str, Any]) -> list[str]:
    """The swept dimensions of the config's kind (the x axes of the plots)."""
    config = resolve_config(config)
    return [name for name, values in config[config["sweep"]["kind"]].items() if len(values) > 1]


def design_id(design: dict[str, Any]) -> str:
    """First 16 hex digits of the SHA-256 of the design's canonical JSON."""
    text = json.dumps(design, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def build_part_params(design: dict[str, Any]):
    """The hinge (``CircularNotchHinge``, ``LeafHinge``, ... by profile name) or
    ``FlexureChain`` of a design [m]."""
    from flexcal.geometry.params import FlexureChain

    mm = 1e-3
    kind = design["kind"]
    types = _hinge_types()
    if kind in types:
        cls = types[kind]
        return cls.from_mm({d.key: design[f"{d.key}_mm"] for d in cls.dimensions}, design["block_mm"])
    if kind == "chain":
        return FlexureChain(length=design["length_mm"] * mm, hinge_length=design["hinge_length_mm"] * mm,
                            width=design["width_mm"] * mm, fillet=design["fillet_mm"] * mm,
                            thickness_1=design["t1_mm"] * mm, thickness_2=design["t2_mm"] * mm,
                            section=design["section_mm"] * mm, connector_length=design["connector_mm"] * mm,
                            end_block_length=design["end_block_mm"] * mm)
    raise ValueError(f"design kind {kind!r} must be one of {', '.join(KINDS)}")
