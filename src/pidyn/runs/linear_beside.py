"""The linear model of a run's own layout, fitted beside a nonlinear one on the same records.

A prediction of an unseen record scores the run's model and, beside it, the linear model of the
same layout identified on the same records (``prediction.json``'s ``linear_mean_nrmse_a``): the
nonlinear model has to earn its terms on records it never saw. Where the config names that linear
model (``linear_system``, which ``pidyn.config.choose_system`` sets when a data set's default for
several records is a nonlinear model), the training run fits it by output error from the data's
start on the run's own fitting part (3-4 s on 17-18 Painter Street events: the linear simulation is
a one-sample map) and keeps its values in ``metrics.json``'s ``linear_model``.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from omegaconf import DictConfig, open_dict

from pidyn.data.sources import Record
from pidyn.refine.output_error import fit_output_error
from pidyn.runs.build import system_and_record
from pidyn.starts.data import start_from_data

log = logging.getLogger(__name__)

#: the top-level config key that names the linear model of the run's layout
KEY = "linear_system"


def linear_config(cfg: DictConfig) -> DictConfig | None:
    """``cfg`` with its system replaced by the linear model it names (None when it names none)."""
    node = cfg.get(KEY)
    if node is None:
        return None
    out = cfg.copy()
    with open_dict(out):
        out.system = node
        out[KEY] = None
    return out


def fit_linear_beside(cfg: DictConfig, record: Record, hold_out: bool) -> dict[str, Any] | None:
    """The linear model of the run's layout fitted on the run's record (its fitting part where
    ``hold_out``): ``{"system", "params", "start", "cost", "seconds"}``, or None where the config
    names no such model. A fit that fails is said so and left out; the run goes on."""
    lin = linear_config(cfg)
    if lin is None:
        return None
    t0 = time.perf_counter()
    system, rec = system_and_record(lin, record)
    if not getattr(system, "linear_time_invariant", False):  # a data default that names another model
        log.warning("linear_system names %s, not a linear model: nothing fitted beside", system.name)
        return None
    split = rec.meta.split
    fitted = rec.segment(*split.fit) if hold_out and split is not None else rec
    start = start_from_data(fitted, system)
    try:
        fit = fit_output_error(fitted, system, None if start is None else start.values)
    except (ValueError, RuntimeError, FloatingPointError) as exc:
        log.warning("the linear model of the same layout could not be fitted beside it: %s", exc)
        return None
    out = {
        "system": system.name,
        "params": {k: float(v) for k, v in fit.params.items()},
        "start": "data" if start is not None else "config",
        "cost": float(fit.cost),
        "seconds": time.perf_counter() - t0,
    }
    log.info(
        "the linear model of the same layout, beside it (output error from the data's start, %.1f s): %s",
        out["seconds"],
        ", ".join(f"{k}={v:.5g}" for k, v in out["params"].items()),
    )
    return out


def linear_model(cfg: DictConfig, metrics: dict[str, Any]) -> tuple[DictConfig, dict[str, float]] | None:
    """A finished run's linear model beside it: (its config, its values), or None."""
    lin = linear_config(cfg)
    saved = metrics.get("linear_model")
    if lin is None or not saved:
        return None
    return lin, dict(saved["params"])
