"""The relative error every report, table and experiment uses: one definition."""

from __future__ import annotations

from typing import Any

import numpy as np


def error_pct(value: Any, truth: Any) -> Any:
    """100 |value - truth| / |truth|, for numbers or arrays (a zero truth gives inf or nan)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 100.0 * np.abs(np.asarray(value, float) - truth) / np.abs(truth)
    return float(out) if np.ndim(out) == 0 else out


def errors_pct(values: dict[str, float], truths: dict[str, float | None]) -> dict[str, float]:
    """Per parameter, for those whose truth is known and nonzero (a missing value gives nan)."""
    return {n: error_pct(values.get(n, np.nan), t) for n, t in truths.items() if t}
