"""The diagnosis task: the subject from the config, the loop run (``pidyn.discrepancy.loop``),
``diagnosis.json``, ``report.md``, figures.

The nominal and extended identifications are ordinary PIDynNet runs in ``nominal/`` and
``extended/``, each with its resolved ``config.yaml``.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
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
from pidyn.parallel import set_workers
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
    set_workers(cfg.get("workers"))  # before the subject: its supports' fits share the cores
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
        metrics, obj = train_identify(SubRun(system_node, folder, fit).config(cfg), rec)
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


@dataclass
class SubRun:
    """One identification inside the diagnosis, as the loop asks for it: the model (a system
    node), its run folder and fitting span. The rest is how the diagnosis identifies: PIDynNet
    alone (the diagnosis polishes by output error itself, ``diagnosis.polish``), no baselines (the
    screening is their peer), started where the diagnosis puts it (the weak form, then each step's
    estimate: ``model.start=config``) and with the diagnosis's least-squares start; its figures
    only with ``subrun_figures`` (the diagnosis draws both models in its own)."""

    system: dict
    folder: Path
    fit: tuple[float, float]

    def config(self, cfg: DictConfig) -> DictConfig:
        """The sub-run's config: the diagnosis's, with this run's model, folder and span (saved in
        the folder as ``config.yaml``)."""
        own: dict[str, Any] = {
            "paths": {"output_dir": str(self.folder)},
            "baselines": {"run": [], "cramer_rao": False},
            "model": {"refine": {"method": "none"}, "start": "config"},
            "figures": bool(cfg.get("subrun_figures", False)),
        }
        if cfg.diagnosis.get("ls_init") is not None:
            own["model"]["schedule"] = {"ls_init": cfg.diagnosis.ls_init}
        c = OmegaConf.merge(cfg, own)
        assert isinstance(c, DictConfig)
        with open_dict(c):
            c.system = self.system  # a model replaces the config's whole, it is not merged into it
            # the span is set on the windows the data's node points to (a CSV's is an interpolation,
            # which a merge would replace by the span alone)
            c.data.windows.t_start, c.data.windows.t_end = self.fit
        self.folder.mkdir(parents=True, exist_ok=True)
        OmegaConf.save(c, self.folder / "config.yaml", resolve=False)
        return c
