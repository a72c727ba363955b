"""The prediction task: ``python predict.py run=RUN data=csmip data.path=C.zip data.station=CE89324
data.direction=transverse`` predicts the record with the model of the run folder ``RUN``
(``pidyn.runs.prediction``) and writes ``prediction.json`` and ``figures/prediction.png``.

The plain simulation is the prediction. ``physics_only=true`` adds the paper's Eq. 14 beside it:
fresh networks trained on the physics alone with the run's parameters held
(``pidyn.runs.physics_only``), where the model takes one ground acceleration.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from pidyn.config import check_settings
from pidyn.notes import note
from pidyn.reporting import write_json
from pidyn.runs.folder import run_folder
from pidyn.runs.physics_only import physics_only
from pidyn.runs.prediction import Identified, figure, predict_record, score

log = logging.getLogger(__name__)

#: what a finished prediction claims
RESULT_FILES = ("prediction.json",)


def predict(cfg: DictConfig) -> dict[str, Any]:
    """Predict the record of ``cfg.data`` with the model of the run ``cfg.run``; returns prediction.json's content."""
    with run_folder(cfg, "predict", claims=RESULT_FILES) as folder:
        return predict_in(cfg, folder)


def predict_in(cfg: DictConfig, folder: Path) -> dict[str, Any]:

    check_settings(cfg)
    if cfg.get("run") is None:
        raise ValueError("run=RUN is needed: the run folder of the identification whose model predicts")
    if cfg.get("data") is None:
        raise ValueError(
            "the record to predict is needed: data=csmip data.path=C.zip (or data=xsens, data=csv)"
        )
    own = Identified.load(cfg.run)
    run = own.chosen()  # the linear model beside it, where the run's own records chose it
    system, record, values = run.for_record(cfg.data)
    linear_run = Identified.load(cfg.linear_run) if cfg.get("linear_run") else None
    out, sim = predict_record(run, record, system, values, linear_run, cfg.data)
    if run is not own:
        own_system, _, own_values = own.for_record(record=record)
        out["nonlinear_mean_nrmse_a"] = score(own_system, own_values, record)["mean_nrmse_a"]
        log.warning(
            "the run's own records chose its linear model (model_choice): %s predicts; its nonlinear model "
            "would have scored mean NRMSE %s",
            run.metrics.get("system"),
            _fmt(out["nonlinear_mean_nrmse_a"]),
        )
    if cfg.get("physics_only"):
        entry = physics_only(run.cfg, system, values, record, sim, cfg.physics)
        out["physics_only"] = {k: v for k, v in entry.items() if k != "response"}
        log.info("physics-only networks (Eq. 14): %s", _physics_text(out["physics_only"]))
    write_json(folder / "prediction.json", out)
    figure(folder / "figures" / "prediction.png", record, sim, run, out)
    _log(out)
    return out


def _log(out: dict[str, Any]) -> None:
    mean = out["mean_nrmse_a"]
    per = ", ".join(f"{k} {v:.3g}" for k, v in out["nrmse"].items())
    log.info(
        "predicted %s with the model of %s: NRMSE %s (mean %s)", out["record"], out["run"], per, _fmt(mean)
    )
    log.info("knowing nothing (%s): mean NRMSE %s", out["trivial"], _fmt(out["trivial_mean_nrmse_a"]))
    if out["seen_by_run"]:
        log.warning(
            "%s is one of the records the run was identified on: this is a fit, not a prediction",
            out["record"],
        )
    if out.get("model_adequate") is False:
        log.warning(
            note(
                "model_rejected_by_its_records",
                f"THE MODEL THAT PREDICTS DOES NOT DESCRIBE THE RECORDS IT WAS IDENTIFIED ON "
                f"({'; '.join(out['model_rejected_because']) or 'its run says so'}): this prediction is of a "
                "model the data reject, whatever it scores here",
            )
        )
    if out.get("beyond_training") is not None:
        lo, hi = out["training_pga"]
        log.warning(
            note(
                "beyond_training_amplitude",
                f"{out['record']}: its peak input acceleration {out['pga']:.3g} m/s^2 is {out['beyond_training']:.3g} "
                f"times the {'strongest' if out['beyond_training'] > 1 else 'weakest'} of the run's records "
                f"({lo:.3g}-{hi:.3g} m/s^2): the model is extrapolated to this shaking",
            )
        )
    if out.get("model_choice_decisive") is False:
        log.warning(
            note(
                "model_choice_undecided",
                f"{out['system']} predicts, but the run's own records, each left out, could not tell it "
                "from its other model (metrics.json model_choice): the other would have done about as well",
            )
        )
    if out["beats_trivial"] is False:
        log.warning(
            "THE MODEL PREDICTS THIS RECORD NO BETTER THAN KNOWING NOTHING (%s): its prediction is not to be used",
            out["trivial"],
        )


def _physics_text(entry: dict[str, Any]) -> str:
    if not entry.get("applies"):
        return f"not applicable: {entry['why']}"
    return f"mean NRMSE {_fmt(entry['mean_nrmse_a'])} in {entry['seconds']:.0f} s"


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.3g}"
