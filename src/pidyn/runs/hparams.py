"""A run's settings and outcome in TensorBoard's HParams tab, so that the jobs of a multirun
(noise levels, batch sizes, earthquake scalings) are compared side by side there, each row a run
with its errors and held-out scores."""

from __future__ import annotations

import math
from typing import Any

#: the settings a sweep varies, as metrics.json names them
KNOBS = ("system", "record", "noise", "eq_scale", "eq_stretch", "batch_size", "seed", "data_seed", "refine")


def _scores(metrics: dict) -> dict[str, float]:
    adequacy = metrics.get("adequacy") or {}
    raw = {
        "max_error_pct": metrics.get("max_error_pct"),
        "mean_error_pct": metrics.get("mean_error_pct"),
        "fit_nrmse": adequacy.get("fit_nrmse"),
        "heldout_nrmse": adequacy.get("heldout_nrmse"),
        "wall_seconds": metrics.get("wall_seconds"),
    }
    out = {}
    for name, value in raw.items():
        if isinstance(value, (int, float)) and math.isfinite(float(value)):
            out[f"hparams/{name}"] = float(value)
    return out


def _plain(value: Any) -> Any:
    """A value TensorBoard takes as a hyperparameter: a number, a bool or a string."""
    return value if isinstance(value, (bool, int, float, str)) else str(value)


def log_hparams(logger: Any, metrics: dict) -> dict[str, Any]:
    """Write the run's knobs and scores to the logger's HParams (a TensorBoard logger; nothing
    otherwise), the run's last words to TensorBoard: its writer is flushed, so the event files
    are whole when the task returns, not when the writer's thread next flushes (every 2 min) or
    the process ends. Returns the knobs written."""
    hp = {k: _plain(metrics[k]) for k in KNOBS if metrics.get(k) is not None}
    exp = getattr(logger, "experiment", None) if logger is not None else None
    if exp is not None and hasattr(logger, "log_hyperparams"):
        logger.log_hyperparams(hp, _scores(metrics))
        if hasattr(exp, "flush"):
            exp.flush()
    return hp
