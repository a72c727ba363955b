"""A run's objects built from its config: the system, the record, the windows, PIDynNet, the
callbacks, the trainer factory. Every object with a ``_target_`` is instantiated here and nowhere
else."""

from __future__ import annotations

import inspect
import logging
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import hydra
import lightning as L
import torch
from hydra.errors import InstantiationException
from omegaconf import DictConfig, OmegaConf, open_dict

from pidyn.config import user_settings
from pidyn.data.checks import check_floors, check_record
from pidyn.data.datamodule import SubperiodDataModule
from pidyn.data.multi import concatenate, pieces
from pidyn.data.sources import Record
from pidyn.models.identify import SubperiodIdentifier
from pidyn.models.lit_module import PIDynNetModule
from pidyn.models.pidynnet import PIDynNet
from pidyn.models.schedule import Schedule
from pidyn.parallel import set_workers
from pidyn.reporting import write_json
from pidyn.runs.methods import check_method_names
from pidyn.runs.runtime import in_multirun, quiet_framework_warnings
from pidyn.starts.data import DATA_SCALES, structure_scale
from pidyn.starts.policy import start_policy
from pidyn.systems.base import StructuralSystem

log = logging.getLogger(__name__)


def instantiate(node: DictConfig, **kwargs: Any) -> Any:
    """``hydra.utils.instantiate``, with a user's error (a bad value, a bad file, a missing channel)
    coming out as itself, not wrapped in Hydra's instantiation error, so it is named as such."""
    try:
        return hydra.utils.instantiate(node, **kwargs)
    except InstantiationException as exc:
        if isinstance(exc.__cause__, (ValueError, FileNotFoundError)):
            raise exc.__cause__ from None
        raise


#: a data group's list of records -> the source's setting each of them sets (``data.paths=[...]``)
MANY = {"paths": "path", "runs": "run"}


def build_record(cfg: DictConfig, system: StructuralSystem) -> Record:
    """The record from ``cfg.data.source`` (``instantiate``), or the records of ``data.paths`` /
    ``data.runs`` laid end to end (``pidyn.data.multi``): one structure, several earthquakes."""
    for many, one in MANY.items():
        values = OmegaConf.select(cfg, f"data.{many}", default=None)
        if values is None:
            continue
        if isinstance(values, str) or not OmegaConf.is_list(values) or not len(values):
            raise ValueError(
                f"data.{many} must be a non-empty list, e.g. 'data.{many}=[A,B]'; got {values!r}"
            )
        if one not in cfg.data.source:
            raise ValueError(f"data.{many}: the source {cfg.data.source._target_} takes no '{one}'")
        records = []
        for value in values:
            node = cfg.data.source.copy()
            node[one] = value
            records.append(_one_record(node, system))
        log.info("identifying from %d records: %s", len(records), ", ".join(r.name for r in records))
        return concatenate(records, weighting=OmegaConf.select(cfg, "data.record_weighting", default=None))
    return _one_record(cfg.data.source, system)


def _one_record(node: DictConfig, system: StructuralSystem) -> Record:
    if "system" in _target_args(node):
        return instantiate(node, system=system)
    return instantiate(node)


def _target_args(node: DictConfig) -> set[str]:

    fn = hydra.utils.get_method(node._target_)
    return set(inspect.signature(fn).parameters)


@dataclass
class Run:
    """The objects of one run, built from the config before any training."""

    system: StructuralSystem
    record: Record
    module: PIDynNetModule
    ident: SubperiodIdentifier
    trainer_factory: Any
    logger: Any
    run_dir: Path
    start: Any = None  # the start read from the data (``pidyn.starts.data``), or None
    hold_out: bool = False  # identified on the record's fitting part; its held-out part judges the model
    linear_model: dict | None = None  # the linear model of the same layout fitted beside it (linear_beside)
    model_choice: dict | None = None  # which of the two its own records, each left out, predict better


def build_run(cfg: DictConfig, record: Record | None) -> Run:
    """Every object of a run from the config (each ``_target_`` instantiated here)."""
    quiet_framework_warnings()
    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        logging.getLogger(name).setLevel(logging.WARNING)
    check_method_names(cfg)
    run_dir = Path(cfg.paths.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(int(cfg.get("num_threads", 1)))
    set_workers(cfg.get("workers"))
    torch.set_default_dtype(torch.float64 if str(cfg.get("precision", "32")) == "64" else torch.float32)
    L.seed_everything(cfg.seed, workers=True, verbose=False)

    system, record = system_and_record(cfg, record)
    hold_out = _hold_out(cfg, record)
    system, start = data_start(cfg, system, record, run_dir)
    accel = system.excitation_as_acceleration(record.f) if cfg.model.excitation_transform else None
    dm: SubperiodDataModule = hydra.utils.instantiate(
        cfg.data.windows, record=record, data_seed=cfg.data_seed, accel_signal=accel
    )
    rpn = hydra.utils.instantiate(cfg.model.rpn, out_features=system.n_dof)
    lnn = hydra.utils.instantiate(cfg.model.lnn, out_features=system.n_latent) if system.n_latent else None
    core = PIDynNet(system, rpn, lnn, normalize_losses=cfg.model.normalize_losses)
    # the truth is the data's: none for measurements, the simulated values for synthetic data
    core.params.specs = [replace(s, true=(record.truth or {}).get(s.name)) for s in core.params.specs]
    module: PIDynNetModule = hydra.utils.instantiate(cfg.model.module, net=core)
    schedule = Schedule(**OmegaConf.to_container(cfg.model.schedule, resolve=True))  # type: ignore[arg-type]
    schedule = schedule.for_records(len(pieces(record)))
    clamp, stopper, extras = _callbacks(cfg)
    logger = hydra.utils.instantiate(cfg.logger) if cfg.get("logger") else None
    trainer_factory = _trainer_factory(cfg, logger)
    ident = SubperiodIdentifier(
        module, dm, trainer_factory, schedule, clamp, stopper, run_dir, extra_callbacks=extras
    )
    return Run(system, record, module, ident, trainer_factory, logger, run_dir, start, hold_out)


def system_and_record(cfg: DictConfig, record: Record | None) -> tuple[StructuralSystem, Record]:
    """The system and the record, checked against each other: the excitation, the inputs (a system
    with ``inputs: null`` takes the record's), the structure's scale where the config leaves it to
    the records (``starts.data.DATA_SCALES``), the truth in the system's own units."""
    unset = [k for k in DATA_SCALES if k in cfg.system and cfg.system[k] is None]
    # the record is read through the system's layout, which its scale does not change
    system: StructuralSystem = instantiate(cfg.system, **dict.fromkeys(unset, 1.0))
    record = build_record(cfg, system) if record is None else record
    if unset:
        scale = structure_scale(record)
        with open_dict(cfg):  # the run's own config, its record and every report say the values used
            for k in unset:
                cfg.system[k] = scale[k]
        system = instantiate(cfg.system)
    if record.excitation != system.excitation:
        raise ValueError(
            f"data '{record.name}' is {record.excitation}-excited but system '{system.name}' expects "
            f"'{system.excitation}' excitation: set system.excitation={record.excitation}"
        )
    if (
        record.n_inputs > 1
        and system.n_inputs == 1
        and OmegaConf.select(cfg, "system.inputs", default=1) is None
    ):
        system = hydra.utils.instantiate(
            cfg.system, inputs=record.inputs
        )  # the model takes the record's inputs
    check_inputs(system, record)
    check_record(record)
    check_floors(record, system.name, system.n_dof, getattr(system, "n_outputs", None))
    if record.truth and hasattr(system, "own_units"):  # masses unknown: the truth per kg of floor 1
        record = replace(record, truth=system.own_units(record.truth))
    return system, record


def _callbacks(cfg: DictConfig) -> tuple[Any, Any, list]:
    """The parameter clamp, the early stopping and any other configured callback."""
    clamp = hydra.utils.instantiate(cfg.callbacks.clamp) if cfg.callbacks.get("clamp") else None
    stopper = (
        hydra.utils.instantiate(cfg.callbacks.early_stopping) if cfg.callbacks.get("early_stopping") else None
    )
    extras = [
        hydra.utils.instantiate(node)
        for name, node in (cfg.get("callbacks") or {}).items()
        if name not in ("clamp", "early_stopping") and node is not None and "_target_" in node
    ]
    return clamp, stopper, extras


def _trainer_factory(cfg: DictConfig, logger: Any) -> Any:
    """A factory of Lightning trainers (one per window) sharing the run's logger."""
    # a redrawn bar only on a terminal; elsewhere LineProgress writes a line now and then
    progress = (
        bool(cfg.trainer.get("enable_progress_bar", True)) and sys.stdout.isatty() and not in_multirun()
    )

    def trainer_factory(**kw: Any) -> L.Trainer:
        kw.setdefault("enable_progress_bar", progress)
        return hydra.utils.instantiate(cfg.trainer, logger=logger if logger is not None else False, **kw)

    return trainer_factory


def _hold_out(cfg: DictConfig, record: Record) -> bool:
    """``data.hold_out``: identify on the record's own fitting part (``meta.split``) only, and
    report the held-out part (the windows and the refinement end where the fitting part does)."""
    if not cfg.data.get("hold_out", False):
        return False
    split = record.meta.split
    if not split:
        raise ValueError(f"data.hold_out is set but record '{record.name}' has no fitting / held-out split")
    with open_dict(cfg):
        cfg.data.windows.t_end = float(split.fit[1])
    log.info("identifying on %.4g-%.4g s; %.4g-%.4g s held out", *split.fit, *split.heldout)
    return True


def data_start(
    cfg: DictConfig, system: StructuralSystem, record: Record, run_dir: Path
) -> tuple[StructuralSystem, Any]:
    """``model.start`` (see ``pidyn.starts.policy.start_policy``); the start goes to data_start.json."""
    keys = named_params(user_settings(), cfg.system.get("params"))
    system, start, used = start_policy(str(cfg.model.get("start", "auto")), system, record, keys)
    if start is not None:
        write_json(run_dir / "data_start.json", {**start.to_dict(), "used_by_pidynnet": used})
    return system, start


def named_params(keys: list[str], params: Any) -> list[str]:
    """``system.params={gain1: {trainable: false}}`` given whole sets the parameters it names, not
    every parameter's start: the key becomes ``system.params.<name>`` for each."""
    if "system.params" not in keys or not params:
        return keys
    return [k for k in keys if k != "system.params"] + [f"system.params.{n}" for n in params]


def check_inputs(system: StructuralSystem, record: Record) -> None:
    """A record with several inputs needs a system with as many (and the other way round)."""
    if record.n_inputs != system.n_inputs:
        names = record.inputs or [f"{record.n_inputs} column(s)"]
        raise ValueError(
            f"data '{record.name}' has {record.n_inputs} input(s) {names} but system '{system.name}' "
            f"takes {system.n_inputs}: set system.inputs={record.inputs or 'null'}"
        )
