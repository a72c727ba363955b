"""The methods beside PIDynNet in a run: the classical baselines (started before PIDynNet, on
another core) and the refinement stage after it, with the checks of their names and results."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from pidyn import baselines as B
from pidyn.baselines.registry import STARTS, check_names
from pidyn.baselines.worker import BaselineJob
from pidyn.data.sources import Record
from pidyn.models.schedule import network_states
from pidyn.parallel import workers
from pidyn.refine import RefineSettings, refine
from pidyn.reporting import diverged, write_json
from pidyn.runs.metrics import record_noise, relative_errors
from pidyn.runs.runtime import in_multirun
from pidyn.simulate import simulate_response
from pidyn.systems.base import StructuralSystem

log = logging.getLogger(__name__)


def default_starts() -> tuple[str, ...]:
    """The refinement's starts when the config names none: the data's, then every estimator that
    ran and gave the model's parameters (``model.refine.starts: null``)."""
    return ("data", *STARTS)


def check_method_names(cfg: DictConfig) -> None:
    """Misspelled names and settings fail before PIDynNet runs, not minutes later (or never)."""
    check_names("baselines.run", list((cfg.get("baselines") or {}).get("run") or []))
    plan = refine_plan(cfg)
    if plan is not None:
        unknown = sorted(set(plan[0]) - set(STARTS) - {"data"})
        if unknown:
            raise ValueError(
                f"model.refine.starts: unknown method(s) {unknown}; choose from "
                f"{', '.join(sorted(set(STARTS) | {'data'}))}"
            )


def refine_plan(cfg: DictConfig) -> tuple[set[str], list[str], Any] | None:
    """``model.refine`` read and checked: (classical starts allowed, state sources to compare,
    RefineSettings), or None when the stage is off."""
    node = cfg.model.get("refine") or "none"
    # model.refine=none / =multiple_shooting on the command line sets the method by name (the
    # settings then are RefineSettings' defaults, the schema of conf/model/refine/*.yaml)
    rcfg = {"method": node} if isinstance(node, str) else OmegaConf.to_container(node, resolve=True)
    assert isinstance(rcfg, dict)
    method = rcfg.pop("method", "none")
    if method == "none":
        return None
    if method != "multiple_shooting":
        raise ValueError(f"model.refine: unknown method '{method}'; choose multiple_shooting or none")
    starts = rcfg.pop("starts", None)
    allowed = set(default_starts() if starts is None else starts)
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
    plan = refine_plan(cfg)
    if plan is None:
        return None
    allowed, compare, settings = plan
    starts = {"pidynnet": pidyn_values, **peer_starts(allowed, pidyn_values, start, baselines)}
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


def peer_starts(
    allowed: set[str], pidyn_values: dict[str, float], start: Any, baselines: list[dict]
) -> dict[str, dict[str, float]]:
    """The refinement's starts beside PIDynNet's: the data's (``start``) and each classical
    estimate named in ``allowed``, PIDynNet's values where one gives none (a peer's c and k only)."""
    out: dict[str, dict[str, float]] = {}
    if start is not None and "data" in allowed:
        out["data"] = {**pidyn_values, **{k: v for k, v in start.values.items() if k in pidyn_values}}
    for b in baselines:
        if b["method"] in allowed and b.get("params"):
            out[b["method"]] = {**pidyn_values, **{k: v for k, v in b["params"].items() if k in pidyn_values}}
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
    fit = record.meta.split.fit if hold_out and record.meta.split else None
    plain = OmegaConf.to_container(bcfg, resolve=True) if bcfg else {}
    parallel = bool(bcfg.get("parallel", False)) and not in_multirun()
    # a run that stops PIDynNet where a peer is far ahead waits for these rows after its first
    # window, its core idle: then the worker may share its work over both (the UKF's grid)
    waits = cfg.model.get("schedule", {}).get("stop_behind") is not None
    return BaselineJob(
        plain,
        record_noise(cfg, record),
        system,
        record,
        None if fit is None else tuple(fit),
        parallel,
        workers=workers() if waits else 1,
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
        levels = record.meta.noise_levels or record_noise(cfg, record)
        crb = B.cramer_rao(system, ref, record.t, record.f, levels, channels=record.sensors())
        write_json(run_dir / "cramer_rao.json", crb)
    if out:
        write_json(run_dir / "baselines.json", {"baselines": out})
    return out
