"""The training task: build a run from the config, identify, run the methods beside PIDynNet, report.

``train(cfg)`` is independent of ``@hydra.main`` so tests and scripts call it directly. The parts
live in ``pidyn.runs``: ``build`` (every ``_target_`` instantiated there), ``methods`` (baselines
and the refinement stage), ``report`` (what the run folder holds).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from pidyn.config import check_settings, choose_system
from pidyn.data.sources import Record
from pidyn.runs.build import build_run
from pidyn.runs.folder import is_complete, run_folder
from pidyn.runs.linear_beside import fit_linear_beside
from pidyn.runs.methods import run_baselines, run_refinement, start_baselines
from pidyn.runs.model_choice import ChoiceSettings, choose_model
from pidyn.runs.pidynnet_stop import behind_check
from pidyn.runs.report import final_values, write_report

log = logging.getLogger(__name__)

#: what a finished identification claims; a run that fails leaves none of them
RESULT_FILES = ("metrics.json", "identified_params.yaml", "refinement.json", "report.md", "modal.json")


def train(cfg: DictConfig) -> dict[str, Any]:
    """Identify the system's parameters from the configured data; returns the metrics."""
    folder = Path(cfg.paths.output_dir)
    if cfg.get("skip_done", False) and is_complete(folder):  # a sweep resumed: this run is finished
        log.info("%s holds this run's results (skip_done): not run again", folder)
        return json.loads((folder / "metrics.json").read_text())
    return identify_run(cfg)[0]


def identify_run(cfg: DictConfig, record: Record | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """``identify`` holding its run folder (``pidyn.runs.folder``): locked, the same run when
    resumed, ``complete.json`` when it finished, ``failed.json`` and no ``metrics.json`` when not."""
    choose_system(cfg)  # before the folder keeps the run's config
    with run_folder(cfg, "train", claims=RESULT_FILES):
        return identify(cfg, record)


def identify(cfg: DictConfig, record: Record | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Identify and report; returns (metrics, objects) with the module, system, record,
    trainer factory and run folder for follow-up tasks (prediction, diagnosis).

    ``record``: data already built from ``cfg.data.source`` (a caller that identifies
    several models on one record builds it once)."""
    t_wall = time.perf_counter()
    stages: dict[str, float] = {}  # where the time goes (metrics.json's stage_seconds, make bench)
    check_settings(choose_system(cfg))
    run = build_run(cfg, record)
    # the classical baselines need nothing from PIDynNet: they run beside it on another core
    pending = start_baselines(cfg, run.system, run.record, run.hold_out)
    t = _lap(stages, "build", t_wall)
    try:
        behind = behind_check(cfg, run.system, run.record, pending, run.start)
        results = run.ident.run(resume=cfg.get("resume", True), behind=behind)
    except BaseException:
        pending.cancel()
        raise
    t = _lap(stages, "pidynnet", t)
    # after PIDynNet: the baselines' results, then the refinement stage
    params = run.module.net.params
    pidyn_values = {n: params.as_floats()[n] for n in params.trainable_names}
    baselines = run_baselines(cfg, run.system, run.record, run.run_dir, params.as_floats(), pending)
    t = _lap(stages, "baselines_wait", t)
    refined = run_refinement(cfg, run.system, run.record, pidyn_values, baselines, results, run.start)
    t = _lap(stages, "refinement", t)
    run.linear_model = fit_linear_beside(cfg, run.record, run.hold_out)
    if run.linear_model is not None:
        t = _lap(stages, "linear_beside", t)
        run.model_choice = choose_model(
            cfg,
            run.system,
            run.record,
            final_values(run, refined, pidyn_values),
            run.linear_model,
            ChoiceSettings.of(cfg.get("model_choice")),
            run.hold_out,
        )
        if run.model_choice is not None:
            _lap(stages, "model_choice", t)
    metrics = write_report(cfg, run, results, pidyn_values, baselines, refined, t_wall, stages)
    objects = {
        "module": run.module,
        "system": run.system,
        "record": run.record,
        "trainer_factory": run.trainer_factory,
        "run_dir": run.run_dir,
        "logger": run.logger,
        "trajectory": run.ident.trajectory,
        "windows": [r.__dict__ for r in results],
    }
    return metrics, objects


def _lap(stages: dict[str, float], name: str, since: float) -> float:
    """Seconds since ``since`` as stage ``name``; returns now, the next stage's start."""
    now = time.perf_counter()
    stages[name] = now - since
    return now
