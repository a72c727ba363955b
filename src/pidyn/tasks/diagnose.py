"""The diagnosis task: the subject from the config, the loop run (``pidyn.discrepancy.loop``),
``diagnosis.json``, ``report.md``, figures.

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
from pidyn.data.sources import Record
from pidyn.discrepancy import loop
from pidyn.discrepancy.loop import Inputs, Subject
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.subjects import subject_for
from pidyn.discrepancy.writer import write_diagnosis
from pidyn.runs.build import build_record, instantiate
from pidyn.runs.folder import is_complete, run_folder
from pidyn.runs.methods import refine_plan
from pidyn.tasks.train import identify as train_identify

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
    subject = compose_subject(cfg, record)
    result = loop.diagnose(subject)
    diagnosis = write_diagnosis(subject, result, time.perf_counter() - t_wall)
    log.info("run folder %s (%.0f s)", subject.run_dir, diagnosis["wall_seconds"])
    return diagnosis


def compose_subject(cfg: DictConfig, record: Record | None = None) -> Subject:
    """The subject that diagnoses ``cfg.system`` (``pidyn.discrepancy.subjects``), composed from the
    settings, the record (default: built from ``cfg.data``) and this layer's identification."""
    settings = DiagnosisSettings.from_mapping(OmegaConf.to_container(cfg.diagnosis, resolve=True))  # type: ignore[arg-type]
    system = instantiate(cfg.system)
    subject = subject_for(system)
    node = OmegaConf.to_container(cfg.system, resolve=True)
    assert isinstance(node, dict)

    def identify(rec: Record, system_node: dict, folder: Path, fit: tuple[float, float]):
        metrics, obj = train_identify(_sub_cfg(cfg, system_node, folder, fit), rec)
        return metrics, obj["system"], obj["module"].net.params.as_floats()

    def refine_settings():
        plan = refine_plan(cfg)
        return None if plan is None else plan[2]

    inputs = Inputs(
        settings=settings,
        system_node=node,
        make_system=lambda **kw: instantiate(cfg.system, **kw),
        read_record=lambda s: build_record(cfg, s),
        record=record,
        mass=cfg.data.get("mass", 1.0),
        run_dir=Path(cfg.paths.output_dir),
        identify=identify,
        refine_settings=refine_settings,
        start=str(cfg.model.get("start", "auto")),
    )
    return subject.compose(system, inputs)


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
