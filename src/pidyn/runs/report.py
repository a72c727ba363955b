"""What a run writes to its folder after identification: identified_params.yaml, metrics.json,
refinement.json, windows.json, modal.json, the figures, TensorBoard and the log's summary."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig

from pidyn.adequacy import check_adequacy, describe
from pidyn.assessment import assess
from pidyn.notes import note
from pidyn.reporting import (
    diverged,
    param_table,
    write_json,
    write_text_atomic,
    write_yaml,
)
from pidyn.runs.build import Run
from pidyn.runs.building_report import write_building_report
from pidyn.runs.hparams import log_hparams
from pidyn.runs.metrics import channel_nrmse, record_noise, relative_errors, sim_nrmse_x
from pidyn.runs.run_figures import draw_figures
from pidyn.runs.tb_images import add_png
from pidyn.simulate import rk4_stability, simulate_response
from pidyn.starts.data import DATA_SCALES
from pidyn.supports import support_lines, support_table
from pidyn.systems.base import StructuralSystem

log = logging.getLogger(__name__)


def write_report(
    cfg: DictConfig,
    run: Run,
    results: list,
    pidyn_values: dict[str, float],
    baselines: list[dict],
    refined: Any,
    t_wall: float,
    stages: dict[str, float] | None = None,
) -> dict[str, Any]:
    """identified_params.yaml, metrics.json, refinement.json, windows.json, figures, TensorBoard, log.
    ``stages``: seconds each stage before the report took (``stage_seconds``, the report's own added)."""
    t_report = time.perf_counter()
    system, record, run_dir = run.system, run.record, run.run_dir
    params = run.module.net.params
    names = params.trainable_names
    truths = {n: (record.truth or {}).get(n) for n in names}
    values = dict(refined.params) if refined is not None else dict(pidyn_values)
    final = final_values(run, refined, pidyn_values)
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
    metrics = _metrics(cfg, run, values, truths, pidyn_values, sim, notes, len(results), refined is not None)
    errors, pidyn_errors = metrics["error_pct"], metrics["pidynnet"]["error_pct"]
    if refined is not None:
        _write_refined(run_dir, refined, names, values, truths, metrics)
    if baselines:
        metrics["baselines"] = {
            b["method"]: {"error_pct": b.get("error_pct"), "seconds": b["seconds"]} for b in baselines
        }
    _beside(run, metrics)
    write_json(run_dir / "windows.json", {"windows": [r.__dict__ for r in results]})
    adequacy = _adequacy(run, final, sim)
    _assess(run, final, refined, sim, metrics, adequacy["adequate"])
    _record_adequacy(adequacy, metrics)
    if hasattr(system, "storey_equations"):
        _building(run, final, truths, refined, metrics)
    _supports(system, final, refined, metrics)
    if cfg.get("figures", True):
        draw_figures(run, results, truths, baselines, refined, sim, metrics, final)
        tb_figures(run.logger, run.run_dir / "figures", int(run.module.iteration), metrics, refined)
    if stages is not None:
        metrics["stage_seconds"] = {**stages, "report": time.perf_counter() - t_report}
    metrics["wall_seconds"] = time.perf_counter() - t_wall  # the whole run, its report and figures too
    log_hparams(run.logger, metrics)
    write_json(run_dir / "metrics.json", metrics)
    write_run_report(run_dir, system.describe(final), metrics)
    _log_summary(system.describe(final), errors, pidyn_errors, metrics, run_dir)
    return metrics


def _supports(system: StructuralSystem, final: dict[str, float], refined: Any, metrics: dict) -> None:
    """A bridge on its supports: each support's stiffness and what the data say of it."""
    if not hasattr(system, "support_stiffness_params"):
        return
    metrics["supports"], support_notes = support_table(system, final, refined)
    for text in support_notes:
        log.warning(text)
    metrics["notes"] = list(metrics.get("notes") or []) + support_notes


def _write_refined(
    run_dir: Path, refined: Any, names: list[str], values: dict, truths: dict, metrics: dict
) -> None:
    """The refinement's metrics (intervals, coverage), refinement.json and the refined checkpoint."""
    metrics.update(refined_metrics(refined, names, truths))
    write_json(run_dir / "refinement.json", refined.to_dict())
    torch.save(
        {"names": names, "values": values, "ci95": metrics["ci95"]}, run_dir / "checkpoints" / "refined.pt"
    )


def _metrics(
    cfg: DictConfig,
    run: Run,
    values: dict[str, float],
    truths: dict[str, float | None],
    pidyn_values: dict[str, float],
    sim: dict[str, np.ndarray],
    notes: list[str],
    n_windows: int,
    refined: bool,
) -> dict[str, Any]:
    """metrics.json's fields before the refinement and the baselines add theirs."""
    errors, pidyn_errors = relative_errors(values, truths), relative_errors(pidyn_values, truths)
    return {
        "system": run.system.name,
        # the structure's scale the run used, read from its records where the config left it null
        "scale": {k: float(cfg.system[k]) for k in DATA_SCALES if cfg.system.get(k) is not None},
        "record": run.record.name,
        "noise": record_noise(cfg, run.record),
        "seed": int(cfg.seed),
        "data_seed": int(cfg.data_seed),
        "batch_size": int(cfg.batch_size),
        "eq_scale": float(cfg.eq_scale),
        "eq_stretch": float(cfg.eq_stretch),
        "refine": "multiple_shooting" if refined else "none",
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
        "sim_nrmse_x": sim_nrmse_x(sim, run.record),
        "sim_nrmse": channel_nrmse(sim, run.record),
        "notes": notes,
        "windows": n_windows,
        "iterations": int(run.module.iteration),
    }


def _adequacy(run: Run, final: dict[str, float], sim: dict[str, np.ndarray]) -> dict[str, Any]:
    """Whether the identified model describes the record (``pidyn.adequacy``), on the fitting part
    and on a held-out part, with the integrator's stability at the record's step."""
    record = run.record
    split = record.meta.split if run.hold_out else None
    fit = split.fit if split else (float(record.t[0]), float(record.t[-1]))
    stability = rk4_stability(run.system, final, record.dt, substeps=None)  # the simulator's own steps
    return check_adequacy(sim, record, fit, split.heldout if split else None, stability=stability)


def _record_adequacy(result: dict[str, Any], metrics: dict) -> None:
    """``adequate`` and ``adequacy`` in metrics.json, the held-out scores beside the prediction that
    knows nothing, and a note when the model does not describe the record."""
    metrics["adequate"] = result["adequate"]
    metrics["adequacy"] = result
    if "heldout" in metrics:
        metrics["heldout"]["trivial"] = result["trivial"]
        metrics["heldout"]["trivial_nrmse"] = {
            k: r["trivial_heldout_nrmse"]
            for k, r in result["channels"].items()
            if "trivial_heldout_nrmse" in r
        }
        metrics["heldout"]["beats_trivial"] = result["predicts"]
    if not result["adequate"]:
        metrics["notes"].append(note("model_inadequate", describe(result)))


def final_values(run: Run, refined: Any, pidyn_values: dict[str, float]) -> dict[str, float]:
    """Every parameter of the identified model: the refinement's estimate (PIDynNet's where there
    is none) over the held ones."""
    return {**run.module.net.params.as_floats(), **(refined.params if refined is not None else pidyn_values)}


def _beside(run: Run, metrics: dict) -> None:
    """The linear model of the same layout fitted beside the run's, and which of the two the run's
    own records chose (``pidyn.runs.model_choice``), with its note."""
    if run.linear_model is not None:
        metrics["linear_model"] = run.linear_model
    if run.model_choice is not None:
        metrics["model_choice"] = run.model_choice
        said = [run.model_choice.get(k) for k in ("note", "undecided")]
        metrics["notes"] = list(metrics.get("notes") or []) + [n for n in said if n]


def write_run_report(run_dir: Path, equation: str, metrics: dict) -> None:
    """``report.md``: the verdict on the model first, then the equation and the parameters."""
    ad = metrics["adequacy"]
    names = str(metrics["record"]).split("+")
    on = metrics["record"] if len(names) == 1 else f"{len(names)} records"
    lines = [f"# Identification: {metrics['system']} on {on}", ""]
    if len(names) > 1:  # several records of the structure (pidyn.data.multi)
        lines += ["Records, parameters shared, each its own initial state: " + ", ".join(names), ""]
    lines += [f"**{'Adequate' if ad['adequate'] else 'Not adequate'}**: {describe(ad)}", ""]
    lines += [f"Identified: `{equation}`", ""]
    title = "95 % interval" if ad["adequate"] else "95 % interval (conditional on a rejected model)"
    lines += [f"| parameter | value | {title} |", "|---|---|---|"]
    for n, v in metrics["params"].items():
        lo, hi = (metrics.get("ci95") or {}).get(n, (None, None))
        ci = "" if lo is None else f"[{lo:.5g}, {hi:.5g}]"
        lines.append(f"| {n} | {v:.5g} | {ci} |")
    lines += ["", "| channel | fitting part NRMSE | knowing nothing | held-out NRMSE | knowing nothing |"]
    lines += ["|---|---|---|---|---|"]
    for c, r in ad["channels"].items():
        cells = [
            r.get(k) for k in ("fit_nrmse", "trivial_fit_nrmse", "heldout_nrmse", "trivial_heldout_nrmse")
        ]
        lines.append(f"| {c} | " + " | ".join("" if x is None else f"{x:.3g}" for x in cells) + " |")
    lines += ["", f"Knowing nothing: {ad['trivial']}."]
    if metrics.get("supports"):
        lines += ["", "## Supports (per kg of deck)", "", *support_lines(metrics["supports"])]
    if metrics.get("model_choice"):
        lines += ["", *_choice_lines(metrics["model_choice"], metrics["system"])]
    if metrics.get("notes"):
        lines += ["", "## Notes", ""] + [f"- {n}" for n in metrics["notes"]]
    write_text_atomic(run_dir / "report.md", "\n".join(lines) + "\n")


def _choice_lines(choice: dict, system: str) -> list[str]:
    """report.md's table of the run's own records, each predicted by both models refitted without it."""
    used = (
        "its own" if choice["chosen"] == "nonlinear" else f"the linear model beside it ({choice['system']})"
    )
    lines = ["## Which model predicts (each record left out)", ""]
    lines += [f"Predictions use {used}: {choice['rule']}.", ""]
    lines += [f"| left-out record | {system} | linear |", "|---|---|---|"]
    for r in choice["records"]:
        lines.append(f"| {r['record']} | {r['nonlinear']:.3g} | {r['linear']:.3g} |")
    means = choice["mean_nrmse_a"]
    lines.append(f"| mean | {means['nonlinear']:.3g} | {means['linear']:.3g} |")
    if choice.get("undecided"):  # the records cannot tell the two apart: the reader should know
        lines += ["", f"Undecided: {choice['undecided']}."]
    return lines


def _building(run: Run, final: dict[str, float], truths: dict, refined: Any, metrics: dict) -> None:
    """A building's modal table, storey equations and loops (``building_report``); its modes go to
    metrics.json."""
    modes = write_building_report(
        run.system,
        run.record,
        final,
        {**final, **truths} if any(truths.values()) else None,
        None if refined is None else np.array(refined.initial_state),
        run.run_dir,
        run.logger,
        int(run.module.iteration),
    )
    metrics["modes"] = {k: v for k, v in modes.items() if k != "truth"}


def _assess(
    run: Run, final: dict[str, float], refined: Any, sim: dict[str, np.ndarray], metrics: dict, adequate: bool
) -> None:
    """modal.json and, on a record with a held-out part, how the model predicts it (``pidyn.assessment``)."""
    metrics.update(assess(run.system, run.record, final, refined, sim, run.hold_out, run.run_dir, adequate))
    for r, mode in enumerate(metrics.get("modal") or [], start=1):
        if adequate and mode.get("not_a_property"):  # a rejected model is said so once, elsewhere
            text = note(
                "damping_not_a_property",
                f"mode {r}: {mode['not_a_property']}: the fit's damping, not reported as the structure's",
            )
            log.warning(text)
            metrics.setdefault("notes", []).append(text)


def _divergence_note(sim: dict[str, np.ndarray]) -> list[str]:
    """Says so when the identified model's simulation over the record blows up."""
    if not any(diverged(v) for v in sim.values()):
        return []
    text = note(
        "model_diverges",
        "the identified model diverges when simulated over the record (its response blows up): the estimate "
        "is not a usable model; start from a better guess (system.guess) or a classical estimate "
        "(model.refine.starts)",
    )
    log.warning(text)
    return [text]


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


def _log_summary(equation: str, errors: dict, pidyn_errors: dict, metrics: dict, run_dir: Path) -> None:
    log.info("identified: %s", equation)
    if errors:
        log.info("errors (%%): %s", ", ".join(f"{k}={v:.3f}" for k, v in errors.items()))
        if "ci95" in metrics:
            log.info("PIDynNet alone (%%): %s", ", ".join(f"{k}={v:.3f}" for k, v in pidyn_errors.items()))
    adequate = metrics.get("adequate", True)
    if "ci95" in metrics:
        log.info(
            "95 %% intervals%s: %s",
            "" if adequate else " (conditional on a model the data reject)",
            ", ".join(f"{n} [{lo:.5g}, {hi:.5g}]" for n, (lo, hi) in metrics["ci95"].items()),
        )
    if "adequacy" in metrics:
        (log.info if adequate else log.warning)("%s", describe(metrics["adequacy"]))
    log.info("wall %.1f s, run folder %s", metrics["wall_seconds"], run_dir)


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
    for png in sorted(fig_dir.glob("*.png")):
        add_png(exp, f"figures/{png.stem}", png, step)
    for k, v in (metrics.get("error_pct") or {}).items():
        exp.add_scalar(f"final/error_pct_{k}", v, step)
    for k, v in (metrics["pidynnet"].get("error_pct") or {}).items():
        exp.add_scalar(f"pidynnet/error_pct_{k}", v, step)
    exp.flush()
