"""Generalisation (paper Figures 4-5): identify on the first seconds of a record, then
predict the response to unseen excitations by physics-only fine-tuning, beside the plain
simulation of the identified model.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from omegaconf import DictConfig

from pidyn.data.sources import synthetic_from_motion
from pidyn.excitation.ground_motion import load_record, prepare
from pidyn.models.predict import pearson, predict_response
from pidyn.reporting import write_json
from pidyn.simulate import simulate
from pidyn.tasks.train import _tb_figures, identify

log = logging.getLogger(__name__)


def unseen_cases(cfg: DictConfig, ident_record: str, ident_pga: float) -> list[dict[str, Any]]:
    g = cfg.generalization
    cases = []
    for sc in g.own_scales:
        for st in g.own_stretches:
            if sc == 1.0 and st == 1.0:
                continue
            cases.append({"record": ident_record, "scale": float(sc), "stretch": float(st)})
    for rec in g.other_records:
        if rec == ident_record:
            continue
        base = ident_pga / load_record(rec).pga if g.match_pga else 1.0
        for sc in g.other_scales:
            cases.append({"record": rec, "scale": float(base * sc), "stretch": 1.0})
    return cases[: g.max_cases] if g.max_cases else cases


def generalize(cfg: DictConfig) -> dict[str, Any]:
    metrics, obj = identify(cfg)
    module, system, record, make_trainer = obj["module"], obj["system"], obj["record"], obj["trainer_factory"]
    run_dir: Path = obj["run_dir"]
    g = cfg.generalization
    identified = module.net.params.as_floats()
    ident_pga = float(np.max(np.abs(record.f)))
    rows, examples = [], []
    cases = unseen_cases(cfg, cfg.excitation.record, ident_pga)
    for i, case in enumerate(cases):
        gm = prepare(case["record"], scale=case["scale"], stretch=case["stretch"], duration=g.duration, dt=cfg.excitation.dt)
        truth = synthetic_from_motion(system, gm)  # the true response (true parameters), never shown to the networks
        pred = predict_response(module, truth, make_trainer, iterations=g.iterations,
                                window_length=cfg.data.windows.window_length, batch_size=cfg.batch_size,
                                x_scale=float(np.std(record.x)), v_scale=float(np.std(record.v)) if record.v is not None else None,
                                start_from=str(g.start_from), seed=int(cfg.seed),
                                lbfgs_steps=int(g.get("lbfgs_steps", 30)))
        sim = simulate(system, identified, gm, gm.t)
        row = {"case": i, **case, "pga": gm.pga, "gamma_pidynnet": pearson(pred.x, truth.x),
               "gamma_simulation": pearson(sim.x, truth.x), "peak_x_true": float(np.max(np.abs(truth.x))),
               "seconds": pred.seconds}
        rows.append(row)
        log.info("[%d/%d] %s x%.3g t%.3g: gamma PIDynNet %.4f, simulation %.4f", i + 1, len(cases), case["record"],
                 case["scale"], case["stretch"], row["gamma_pidynnet"], row["gamma_simulation"])
        if len(examples) < 4:
            examples.append((row, truth.t, truth.x[:, 0], pred.x[:, 0], sim.x[:, 0]))
        pd.DataFrame(rows).to_csv(run_dir / "generalization.csv", index=False)  # progress survives a crash
    df = pd.DataFrame(rows)
    share = float((df.gamma_pidynnet >= 0.95).mean()) if len(df) else float("nan")
    summary = {"cases": len(df), "share_gamma_ge_0.95_pidynnet": share,
               "share_gamma_ge_0.95_simulation": float((df.gamma_simulation >= 0.95).mean()) if len(df) else float("nan"),
               "median_gamma_pidynnet": float(df.gamma_pidynnet.median()) if len(df) else float("nan"),
               "median_gamma_simulation": float(df.gamma_simulation.median()) if len(df) else float("nan"),
               "identification": {k: metrics[k] for k in ("params", "error_pct", "max_error_pct")}}
    write_json(run_dir / "generalization.json", summary)
    _figures(run_dir / "figures", record, module, df, examples)
    _tb_figures(obj["logger"], run_dir / "figures", int(module.iteration), {})
    log.info("generalisation: %d cases, share gamma >= 0.95: PIDynNet %.2f, simulation %.2f", len(df), share,
             summary["share_gamma_ge_0.95_simulation"])
    return summary


def _figures(fig_dir: Path, record, module, df: pd.DataFrame, examples: list) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
        ax.set_title(f"prediction: {row['record']} x{row['scale']:.3g}, stretch {row['stretch']:.3g}", fontsize=9)
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
