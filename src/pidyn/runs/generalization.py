"""Generalisation's parts (paper Figures 4-5): the unseen excitations, one prediction by
physics-only fine-tuning beside the plain simulation of the identified model, the summary, the
table and the figures. ``pidyn.tasks.generalize`` runs them in order and resumes a sweep."""

from __future__ import annotations

import logging
import os
import platform
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from pidyn.data.sources import synthetic_from_motion
from pidyn.excitation.ground_motion import load_record, prepare
from pidyn.models.predict import pearson, predict_response
from pidyn.models.predict_settings import PredictSettings
from pidyn.reporting import pyplot, write_json
from pidyn.simulate import simulate

log = logging.getLogger(__name__)


def unseen_cases(cfg: DictConfig, ident_record: str, ident_pga: float) -> list[dict[str, Any]]:
    g = cfg.generalization
    cases = []
    for sc in g.own_scales:
        for st in g.own_stretches:
            if sc == 1.0 and st == 1.0:
                continue
            cases.append({"record": ident_record, "scale": float(sc), "stretch": float(st), "start": 0.0})
    for rec in g.other_records:
        if rec == ident_record:
            continue
        start = strong_motion_start(rec, float(g.lead)) if g.align else 0.0
        seg = prepare(rec, start=start, duration=g.duration, dt=cfg.excitation.dt)
        base = ident_pga / seg.pga if g.match_pga else 1.0
        for sc in g.other_scales:
            cases.append({"record": rec, "scale": float(base * sc), "stretch": 1.0, "start": start})
    return cases[: g.max_cases] if g.max_cases else cases


def strong_motion_start(record: str, lead: float) -> float:
    """Where a predicted segment of ``record`` begins: ``lead`` seconds before its strong motion
    (5 % of the Arias intensity), rounded down to a whole second. Records whose strong motion
    comes late (Chi-Chi TCU078 at 24 s, Tabas at 14 s) would otherwise put nearly silent
    ground into a 20 s prediction."""
    return float(np.floor(max(0.0, load_record(record).arias_time(0.05) - lead)))


def prediction_settings(g: DictConfig) -> PredictSettings:
    """The prediction fields of ``generalization`` as validated settings (a misspelled value
    fails here, before the identification runs)."""
    names = {f.name for f in fields(PredictSettings)}
    return PredictSettings(**{k: v for k, v in OmegaConf.to_container(g, resolve=True).items() if k in names})


def predict_case(
    cfg: DictConfig,
    obj: dict[str, Any],
    settings: PredictSettings,
    i: int,
    case: dict[str, Any],
    pred_dir: Path,
) -> dict[str, Any]:
    """One unseen excitation: the true response, PIDynNet's physics-only prediction and the plain
    simulation of the identified model; the series go to ``predictions/case_<i>.npz``."""
    g = cfg.generalization
    module, system, record = obj["module"], obj["system"], obj["record"]
    gm = prepare(
        case["record"],
        scale=case["scale"],
        stretch=case["stretch"],
        duration=g.duration,
        dt=cfg.excitation.dt,
        start=case["start"],
    )
    truth = synthetic_from_motion(
        system, gm
    )  # the true response (true parameters), never shown to the networks
    pred = predict_response(
        module,
        truth,
        obj["trainer_factory"],
        settings,
        window_length=cfg.data.windows.window_length,
        batch_size=cfg.batch_size,
        x_scale=float(np.std(record.x)),
        v_scale=float(np.std(record.v)) if record.v is not None else None,
        seed=int(cfg.seed),
    )
    sim = simulate(system, obj["identified"], gm, gm.t)  # the estimate before any prediction
    row = {
        "case": i,
        **case,
        "pga": gm.pga,
        "gamma_pidynnet": pearson(pred.x, truth.x),
        "gamma_simulation": pearson(sim.x, truth.x),
        "peak_x_true": float(np.max(np.abs(truth.x))),
        "windows": len(pred.windows),
        "max_window_loss": pred.max_window_loss,
        "seconds": pred.seconds,
    }
    np.savez_compressed(pred_dir / f"case_{i:03d}.npz", t=truth.t, x_true=truth.x, x_pred=pred.x, x_sim=sim.x)
    return row


def summarize(rows: list[dict[str, Any]], metrics: dict[str, Any]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The cases as a table and their summary: the share with gamma >= 0.95 and the medians."""
    df = pd.DataFrame(rows)
    share = float((df.gamma_pidynnet >= 0.95).mean()) if len(df) else float("nan")
    summary = {
        "cases": len(df),
        "share_gamma_ge_0.95_pidynnet": share,
        "share_gamma_ge_0.95_simulation": float((df.gamma_simulation >= 0.95).mean())
        if len(df)
        else float("nan"),
        "median_gamma_pidynnet": float(df.gamma_pidynnet.median()) if len(df) else float("nan"),
        "median_gamma_simulation": float(df.gamma_simulation.median()) if len(df) else float("nan"),
        "identification": {k: metrics[k] for k in ("params", "error_pct", "max_error_pct")},
    }
    return df, summary


def write_outputs(run_dir: Path, cfg: DictConfig, record, df: pd.DataFrame, summary: dict[str, Any]) -> None:
    """generalization.json, generalization.md and Figures 4-5 in the run folder."""
    write_json(run_dir / "generalization.json", summary)
    _write_markdown(run_dir / "generalization.md", cfg, df, summary)
    _figures(run_dir / "figures", record, df, _examples(run_dir / "predictions", df))


def _write_markdown(path: Path, cfg: DictConfig, df: pd.DataFrame, summary: dict[str, Any]) -> None:
    """The run's result as a table a reader can check case by case."""
    import torch  # lazy: only for the table's versions line

    try:
        from hydra.core.hydra_config import HydraConfig  # inside a Hydra run only

        overrides = " ".join(HydraConfig.get().overrides.task)
    except ValueError:
        overrides = ""
    g = cfg.generalization
    errs = summary["identification"]["error_pct"]
    lines = [
        f"# Generalisation ({str(cfg.system._target_).rsplit('.', 1)[-1]}, identified on {cfg.excitation.record} "
        f"0-{cfg.excitation.duration:g} s)\n",
        f"Command: `{('python generalize.py ' + overrides).strip()}`  ",
        f"Machine: {platform.machine()}, {torch.get_num_threads()} torch thread(s), {os.cpu_count()} cores  \n",
        "Identification errors (%): " + ", ".join(f"{k} {v:.3g}" for k, v in errs.items()) + "\n",
        f"Each unseen excitation is {g.duration:g} s long (stretched records longer); other records start "
        f"{g.lead:g} s before their strong motion (5 % Arias intensity), rounded down to a whole "
        "second, and are scaled to the identification record's PGA times the listed factor. Physics-only prediction "
        f"(paper Eq. 14), identified parameters fixed: per {cfg.data.windows.window_length:g} s window "
        f"{g.iterations} Adam iterations, then up to {g.lbfgs_steps} L-BFGS steps on the window's whole pool; "
        f"a window whose physics loss stays above {g.split_tol:g} is solved again as two halves "
        f"(down to {g.min_window:g} s). The state is handed from window to window. Reference: the identified "
        "model simulated with solve_ivp.\n",
        "| record | from (s) | scale | stretch | PGA (m/s^2) | gamma PIDynNet | gamma simulation | windows | max window loss | seconds |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in df.to_dict("records"):
        lines.append(
            f"| {r['record']} | {r.get('start', 0.0):g} | {r['scale']:.3g} | {r['stretch']:.3g} | {r['pga']:.2f} | "
            f"{r['gamma_pidynnet']:.4f} | {r['gamma_simulation']:.4f} | {r.get('windows', '')} | "
            f"{r.get('max_window_loss', float('nan')):.2g} | {r['seconds']:.0f} |"
        )
    lines.append("")
    lines.append(
        f"Share with gamma >= 0.95 over {summary['cases']} excitations: PIDynNet "
        f"{summary['share_gamma_ge_0.95_pidynnet']:.2f}, identified model simulated "
        f"{summary['share_gamma_ge_0.95_simulation']:.2f} (paper: about 0.95 for PIDynNet). Median gamma: "
        f"PIDynNet {summary['median_gamma_pidynnet']:.4f}, simulation {summary['median_gamma_simulation']:.4f}."
    )
    path.write_text("\n".join(lines) + "\n")


def resume_rows(run_dir: Path, cases: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows already in ``generalization.csv`` whose case matches, in order, and whose prediction
    file exists; an interrupted sweep continues at the first case not done."""
    path = run_dir / "generalization.csv"
    if not path.exists():
        return []
    rows = []
    for i, r in enumerate(pd.read_csv(path).to_dict("records")):
        npz = run_dir / "predictions" / f"case_{i:03d}.npz"
        if i >= len(cases) or not npz.exists():
            break
        c = cases[i]
        if (
            r["record"] != c["record"]
            or not np.isclose(r["scale"], c["scale"])
            or not np.isclose(r["stretch"], c["stretch"])
            or not np.isclose(r.get("start", 0.0), c["start"])
        ):
            break
        r["start"] = c["start"]  # sweeps written before records were aligned all started at 0
        rows.append(r)
    if rows:
        if len(rows) < len(cases):
            log.info("resuming the generalisation sweep at case %d of %d", len(rows) + 1, len(cases))
        else:
            log.info("all %d cases already done; rewriting the summary, table and figures", len(cases))
    return rows


def _examples(pred_dir: Path, df: pd.DataFrame, n: int = 4) -> list:
    """Cases for Figure 4: the worst PIDynNet prediction first, then one case of each of the
    first other records (the identification record's own versions are the easy ones)."""
    if not len(df):
        return []
    picks = [int(df.gamma_pidynnet.idxmin())]
    for rec in df.record.drop_duplicates().iloc[1:]:
        if len(picks) >= n:
            break
        i = int(df.index[df.record == rec][-1])
        if i not in picks:
            picks.append(i)
    out = []
    for i in picks:
        r = df.loc[i].to_dict()
        d = np.load(pred_dir / f"case_{int(r['case']):03d}.npz")
        out.append((r, d["t"], d["x_true"][:, 0], d["x_pred"][:, 0], d["x_sim"][:, 0]))
    return out


def _figures(fig_dir: Path, record, df: pd.DataFrame, examples: list) -> None:
    plt = pyplot()

    fig_dir.mkdir(exist_ok=True)
    # Figure 4: identification window, then predictions under unseen excitations
    n = 1 + len(examples)
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.1 * n), squeeze=False)
    ax = axes[0][0]
    ax.plot(record.t, record.x[:, 0], color="0.3", lw=0.8, label="measured")
    ax.axvspan(record.t[0], record.t[-1], color="tab:green", alpha=0.08)
    ax.set_title("identification", fontsize=9)
    ax.legend(fontsize=7)
    for i, (row, t, xt, xp, xs) in enumerate(examples, start=1):
        ax = axes[i][0]
        ax.axvspan(t[0], t[-1], color="tab:blue", alpha=0.06)
        ax.plot(t, xt, color="0.3", lw=0.9, label="true")
        ax.plot(t, xp, "--", lw=0.8, label=f"PIDynNet (gamma {row['gamma_pidynnet']:.3f})")
        ax.plot(t, xs, ":", lw=0.8, label=f"identified model simulated (gamma {row['gamma_simulation']:.3f})")
        ax.set_title(
            f"prediction: {row['record']} from {row.get('start', 0.0):g} s, x{row['scale']:.3g}, "
            f"stretch {row['stretch']:.3g}",
            fontsize=9,
        )
        ax.legend(fontsize=7, loc="upper right")
    axes[-1][0].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(fig_dir / "fig4_identification_prediction.png", dpi=110)
    plt.close(fig)
    # Figure 5: histogram of the correlation coefficient
    fig, ax = plt.subplots(figsize=(6, 3.5))
    bins = np.linspace(min(0.8, float(np.nanmin(df.gamma_pidynnet)) if len(df) else 0.8), 1.0, 21)
    ax.hist(df.gamma_pidynnet.clip(lower=bins[0]), bins=bins, alpha=0.7, label="PIDynNet fine-tuned")
    ax.hist(df.gamma_simulation.clip(lower=bins[0]), bins=bins, alpha=0.5, label="identified model simulated")
    ax.axvline(0.95, color="k", ls="--", lw=0.8)
    ax.set_xlabel("Pearson correlation gamma (predicted vs true x)")
    ax.set_ylabel("excitations")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(fig_dir / "fig5_correlation_histogram.png", dpi=110)
    plt.close(fig)
