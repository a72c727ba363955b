"""Generalisation (paper Figures 4-5): identify on the first seconds of a record, then
predict the response to unseen excitations by physics-only fine-tuning, beside the plain
simulation of the identified model. The parts live in ``pidyn.runs.generalization``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from omegaconf import DictConfig

from pidyn.runs.generalization import (
    predict_case,
    prediction_settings,
    resume_rows,
    summarize,
    unseen_cases,
    write_outputs,
)
from pidyn.runs.report import tb_figures
from pidyn.tasks.train import identify

log = logging.getLogger(__name__)


def generalize(cfg: DictConfig) -> dict[str, Any]:
    """Identify, then predict every unseen case (resumed where a sweep stopped); returns the summary."""
    settings = prediction_settings(cfg.generalization)
    metrics, obj = identify(cfg)
    obj = {**obj, "identified": obj["module"].net.params.as_floats()}
    record, run_dir = obj["record"], Path(obj["run_dir"])
    cases = unseen_cases(cfg, cfg.excitation.record, float(np.max(np.abs(record.f))))
    rows = resume_rows(run_dir, cases) if cfg.get("resume", True) else []
    pred_dir = run_dir / "predictions"
    pred_dir.mkdir(exist_ok=True)
    for i, case in enumerate(cases):
        if i < len(rows):
            continue
        row = predict_case(cfg, obj, settings, i, case, pred_dir)
        rows.append(row)
        log.info(
            "[%d/%d] %s x%.3g t%.3g: gamma PIDynNet %.4f, simulation %.4f",
            i + 1,
            len(cases),
            case["record"],
            case["scale"],
            case["stretch"],
            row["gamma_pidynnet"],
            row["gamma_simulation"],
        )
        pd.DataFrame(rows).to_csv(run_dir / "generalization.csv", index=False)  # progress survives a crash
    df, summary = summarize(rows, metrics)
    write_outputs(run_dir, cfg, record, df, summary)
    tb_figures(obj["logger"], run_dir / "figures", int(obj["module"].iteration), {})
    log.info(
        "generalisation: %d cases, share gamma >= 0.95: PIDynNet %.2f, simulation %.2f",
        len(df),
        summary["share_gamma_ge_0.95_pidynnet"],
        summary["share_gamma_ge_0.95_simulation"],
    )
    return summary
