"""The training task: build everything from the config, identify, report.

``train(cfg)`` is independent of ``@hydra.main`` so tests and scripts call it directly.
Every object with a ``_target_`` is instantiated here and nowhere else.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import hydra
import lightning as L
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf, open_dict

from pidyn.baselines.worker import BaselineJob
from pidyn.data.datamodule import SubperiodDataModule
from pidyn.data.sources import Record
from pidyn.errors import errors_pct
from pidyn.models.identify import Schedule, SubperiodIdentifier
from pidyn.models.lit_module import PIDynNetModule
from pidyn.models.pidynnet import PIDynNet
from pidyn.reporting import (
    diverged,
    nrmse,
    param_table,
    plot_convergence,
    plot_response,
    write_json,
    write_yaml,
)
from pidyn.simulate import simulate_identified, simulate_response  # noqa: F401  (re-exported)
from pidyn.systems.base import StructuralSystem

log = logging.getLogger(__name__)


def build_record(cfg: DictConfig, system: StructuralSystem) -> Record:
    """The record from ``cfg.data.source``; a data error (a bad file, a missing channel) comes out as
    itself, not wrapped in Hydra's instantiation error, so it is named as such."""
    from hydra.errors import InstantiationException

    try:
        if "system" in _target_args(cfg.data.source):
            return hydra.utils.instantiate(cfg.data.source, system=system)
        return hydra.utils.instantiate(cfg.data.source)
    except InstantiationException as exc:
        if isinstance(exc.__cause__, (ValueError, FileNotFoundError)):
            raise exc.__cause__ from None
        raise


def _target_args(node: DictConfig) -> set[str]:
    import inspect

    fn = hydra.utils.get_method(node._target_)
    return set(inspect.signature(fn).parameters)


def train(cfg: DictConfig) -> dict[str, Any]:
    """Identify the system's parameters from the configured data; returns the metrics."""
    done = Path(cfg.paths.output_dir) / "metrics.json"
    if cfg.get("skip_done", False) and done.exists():  # a sweep resumed: this run is finished
        log.info("%s holds this run's results (skip_done): not run again", done.parent)
        return json.loads(done.read_text())
    return identify(cfg)[0]


def identify(cfg: DictConfig, record: Record | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Identify and report; returns (metrics, objects) with the module, system, record,
    trainer factory and run folder for follow-up tasks (prediction, diagnosis).

    ``record``: data already built from ``cfg.data.source`` (a caller that identifies
    several models on one record builds it once)."""
    t_wall = time.perf_counter()
    run = build_run(cfg, record)
    # the classical baselines need nothing from PIDynNet: they run beside it on another core
    pending = start_baselines(cfg, run.system, run.record, run.hold_out)
    try:
        results = run.ident.run(resume=cfg.get("resume", True))
    except BaseException:
        pending.cancel()
        raise
    # after PIDynNet: the baselines' results, then the refinement stage
    params = run.module.net.params
    pidyn_values = {n: params.as_floats()[n] for n in params.trainable_names}
    baselines = run_baselines(cfg, run.system, run.record, run.run_dir, params.as_floats(), pending)
    refined = run_refinement(cfg, run.system, run.record, pidyn_values, baselines, results, run.start)
    metrics = _report(cfg, run, results, pidyn_values, baselines, refined, t_wall)
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
    start: Any = None  # the start read from the data (``pidyn.baselines.data_start``), or None
    hold_out: bool = False  # identified on the record's fitting part; its held-out part judges the model


def build_run(cfg: DictConfig, record: Record | None) -> Run:
    """Every object of a run from the config (each ``_target_`` instantiated here)."""
    _quiet_framework_warnings()
    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        logging.getLogger(name).setLevel(logging.WARNING)
    check_method_names(cfg)
    run_dir = Path(cfg.paths.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(int(cfg.get("num_threads", 1)))
    torch.set_default_dtype(torch.float64 if str(cfg.get("precision", "32")) == "64" else torch.float32)
    L.seed_everything(cfg.seed, workers=True, verbose=False)

    system: StructuralSystem = hydra.utils.instantiate(cfg.system)
    record = build_record(cfg, system) if record is None else record
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
    if record.truth and hasattr(system, "own_units"):  # masses unknown: the truth per kg of floor 1
        record = replace(record, truth=system.own_units(record.truth))
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
    clamp = hydra.utils.instantiate(cfg.callbacks.clamp) if cfg.callbacks.get("clamp") else None
    stopper = (
        hydra.utils.instantiate(cfg.callbacks.early_stopping) if cfg.callbacks.get("early_stopping") else None
    )
    extras = [
        hydra.utils.instantiate(node)
        for name, node in (cfg.get("callbacks") or {}).items()
        if name not in ("clamp", "early_stopping") and node is not None and "_target_" in node
    ]
    logger = hydra.utils.instantiate(cfg.logger) if cfg.get("logger") else None
    # a redrawn bar only on a terminal; elsewhere LineProgress writes a line now and then
    progress = (
        bool(cfg.trainer.get("enable_progress_bar", True)) and sys.stdout.isatty() and not _in_multirun()
    )

    def trainer_factory(**kw: Any) -> L.Trainer:
        kw.setdefault("enable_progress_bar", progress)
        return hydra.utils.instantiate(cfg.trainer, logger=logger if logger is not None else False, **kw)

    ident = SubperiodIdentifier(
        module, dm, trainer_factory, schedule, clamp, stopper, run_dir, extra_callbacks=extras
    )
    return Run(system, record, module, ident, trainer_factory, logger, run_dir, start, hold_out)


def _hold_out(cfg: DictConfig, record: Record) -> bool:
    """``data.hold_out``: identify on the record's own fitting part (``meta['split']``) only, and
    report the held-out part (the windows and the refinement end where the fitting part does)."""
    if not cfg.data.get("hold_out", False):
        return False
    split = (record.meta or {}).get("split")
    if not split:
        raise ValueError(f"data.hold_out is set but record '{record.name}' has no fitting / held-out split")
    with open_dict(cfg):
        cfg.data.windows.t_end = float(split["fit"][1])
    log.info("identifying on %.4g-%.4g s; %.4g-%.4g s held out", *split["fit"], *split["heldout"])
    return True


def data_start(
    cfg: DictConfig, system: StructuralSystem, record: Record, run_dir: Path
) -> tuple[StructuralSystem, Any]:
    """``model.start`` (see ``pidyn.baselines.data_start.start_policy``); the start goes to data_start.json."""
    from pidyn.baselines.data_start import start_policy
    from pidyn.config import user_settings

    system, start, used = start_policy(str(cfg.model.get("start", "auto")), system, record, user_settings())
    if start is not None:
        write_json(run_dir / "data_start.json", {**start.to_dict(), "used_by_pidynnet": used})
    return system, start


def check_inputs(system: StructuralSystem, record: Record) -> None:
    """A record with several inputs needs a system with as many (and the other way round)."""
    if record.n_inputs != system.n_inputs:
        names = record.inputs or [f"{record.n_inputs} column(s)"]
        raise ValueError(
            f"data '{record.name}' has {record.n_inputs} input(s) {names} but system '{system.name}' "
            f"takes {system.n_inputs}: set system.inputs={record.inputs or 'null'}"
        )


def _report(
    cfg: DictConfig,
    run: Run,
    results: list,
    pidyn_values: dict[str, float],
    baselines: list[dict],
    refined: Any,
    t_wall: float,
) -> dict[str, Any]:
    """identified_params.yaml, metrics.json, refinement.json, windows.json, figures, TensorBoard, log."""
    system, record, run_dir = run.system, run.record, run.run_dir
    params = run.module.net.params
    names = params.trainable_names
    truths = {n: (record.truth or {}).get(n) for n in names}
    values = dict(refined.params) if refined is not None else dict(pidyn_values)
    final = {**params.as_floats(), **values}
    notes = [n for r in results for n in (r.notes or [])] + ([] if refined is None else refined.notes)
    units = {n: params.spec(n).unit for n in names}
    # the identified model simulated over the whole record (the physics-only check)
    sim = simulate_response(
        system, final, record, state0=None if refined is None else np.array(refined.initial_state)
    )
    notes += _divergence_note(sim)
    write_yaml(
        run_dir / "identified_params.yaml",
        identified_params(system, final, values, truths, units, refined, notes),
    )
    errors, pidyn_errors = relative_errors(values, truths), relative_errors(pidyn_values, truths)
    metrics: dict[str, Any] = {
        "system": system.name,
        "record": record.name,
        "noise": record_noise(cfg, record),
        "seed": int(cfg.seed),
        "data_seed": int(cfg.data_seed),
        "batch_size": int(cfg.batch_size),
        "eq_scale": float(cfg.eq_scale),
        "eq_stretch": float(cfg.eq_stretch),
        "refine": "none" if refined is None else "multiple_shooting",
        "params": values,
        "truth": truths,
        "error_pct": errors,
        "max_error_pct": max(errors.values()) if errors else None,
        "mean_error_pct": float(np.mean(list(errors.values()))) if errors else None,
        "pidynnet": {
            "params": pidyn_values,
            "error_pct": pidyn_errors,
            "max_error_pct": max(pidyn_errors.values()) if pidyn_errors else None,
        },
        "sim_nrmse_x": _sim_nrmse_x(sim, record),
        "sim_nrmse": channel_nrmse(sim, record),
        "notes": notes,
        "windows": len(results),
        "iterations": int(run.module.iteration),
    }
    if refined is not None:
        metrics.update(refined_metrics(refined, names, truths))
        write_json(run_dir / "refinement.json", refined.to_dict())
        torch.save(
            {"names": names, "values": values, "ci95": metrics["ci95"]},
            run_dir / "checkpoints" / "refined.pt",
        )
    if baselines:
        metrics["baselines"] = {
            b["method"]: {"error_pct": b.get("error_pct"), "seconds": b["seconds"]} for b in baselines
        }
    metrics["wall_seconds"] = time.perf_counter() - t_wall
    write_json(run_dir / "metrics.json", metrics)
    write_json(run_dir / "windows.json", {"windows": [r.__dict__ for r in results]})
    _assess(run, final, refined, sim, metrics)
    if hasattr(system, "storey_equations"):
        from pidyn.tasks.building_report import write_building_report

        modes = write_building_report(
            system,
            record,
            final,
            {**final, **truths} if any(truths.values()) else None,
            None if refined is None else np.array(refined.initial_state),
            run_dir,
            run.logger,
            int(run.module.iteration),
        )
        metrics["modes"] = {k: v for k, v in modes.items() if k != "truth"}
        write_json(run_dir / "metrics.json", metrics)
    _figures(run, results, truths, baselines, refined, sim, metrics)
    _log_summary(system.describe(final), errors, pidyn_errors, metrics, run_dir)
    return metrics


def _assess(
    run: Run, final: dict[str, float], refined: Any, sim: dict[str, np.ndarray], metrics: dict
) -> None:
    """modal.json and, on a record with a held-out part, how the model predicts it (``pidyn.assessment``)."""
    from pidyn.assessment import assess

    metrics.update(assess(run.system, run.record, final, refined, sim, run.hold_out, run.run_dir))
    write_json(run.run_dir / "metrics.json", metrics)


def _divergence_note(sim: dict[str, np.ndarray]) -> list[str]:
    """Says so when the identified model's simulation over the record blows up."""
    if not any(diverged(v) for v in sim.values()):
        return []
    note = (
        "the identified model diverges when simulated over the record (its response blows up): the estimate "
        "is not a usable model; start from a better guess (system.guess) or a classical estimate "
        "(model.refine.starts)"
    )
    log.warning(note)
    return [note]


def identified_params(
    system: StructuralSystem,
    final: dict[str, float],
    values: dict[str, float],
    truths: dict[str, float | None],
    units: dict[str, str],
    refined: Any,
    notes: list[str],
) -> dict:
    """The content of ``identified_params.yaml``: the equation, every estimated parameter with
    its interval (and its error when the truth is known), the notes, the correlations."""
    table = param_table(values, truths, units, None if refined is None else refined.intervals)
    out = {"system": system.name, "equation": system.describe(final), "params": table, "notes": notes}
    if hasattr(system, "storey_equations"):
        out["storey_equations"] = system.storey_equations(final)
    if not getattr(system, "mass_known", True):  # the records give the model up to one scale
        try:
            system.absolute_values(final)
        except ValueError as exc:
            out["absolute_values"] = str(exc)
    if refined is not None:
        out["correlation"] = {"names": refined.names, "matrix": refined.correlation}
        out["noise_std"] = refined.noise_std
    return out


def refined_metrics(refined: Any, names: list[str], truths: dict[str, float | None]) -> dict[str, Any]:
    out: dict[str, Any] = {
        "ci95": {n: refined.intervals[n]["ci95"] for n in names},
        "std": {n: refined.intervals[n]["std"] for n in names},
    }
    if truths and all(truths.values()):
        out["covered"] = {n: bool(out["ci95"][n][0] <= truths[n] <= out["ci95"][n][1]) for n in names}
    out["refinement"] = {
        k: v
        for k, v in refined.to_dict().items()
        if k not in ("params", "intervals", "correlation", "history")
    }
    if getattr(refined, "compared", None):
        out["refine_compare"] = refined.compared
    return out


def _figures(
    run: Run,
    results: list,
    truths: dict,
    baselines: list[dict],
    refined: Any,
    sim: dict[str, np.ndarray],
    metrics: dict,
) -> None:
    system, record = run.system, run.record
    fig_dir = run.run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    ukf = next((b for b in baselines if b["method"] == "ukf" and b.get("trajectory")), None)
    plot_convergence(
        fig_dir / "param_convergence.png",
        run.ident.trajectory,
        truths,
        [r.__dict__ for r in results],
        title=f"{system.name} under {record.name}",
        other=None if ukf is None else ("UKF", ukf["trajectory"]),
        final=None if refined is None else refined.intervals,
    )
    kind, meas = record.reference()
    floor = max(record.sensors()[kind])  # the highest measured floor moves the most
    label = f"{kind}{floor}" if system.n_dof > 1 else kind
    series = {
        f"measured {label}": meas[:, floor - 1],
        "identified model (simulated)": sim[kind][:, floor - 1],
    }
    plot_response(
        fig_dir / "response.png",
        record.t,
        series,
        title=f"{system.name}: NRMSE {metrics['sim_nrmse'][label]:.3g} ({label})",
    )
    tb_figures(run.logger, fig_dir, int(run.module.iteration), metrics, refined)


def _log_summary(equation: str, errors: dict, pidyn_errors: dict, metrics: dict, run_dir: Path) -> None:
    log.info("identified: %s", equation)
    if errors:
        log.info("errors (%%): %s", ", ".join(f"{k}={v:.3f}" for k, v in errors.items()))
        if "ci95" in metrics:
            log.info("PIDynNet alone (%%): %s", ", ".join(f"{k}={v:.3f}" for k, v in pidyn_errors.items()))
    if "ci95" in metrics:
        log.info(
            "95 %% intervals: %s",
            ", ".join(f"{n} [{lo:.5g}, {hi:.5g}]" for n, (lo, hi) in metrics["ci95"].items()),
        )
    log.info("wall %.1f s, run folder %s", metrics["wall_seconds"], run_dir)


def channel_nrmse(sim: dict[str, np.ndarray], record: Record) -> dict[str, float]:
    """NRMSE of the simulated response against every measured channel (``x``, or ``a3`` for
    floor 3 of a building)."""
    out = {}
    multi = sim["x"].shape[1] > 1
    for kind, floors in record.sensors().items():
        meas = getattr(record, kind)
        for fl in floors:
            out[f"{kind}{fl}" if multi else kind] = nrmse(sim[kind][:, fl - 1], meas[:, fl - 1])
    return out


def _sim_nrmse_x(sim: dict[str, np.ndarray], record: Record) -> float | None:
    """Displacement NRMSE over every floor: against the noise-free truth when simulated, else
    against the measured displacement (None when no displacement was measured)."""
    if record.clean is not None:
        return nrmse(sim["x"], record.clean.x)
    if record.x is None:
        return None
    seen = ~np.isnan(record.x)
    return nrmse(sim["x"][seen], record.x[seen])


def record_noise(cfg: DictConfig, record: Record) -> float:
    """The measurement-noise level of the record: what its data source drew or was given
    (``noise=null`` lets a source draw it), else the config's, else 0."""
    return float((record.meta or {}).get("noise", cfg.get("noise")) or 0.0)


def relative_errors(values: dict[str, float], truths: dict[str, float | None]) -> dict[str, float]:
    """|value - truth| / |truth| in %, for the estimated parameters whose truth is known and nonzero."""
    return errors_pct(values, {n: truths.get(n) for n in values})


DEFAULT_STARTS = ("data", "output_error", "equation_error", "sindy", "ukf")


def check_method_names(cfg: DictConfig) -> None:
    """Misspelled names and settings fail before PIDynNet runs, not minutes later (or never)."""
    from pidyn.baselines.registry import PARAMETRIC, check_names

    check_names("baselines.run", list((cfg.get("baselines") or {}).get("run") or []))
    plan = refine_plan(cfg)
    if plan is not None:
        unknown = sorted(set(plan[0]) - set(PARAMETRIC) - {"data"})
        if unknown:
            raise ValueError(
                f"model.refine.starts: unknown method(s) {unknown}; choose from "
                f"{', '.join(sorted(set(PARAMETRIC) | {'data'}))}"
            )


def refine_plan(cfg: DictConfig) -> tuple[set[str], list[str], Any] | None:
    """``model.refine`` read and checked: (classical starts allowed, state sources to compare,
    RefineSettings), or None when the stage is off."""
    from pidyn.refine import RefineSettings

    node = cfg.model.get("refine") or "none"
    # model.refine=none / =multiple_shooting on the command line sets the method by name (the
    # settings then are RefineSettings' defaults, which conf/model/refine/*.yaml mirror)
    rcfg = {"method": node} if isinstance(node, str) else OmegaConf.to_container(node, resolve=True)
    assert isinstance(rcfg, dict)
    method = rcfg.pop("method", "none")
    if method == "none":
        return None
    if method != "multiple_shooting":
        raise ValueError(f"model.refine: unknown method '{method}'; choose multiple_shooting or none")
    allowed = set(rcfg.pop("starts", DEFAULT_STARTS))
    compare = list(rcfg.pop("compare_states", None) or [])
    settings = RefineSettings(**rcfg)
    for source in compare:
        replace(settings, states=source)  # checks the name
    return allowed, compare, settings


def run_refinement(
    cfg: DictConfig,
    system: StructuralSystem,
    record: Record,
    pidyn_values: dict[str, float],
    baselines: list[dict],
    results: list,
    start: Any = None,
) -> Any:
    """The refinement stage after PIDynNet (``model.refine``); None when it is off.

    Starts: PIDynNet's estimate with its networks' states, and the classical estimates named
    in ``model.refine.starts`` that ran on the same record; the stage refines the one that
    simulates the record best and says so when that is not PIDynNet's."""
    from pidyn.models.identify import network_states
    from pidyn.refine import refine

    plan = refine_plan(cfg)
    if plan is None:
        return None
    allowed, compare, settings = plan
    starts = {"pidynnet": pidyn_values}
    if start is not None and "data" in allowed:  # the data's values, PIDynNet's where the data give none
        starts["data"] = {**pidyn_values, **{k: v for k, v in start.values.items() if k in pidyn_values}}
    for b in baselines:
        if b["method"] in allowed and b.get("params"):
            starts[b["method"]] = b["params"]
    w = cfg.data.windows
    span = {"t_start": w.get("t_start"), "t_end": w.get("t_end")}
    out = refine(system, record, starts, settings, network_states=network_states(results), **span)
    check_refined(system, record, out, sorted(starts))
    # the same refinement from the same start (PIDynNet's, or the classical estimate that
    # simulated better) with the segment states taken elsewhere (e.g. accelerations integrated
    # twice): what the networks' states buy
    out.compared = {}
    for source in compare:
        alt = refine(system, record, {out.start: starts[out.start]}, replace(settings, states=source), **span)
        out.compared[source] = {
            "params": alt.params,
            "cost": alt.cost,
            "converged": alt.converged,
            "max_defect": alt.max_defect,
            "seconds": alt.seconds,
            "error_pct": relative_errors(alt.params, record.truth or {}),
        }
        log.info(
            "refinement from %s states: %s", source, ", ".join(f"{k}={v:.5g}" for k, v in alt.params.items())
        )
    return out


class RefinementFailed(RuntimeError):
    """The refinement ended on parameters that do not describe the record (non-finite, or a model
    that blows up when simulated): a bad start, named, instead of NaNs further on."""


def check_refined(system: StructuralSystem, record: Record, out: Any, starts: list[str]) -> None:
    """Refuse a refinement that ended on non-finite parameters or on a model that diverges over the
    record; the message names the starts tried and what to give instead."""
    bad = sorted(n for n, v in out.params.items() if not np.isfinite(v))
    blown = False
    if not bad:
        sim = simulate_response(
            system,
            {**{s.name: s.init for s in system.param_specs()}, **out.params},
            record,
            state0=np.array(out.initial_state),
        )
        blown = any(diverged(v) for v in sim.values())
    if bad or blown:
        what = f"non-finite {bad}" if bad else "a model that blows up when simulated over the record"
        raise RefinementFailed(
            f"the refinement from {out.start} (starts tried: {', '.join(starts)}) ended on {what}; PIDynNet's "
            f"windows are kept in the run folder. Give a better start: model.refine.starts=[data, output_error, ukf] "
            f"with baselines.run naming the classical ones, or system.guess / system.params.<name>.init"
        )


def start_baselines(
    cfg: DictConfig, system: StructuralSystem, record: Record, hold_out: bool = False
) -> BaselineJob:
    """The run's baselines, started now (in a worker with ``baselines.parallel``, outside a
    multirun whose jobs already use the cores); ``hold_out``: they see the fitting part only."""
    bcfg = cfg.get("baselines") or {}
    fit = (record.meta or {}).get("split", {}).get("fit") if hold_out else None
    plain = OmegaConf.to_container(bcfg, resolve=True) if bcfg else {}
    parallel = bool(bcfg.get("parallel", False)) and not _in_multirun()
    return BaselineJob(
        plain, record_noise(cfg, record), system, record, None if fit is None else tuple(fit), parallel
    )


def run_baselines(
    cfg: DictConfig,
    system: StructuralSystem,
    record: Record,
    run_dir: Path,
    identified: dict[str, float],
    pending: BaselineJob | None = None,
) -> list[dict]:
    """The configured classical methods on the same record (``pending``: already started),
    logged and written to baselines.json, and the Cramer-Rao bound to cramer_rao.json."""
    from pidyn import baselines as B

    bcfg = cfg.get("baselines") or {}
    out = (pending if pending is not None else start_baselines(cfg, system, record)).result()
    truth = record.truth or {}
    for row in out:
        if row.get("note", "").startswith("failed"):
            log.warning("baseline %s %s", row["method"], row["note"])
        else:
            log.info(
                "baseline %s: %s (%.1f s) %s",
                row["method"],
                ", ".join(f"{k}={v:.5g}" for k, v in row["params"].items()),
                row["seconds"],
                row.get("note", ""),
            )
    if bcfg.get("cramer_rao"):
        # the bound at the truth when it is known, else at the identified model
        ref = {**{s.name: s.init for s in system.param_specs()}, **identified, **(truth or {})}
        levels = (record.meta or {}).get("noise_levels") or record_noise(cfg, record)
        crb = B.cramer_rao(system, ref, record.t, record.f, levels, channels=record.sensors())
        write_json(run_dir / "cramer_rao.json", crb)
    if out:
        write_json(run_dir / "baselines.json", {"baselines": out})
    return out


def _in_multirun() -> bool:
    """True inside a Hydra multirun job (progress bars of parallel jobs would interleave)."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    try:
        return HydraConfig.get().mode == RunMode.MULTIRUN
    except ValueError:
        return False


def _quiet_framework_warnings() -> None:
    """Silence Lightning notices that do not apply to a one-window-at-a-time loop."""
    import warnings

    for msg in (
        ".*LeafSpec.*",
        ".*IterableDataset.*has `__len__`.*",
        ".*smaller than the logging interval.*",
        ".*does not have many workers.*",
        ".*litlogger.*",
    ):
        warnings.filterwarnings("ignore", message=msg)


def tb_figures(logger: Any, fig_dir: Path, step: int, metrics: dict, refined: Any = None) -> None:
    exp = getattr(logger, "experiment", None) if logger is not None else None
    if exp is None or not hasattr(exp, "add_image"):
        return
    if refined is not None:
        for n, row in refined.intervals.items():
            exp.add_scalar(f"refined/{n}", row["value"], step)
            exp.add_scalar(f"ci95_lo/{n}", row["ci95"][0], step)
            exp.add_scalar(f"ci95_hi/{n}", row["ci95"][1], step)
        for c, sd in refined.noise_std.items():
            exp.add_scalar(f"noise_std/{c}", sd, step)
        if refined.notes:
            exp.add_text("identifiability", "\n\n".join(refined.notes), step)
    import matplotlib.image as mpimg

    for png in sorted(fig_dir.glob("*.png")):
        img = mpimg.imread(png)[..., :3]
        exp.add_image(f"figures/{png.stem}", np.transpose(img, (2, 0, 1)), step)
    for k, v in (metrics.get("error_pct") or {}).items():
        exp.add_scalar(f"final/error_pct_{k}", v, step)
    for k, v in (metrics["pidynnet"].get("error_pct") or {}).items():
        exp.add_scalar(f"pidynnet/error_pct_{k}", v, step)
    exp.flush()
