"""Which model a run from several records stands behind: its own nonlinear model, or the linear
model of the same layout fitted beside it (``linear_beside``), chosen by how each predicts the
run's records that it was not fitted to.

The records are split into folds (each record by itself where there are few). For each fold both
models are refitted by output error on the other records, and each fold's records are simulated
from rest under their own input motions, as ``predict.py`` does with a record the run never saw.
The refits start where nothing of the left-out records has been (``start: data``): the linear
model from the other records' own data start, the nonlinear model from that linear fit with its
own terms at the config's start. Started from the run's values (``start: run``), fitted to every
record, a refit of a few evaluations keeps much of what the left-out records taught it, and the
model with more terms keeps more. The nonlinear model is kept when its mean NRMSE over those
predictions is below the linear model's; otherwise the run says its nonlinear terms did not earn
their place on its own records, and its predictions use the linear model. The mean, not the
median: a model that fails badly on one unseen record is the one not to hand on. The choice
looks at the run's own records only; nothing of a record to be predicted enters it.

Whether the records can tell the two models apart at all is said beside the choice: the mean of
the paired log ratios ln(NRMSE_nonlinear / NRMSE_linear) over the left-out records and its
standard error. Within two standard errors of 0 the choice is ``decisive: false`` (a note says
so): a run of four records, or of a direction where both models predict alike, chooses by a coin,
and a prediction with the other model would do as well.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from omegaconf import DictConfig

from pidyn.data.multi import concatenate, pieces, split
from pidyn.data.sources import Record
from pidyn.notes import note
from pidyn.params import fixed_values
from pidyn.refine.output_error import fit_output_error
from pidyn.runs.build import system_and_record
from pidyn.runs.linear_beside import linear_config
from pidyn.runs.prediction import score
from pidyn.starts.data import start_from_data
from pidyn.systems.base import StructuralSystem

log = logging.getLogger(__name__)

NONLINEAR, LINEAR = "nonlinear", "linear"
#: where a fold's refits start (``ChoiceSettings.start``)
STARTS = ("data", "run")


@dataclass(frozen=True)
class ChoiceSettings:
    """``model_choice``: the folds (at most; fewer records: one a fold) and each refit's budget."""

    enabled: bool = True
    folds: int = 5
    max_nfev: int = 20
    #: where each refit starts: ``data`` (nothing of the left-out records) or ``run`` (the run's values)
    start: str = "data"

    @classmethod
    def of(cls, node: Any) -> ChoiceSettings:
        """From the config's ``model_choice`` (None: the defaults); a key it does not know is named."""
        values = dict(node or {})
        unknown = sorted(set(values) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(
                f"model_choice: unknown setting(s) {unknown}; known: {', '.join(f.name for f in fields(cls))}"
            )
        out = cls(**values)
        if out.start not in STARTS:
            raise ValueError(f"model_choice.start: '{out.start}' is not one of {list(STARTS)}")
        return out


def fold_indices(n: int, folds: int) -> list[list[int]]:
    """Record i in fold i mod k, k = min(n, folds): every record is left out once."""
    k = max(1, min(n, int(folds)))
    return [list(range(j, n, k)) for j in range(k)]


def choose_model(
    cfg: DictConfig,
    system: StructuralSystem,
    record: Record,
    values: dict[str, float],
    linear: dict[str, Any] | None,
    settings: ChoiceSettings | None = None,
    hold_out: bool = False,
) -> dict[str, Any] | None:
    """metrics.json's ``model_choice``: the chosen model, both means and every left-out record's
    NRMSE; None where there is nothing to choose (one record, no linear model beside, off)."""
    settings = settings or ChoiceSettings()
    records = fitting_records(record, hold_out)
    lin_cfg = linear_config(cfg)
    if not settings.enabled or linear is None or lin_cfg is None or len(records) < 2:
        return None
    t0 = time.perf_counter()
    lin_system, _ = system_and_record(lin_cfg, record)
    lin_values = {**fixed_values(lin_system), **linear["params"]}
    rows = []
    for held in fold_indices(len(records), settings.folds):
        train = concatenate([r for i, r in enumerate(records) if i not in held])
        fits = _fold_fits(train, (system, values), (lin_system, lin_values), settings)
        for i in held:
            row = {"record": records[i].name}
            for key, model in ((NONLINEAR, system), (LINEAR, lin_system)):
                row[key] = _scored(model, fits[key], records[i])
            rows.append(row)
            log.info(
                "left out %s: NRMSE %.3g with the nonlinear model, %.3g with the linear one (fitted on the others)",
                row["record"],
                row[NONLINEAR],
                row[LINEAR],
            )
    return _decide(system.name, lin_system.name, rows, time.perf_counter() - t0)


def fitting_records(record: Record, hold_out: bool) -> list[Record]:
    """The run's records, each by itself; where the run held out the end of its last record
    (``hold_out``), that record up to its fitting part's end: the held-out part judges the run
    afterwards and takes no part in choosing its model."""
    records = split(record)
    fit = record.meta.split.fit if hold_out and record.meta.split is not None else None
    if fit is not None and len(records) > 1:
        records[-1] = records[-1].segment(None, fit[1] - pieces(record)[-1].t_offset)
    return records


def _fold_fits(
    train: Record,
    nonlinear: tuple[StructuralSystem, dict[str, float]],
    linear: tuple[StructuralSystem, dict[str, float]],
    settings: ChoiceSettings,
) -> dict[str, dict[str, float] | None]:
    """Both models refitted on a fold's training records. ``start: run``: each from the run's
    values. ``start: data``: the linear model from these records' data start (its config's
    where they show no resonance), the nonlinear one from that fit for the names both models
    share and from its config for its own terms; the values neither fits (a scale, the mass)
    are the run's."""
    (system, values), (lin_system, lin_values) = nonlinear, linear
    if settings.start == "run":
        return {
            NONLINEAR: _refit(train, system, values, settings.max_nfev),
            LINEAR: _refit(train, lin_system, lin_values, settings.max_nfev),
        }
    start = start_from_data(train, lin_system)
    lin_start = {**lin_values, **_spec_starts(lin_system), **({} if start is None else start.values)}
    lin_fit = _refit(train, lin_system, lin_start, settings.max_nfev)
    shared = {} if lin_fit is None else {k: v for k, v in lin_fit.items() if k in _trainable(system)}
    own = {**values, **_spec_starts(system), **shared}
    return {NONLINEAR: _refit(train, system, own, settings.max_nfev), LINEAR: lin_fit}


def _trainable(system: StructuralSystem) -> set[str]:
    return {s.name for s in system.param_specs() if s.trainable}


def _spec_starts(system: StructuralSystem) -> dict[str, float]:
    """The trainable parameters' starts as the config gives them (no record has informed them)."""
    return {s.name: float(s.init) for s in system.param_specs() if s.trainable}


def _refit(
    train: Record, system: StructuralSystem, values: dict[str, float], max_nfev: int
) -> dict[str, float] | None:
    """The model's values refitted on ``train`` from ``values`` (None: the fit failed)."""
    try:
        fit = fit_output_error(train, system, values, max_nfev=max_nfev)
    except (ValueError, RuntimeError, FloatingPointError, np.linalg.LinAlgError) as exc:
        log.warning("%s could not be refitted without the left-out records: %s", system.name, exc)
        return None
    return {**values, **fit.params}


def _scored(system: StructuralSystem, values: dict[str, float] | None, record: Record) -> float:
    """Mean NRMSE of the record's accelerations simulated from rest (inf: no fit, or it blew up)."""
    if values is None:
        return float("inf")
    with np.errstate(all="ignore"):
        mean = score(system, values, record)["mean_nrmse_a"]
    return float(mean) if mean is not None and np.isfinite(mean) else float("inf")


def paired_ratio(rows: list[dict]) -> dict[str, Any]:
    """The mean paired log ratio ln(NRMSE_nonlinear / NRMSE_linear) over the left-out records, its
    standard error, and whether it lies more than two standard errors from 0 (``decisive``). A
    record one model could not predict at all (inf) decides against that model."""
    nl = np.array([r[NONLINEAR] for r in rows], dtype=float)
    li = np.array([r[LINEAR] for r in rows], dtype=float)
    one_failed = np.isinf(nl) != np.isinf(li)
    if one_failed.any():
        return {"log_ratio": None, "log_ratio_se": None, "decisive": True}
    ok = np.isfinite(nl) & np.isfinite(li) & (nl > 0) & (li > 0)
    d = np.log(nl[ok] / li[ok])
    if d.size < 2:
        return {"log_ratio": None, "log_ratio_se": None, "decisive": False}
    mean, se = float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))
    return {"log_ratio": mean, "log_ratio_se": se, "decisive": bool(abs(mean) > 2 * se)}


def _decide(nonlinear: str, linear: str, rows: list[dict], seconds: float) -> dict[str, Any]:
    means = {key: float(np.mean([r[key] for r in rows])) for key in (NONLINEAR, LINEAR)}
    kept = means[NONLINEAR] < means[LINEAR]
    chosen = NONLINEAR if kept else LINEAR
    better = sum(r[NONLINEAR] < r[LINEAR] for r in rows)
    out = {
        "chosen": chosen,
        "system": nonlinear if kept else linear,
        "rule": "the lower mean NRMSE of the accelerations over the run's records, each predicted by "
        "the model refitted without it (from rest, its own input motions)",
        "mean_nrmse_a": means,
        "nonlinear_better": f"{better} of {len(rows)}",
        **paired_ratio(rows),
        "records": rows,
        "seconds": seconds,
    }
    text = (
        f"the run's records, each left out and predicted: mean NRMSE {means[NONLINEAR]:.3g} with {nonlinear}, "
        f"{means[LINEAR]:.3g} with {linear} (the nonlinear model better on {better} of {len(rows)})"
    )
    if kept:
        log.info("%s: the nonlinear model is kept", text)
    else:
        out["note"] = note(
            "nonlinear_not_earned",
            f"{text}: its nonlinear terms do not predict records it was not fitted to better; "
            f"predictions use {linear}",
        )
        log.warning(out["note"])
    if not out["decisive"]:
        out["undecided"] = note("model_choice_undecided", _undecided_text(out, nonlinear, linear, len(rows)))
        log.warning(out["undecided"])
    return out


def _undecided_text(out: dict[str, Any], nonlinear: str, linear: str, n: int) -> str:
    ratio = out["log_ratio"]
    if ratio is None:
        return f"{n} record(s) left out cannot tell {nonlinear} from {linear}: the choice is a coin"
    lo, hi = np.exp(ratio - 2 * out["log_ratio_se"]), np.exp(ratio + 2 * out["log_ratio_se"])
    return (
        f"the {n} left-out records cannot tell {nonlinear} from {linear}: its NRMSE is {np.exp(ratio):.3g} "
        f"times the linear model's ({lo:.3g}-{hi:.3g} at two standard errors); the choice of "
        f"{out['system']} is a coin, and the other model would predict as well"
    )
