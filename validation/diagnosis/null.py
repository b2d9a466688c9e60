"""The null of the diagnosis on one trajectory: what each term gains on data with nothing
injected (issue #28, docs/diagnosis.md "Null of the trajectory").

The fixed significance threshold (a held-out gain of 1 noise variance) was set on `none`
files of the standard trajectory, where the baseline model fits the prototype to the
noise. On another trajectory (``flexcal design``'s postures reach large combined rotations)
the model's own form error is larger and a term can take it up: large_deflection gained
3.9 noise variances, closure 0.93, on a `none` file of a 77-point design. A ``NullModel``
holds, per term, the largest first-stage held-out gain seen on `none` files of the same
trajectory (the prototype with nothing injected, seeds apart from the benchmark's); a term
is then significant only if it gains ``NULL_FACTOR`` times that as well.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["NullModel", "null_from_reports", "NULL_FACTOR", "NULL_SEEDS", "read_null", "write_null",
           "check_null_baseline"]

# the standard trajectory's threshold of 1 noise variance was 3.3x the largest null gain seen
# there (docs/diagnosis.md, Scores and significance): the same factor over each term's null
NULL_FACTOR = 3.0
NULL_SEEDS = (100, 101, 102)  # `none` files of the null: scenario seeds 1100-1102, apart from the benchmark's 1000-1009


@dataclass(frozen=True, kw_only=True)
class NullModel:
    """gain {term id: largest held-out gain [noise variances] on the null files};
    closure {term id: largest held-out closure [-]}; n_files; trajectory: its digest
    (``benchmark.trajectory_digest``) or "standard"; factor: NULL_FACTOR; baseline: the
    baseline model's options (``cli.opening.model_key``) the gains were measured with, None when
    the file does not say (null files before session 28: the second-order baseline)."""

    gain: dict = field(default_factory=dict)
    closure: dict = field(default_factory=dict)
    n_files: int = 0
    trajectory: str = "standard"
    factor: float = NULL_FACTOR
    baseline: dict | None = None

    def min_gain(self, term_id: str, floor: float) -> float:
        """The gain [noise variances] a term needs: ``floor`` or factor x its null gain."""
        return max(floor, self.factor * max(self.gain.get(term_id, 0.0), 0.0))

    def as_dict(self) -> dict[str, Any]:
        return {"gain": dict(self.gain), "closure": dict(self.closure), "n_files": self.n_files,
                "trajectory": self.trajectory, "factor": self.factor, "baseline": self.baseline}


def null_from_reports(reports: Sequence[dict], trajectory: str = "standard", baseline: dict | None = None) -> NullModel:
    """A ``NullModel`` from diagnosis reports of `none` files (their first-stage ranking)."""
    if not reports:
        raise ValueError("the null needs at least one diagnosis of a file with nothing injected")
    gain: dict[str, float] = {}
    closure: dict[str, float] = {}
    for report in reports:
        for row in report["ranking"]:
            gain[row["effect"]] = max(gain.get(row["effect"], -np.inf), float(row["gain_noise_variances"]))
            closure[row["effect"]] = max(closure.get(row["effect"], -np.inf), float(row["closure"]))
    return NullModel(gain=gain, closure=closure, n_files=len(reports), trajectory=trajectory, baseline=baseline)


def measure_null(make_none: Callable[[int], Any], diagnose: Callable[[Any], Any], seeds: Sequence[int] = NULL_SEEDS,
                 trajectory: str = "standard", baseline: dict | None = None) -> NullModel:
    """Diagnose the `none` measurement ``make_none(seed)`` of each seed (without a null) and
    collect the terms' gains; baseline: the model ``diagnose`` calibrates (``NullModel``)."""
    return null_from_reports([diagnose(make_none(s)).report for s in seeds], trajectory, baseline)


def write_null(path: str | Path, null: NullModel) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)  # a new --out folder (the cases come later)
    Path(path).write_text(json.dumps(null.as_dict(), indent=1, sort_keys=True) + "\n")


def _baseline(value) -> dict | None:
    if value is not None and not isinstance(value, dict):
        raise ValueError(f"baseline {value!r} is not a table of model options")
    return value


def check_null_baseline(null: NullModel, baseline: dict, path: str = "the null") -> None:
    """Refuse (ValueError) a null measured with another baseline model than ``baseline`` (the
    run's ``cli.opening.model_key``): its gains are that model's form error, not this one's. A
    null without a baseline (before session 28) was measured with the second-order model."""
    if null.baseline is None and "model" not in baseline:
        return
    if null.baseline != baseline:
        made = null.baseline or "the second-order baseline (a null file from before session 28)"
        raise ValueError(f"{path} was measured with the baseline model {made}, this run's is {baseline}: measure the "
                         f"null again with this model (flexcal diagnose-benchmark --trajectory ... with the same model "
                         f"options) or give the null's model options")


def read_null(path: str | Path) -> NullModel:
    """A ``NullModel`` from its JSON file (``write_null``; DIR/null.json of diagnose-benchmark)."""
    try:
        data = json.loads(Path(path).read_text())
        return NullModel(gain={str(k): float(v) for k, v in data["gain"].items()},
                         closure={str(k): float(v) for k, v in data.get("closure", {}).items()},
                         n_files=int(data["n_files"]), trajectory=str(data.get("trajectory", "standard")),
                         factor=float(data.get("factor", NULL_FACTOR)), baseline=_baseline(data.get("baseline")))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"cannot read the null file {path}: {error} (write it with flexcal diagnose-benchmark: "
                         f"DIR/null.json)") from None
