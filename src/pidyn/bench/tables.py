"""The studies' tables: a number or an interval as a cell, a run folder's JSON, a sweep's jobs.

Every study writes markdown tables from finished run folders; these are the pieces they share, so
that a missing value, an interval and a sweep's job folders read the same in every table."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml


def _missing(v: Any) -> bool:
    if v is None or v == "":
        return True
    return isinstance(v, float) and not math.isfinite(v)


def cell(v: Any, fmt: str = ".3f", missing: str = "-") -> str:
    """A number formatted, or ``missing`` for None, an empty cell or a value that is not finite."""
    return missing if _missing(v) else format(float(v), fmt)


def interval(ci: Any, fmt: str = ".3f", missing: str = "-") -> str:
    """``[lo, hi]`` formatted, or ``missing`` when either end is unknown."""
    if not ci or any(_missing(x) for x in ci[:2]):
        return missing
    return f"[{format(float(ci[0]), fmt)}, {format(float(ci[1]), fmt)}]"


def median(values: Iterable[Any]) -> float | None:
    """The median of the known values; None when there is none."""
    v = sorted(float(x) for x in values if x is not None)
    if not v:
        return None
    mid = len(v) // 2
    return v[mid] if len(v) % 2 else 0.5 * (v[mid - 1] + v[mid])


def load_json(path: Path) -> Any:
    """A run folder's JSON file, or None where the run did not write it."""
    return json.loads(path.read_text()) if path.is_file() else None


def sweep_runs(folder: Path) -> list[tuple[dict, Path]]:
    """(config, run folder) of every job of a Hydra multirun, in the folders' order."""
    out = []
    for cfg_path in sorted(folder.glob("*/.hydra/config.yaml")):
        out.append((yaml.safe_load(cfg_path.read_text()), cfg_path.parent.parent))
    return out
