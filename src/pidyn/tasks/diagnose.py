"""The diagnosis task: the case from the config, the loop run, ``diagnosis.json``, ``report.md``, figures.

The nominal and extended identifications are ordinary PIDynNet runs in ``nominal/`` and
``extended/``, each with its resolved ``config.yaml``.
"""

from __future__ import annotations

import copy
import json
import logging
import time
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from pidyn.config import check_settings
from pidyn.data.checks import check_floors, check_record
from pidyn.data.sources import Record
from pidyn.discrepancy import pipeline
from pidyn.discrepancy.accelerometers import motion_view, needs_view
from pidyn.discrepancy.case import Case, check_diagnosable, prepare, split_spans
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.summary import log_verdict, summarize, write_figures
from pidyn.reporting import write_json
from pidyn.runs.build import build_record, instantiate
from pidyn.runs.folder import is_complete, run_folder
from pidyn.tasks.train import identify

log = logging.getLogger(__name__)


def diagnose(cfg: DictConfig, record: Record | None = None) -> dict[str, Any]:
    """What the nominal model ``cfg.system`` misses on ``record`` (default: built from
    ``cfg.data``); writes diagnosis.json, report.md and figures to the run folder."""
    folder = Path(cfg.paths.output_dir)
    if record is None and cfg.get("skip_done", False) and is_complete(folder):  # a sweep resumed: finished
        log.info("%s holds this diagnosis (skip_done): not run again", folder)
        return json.loads((folder / "diagnosis.json").read_text())
    with run_folder(cfg, "diagnose", claims=("diagnosis.json", "report.md")):
        return _diagnose(cfg, record)


def _diagnose(cfg: DictConfig, record: Record | None) -> dict[str, Any]:
    t_wall = time.perf_counter()
    check_settings(cfg)
    if cfg.system.get("n_storeys") is not None:  # a shear building: storey by storey
        return diagnose_building_task(cfg, record)
    if cfg.system.get("support_terms", "absent") != "absent":  # a bridge's supports, one by one
        raise ValueError("a bridge's diagnosis support by support is not built yet: diagnose system=linear")
    case = compose_case(cfg, record)
    outcome = pipeline.run(case)
    diagnosis = summarize(case, outcome)
    diagnosis["wall_seconds"] = time.perf_counter() - t_wall
    write_json(case.run_dir / "diagnosis.json", diagnosis)
    write_figures(case, outcome, diagnosis)
    log_verdict(diagnosis)
    log.info("run folder %s (%.0f s)", case.run_dir, diagnosis["wall_seconds"])
    return diagnosis


def diagnose_building_task(cfg: DictConfig, record: Record | None = None) -> dict[str, Any]:
    """A shear building's diagnosis (``pidyn.discrepancy.storeys``), written to the run folder."""
    from dataclasses import replace

    from pidyn.discrepancy.case import split_spans
    from pidyn.discrepancy.storey_report import report_lines, summarize_building, write_building_figures
    from pidyn.discrepancy.storeys import diagnose_building
    from pidyn.runs.methods import refine_plan

    settings = DiagnosisSettings.from_mapping(OmegaConf.to_container(cfg.diagnosis, resolve=True))  # type: ignore[arg-type]
    system = instantiate(cfg.system)
    record = build_record(cfg, system) if record is None else record
    check_record(record)
    check_floors(record, system.name, system.n_dof)
    plan = refine_plan(cfg)
    if plan is None:
        raise ValueError(
            "diagnose: a building's diagnosis refines every model; model.refine=none is not possible"
        )
    # no networks here: the segments start from the accelerations integrated twice
    refine_settings = replace(plan[2], states="integrated")
    run_dir = Path(cfg.paths.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    start, chosen = None, str(cfg.model.get("start", "auto"))
    if chosen not in ("auto", "data", "config"):  # model.start=<an earlier run's folder>
        from pidyn.baselines.start_policy import start_from_run

        start = start_from_run(chosen, system).values
    d = diagnose_building(record, system, settings, refine_settings, start, run_dir)
    fit, held = split_spans(record, float(settings.fit_share))
    out = summarize_building(record, system, d, fit, held, settings.thresholds)
    write_json(run_dir / "diagnosis.json", out)
    (run_dir / "report.md").write_text("\n".join(report_lines(out)) + "\n")
    write_building_figures(run_dir, d)
    log_verdict(out)
    log.info("run folder %s (%.0f s)", run_dir, out["wall_seconds"])
    return out


def compose_case(cfg: DictConfig, record: Record | None = None) -> Case:
    """The settings, the nominal system, the record and the identification the pipeline calls."""
    settings = DiagnosisSettings.from_mapping(OmegaConf.to_container(cfg.diagnosis, resolve=True))  # type: ignore[arg-type]
    base = instantiate(cfg.system)
    check_diagnosable(base)
    record = build_record(cfg, base) if record is None else record
    check_record(record)
    if record.excitation != base.excitation:
        base = instantiate(cfg.system, excitation=record.excitation)
    if needs_view(record):  # accelerometers: the relative motion the screening needs, from the accelerations
        full = instantiate(cfg.system, inputs=record.inputs) if record.n_inputs > 1 else base
        fit = split_spans(record, float(settings.fit_share))[0]
        record = motion_view(record, full, fit, tol=float(settings.polish_tol))
    node = OmegaConf.to_container(cfg.system, resolve=True)
    assert isinstance(node, dict)

    def run_identification(system_node: dict, folder: Path, fit: tuple[float, float]):
        metrics, obj = identify(_sub_cfg(cfg, system_node, folder, fit), record)
        return metrics, obj["system"], obj["module"].net.params.as_floats()

    return prepare(
        record,
        base,
        node,
        settings,
        cfg.data.get("mass", 1.0),
        Path(cfg.paths.output_dir),
        run_identification,
    )


def _sub_cfg(cfg: DictConfig, system_node: dict, out_dir: Path, fit: tuple[float, float]) -> DictConfig:
    """The config of one identification inside the diagnosis (saved in its folder)."""
    c = copy.deepcopy(cfg)
    with open_dict(c):
        c.system = system_node
        c.paths.output_dir = str(out_dir)
        c.data.windows.t_start = fit[0]
        c.data.windows.t_end = fit[1]
        c.baselines = {"run": [], "cramer_rao": False}
        c.model.refine = {
            "method": "none"
        }  # the diagnosis polishes with output error itself (diagnosis.polish)
        c.model.start = "config"  # the diagnosis gives its own start (weak form, then each step's estimate)
        if cfg.diagnosis.get("ls_init") is not None:
            c.model.schedule.ls_init = cfg.diagnosis.ls_init
    out_dir.mkdir(parents=True, exist_ok=True)
    OmegaConf.save(c, out_dir / "config.yaml", resolve=False)
    return c
