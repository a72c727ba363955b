"""The mini shake-table study: three building models measured by Xsens DOT IMUs, every run
identified (masses unknown), each model's other runs predicted from its Northridge run beside
mdof's SRIM identified on the same part, the clocks' alignment measured against the IMUs' own.

    python experiments/shake_table.py                  # part of make real (a quarter of an hour)
    python experiments/shake_table.py --aggregate outputs/real/<stamp>

Results: experiments/results/real/shake_table.md, shake_table_runs.csv, shake_table_predictions.csv,
figures/shake_table_prediction_<model>.png.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from pidyn.assessment import reported_damping
from pidyn.bench.launch import run_logged
from pidyn.bench.tables import cell, interval

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"
MODELS_DIR = ROOT / "data" / "mini_shake_table"
#: model folder -> (storeys, the run each is identified on to predict the others)
MODELS = {
    "Flexible 3 story": (3, "Northridge"),
    "Stiff 3 story": (3, "Northridge"),
    "Stiff 1 story": (1, "Northridge Trial 1"),
}
AGREE = 0.05  # a model's fundamental frequency agrees across its runs to within this share


def slug(model: str) -> str:
    return model.lower().replace(" ", "_")


def run_sweeps(base: Path, jobs: int = 2, launcher: str = "joblib") -> None:
    """Per model: its identification run (align=lag, the default, and align=clock: the shared
    clock as it is), then its other runs, each started from the identification run's estimate
    (a sine below the fundamental does not show the resonance a start needs), as Hydra multiruns."""
    from pidyn.data.imu import run_labels

    for model, (storeys, ident) in MODELS.items():
        others = [r for r in run_labels(MODELS_DIR / model) if r != ident]
        folder = base / "shake_table" / slug(model)
        _sweep(model, storeys, [ident], folder, jobs, launcher)
        _sweep(
            model,
            storeys,
            [ident],
            base / "shake_table_clock" / slug(model),
            jobs,
            launcher,
            ["data.align=clock"],
        )
        start = _runs(folder).get(ident)
        if others and start is not None:
            _sweep(
                model,
                storeys,
                others,
                base / "shake_table" / f"{slug(model)}_others",
                jobs,
                launcher,
                # double quotes: a Hydra run folder's name holds the single-quoted overrides
                [f'model.start="{start}"'],
            )


def diagnose_models(base: Path) -> None:
    """Each model's identification run diagnosed storey by storey (``diagnose.py`` from that run's
    estimate): which storey's shear the linear shear model misses, and what it looks like."""
    for model, (storeys, ident) in MODELS.items():
        start = _runs(base / "shake_table" / slug(model)).get(ident)
        if start is None:
            continue
        folder = base / "shake_table_diagnose" / slug(model)
        cmd = [
            sys.executable,
            "diagnose.py",
            "data=xsens",
            f"data.path={MODELS_DIR.relative_to(ROOT) / model}",
            f"data.run={ident}",
            "system=shear_building",
            f"system.n_storeys={storeys}",
            f'model.start="{start}"',
            "skip_done=true",
            f"hydra.run.dir={folder}",
        ]
        run_logged(cmd, f"diagnose {slug(model)}", ROOT)


def diagnosis_lines(base: Path) -> list[str]:
    """The storey-by-storey diagnoses of the identification runs, as a table."""
    rows = []
    for model, (_, ident) in MODELS.items():
        f = base / "shake_table_diagnose" / slug(model) / "diagnosis.json"
        if not f.exists():
            continue
        d = json.loads(f.read_text())
        final = d.get("extended_parameters") or d["nominal_parameters"]
        for r in d["ranking"]:
            i, own = r["storey"], r.get("own_law") or {}
            top = r["rows"][0] if r["rows"] else {}
            named = [f"{c}" for c, s_ in zip(d["causes"], d["storeys"]) if s_ == i]
            rows.append(
                f"| {model} | {ident} | {i} | {final[f'c{i}']:.4g}, {final[f'k{i}']:.5g} | "
                f"{own.get('c', float('nan')):.4g}, {own.get('k', float('nan')):.5g} | {r['verdict']} | "
                f"{top.get('effect', '-')} ({_fmt(top.get('score'))}, cv {_fmt(top.get('cv_gain'))}) | "
                f"{', '.join(named) or '-'} |"
            )
        for note in d.get("notes") or []:
            rows.append(f"| {model} | {ident} | note | {note} | | | | |")
        rows.append(
            f"| {model} | {ident} | verdict | **{d['verdict']}** | held-out NRMSE {_fmt(d['gain']['nominal'])}"
            f"{'' if d['gain']['extended'] is None else ' -> ' + _fmt(d['gain']['extended'])} | | | {d['wall_seconds']:.0f} s |"
        )
    if not rows:
        return []
    return [
        "",
        "## Storey by storey: what the linear shear model misses",
        "",
        "`diagnose.py system=shear_building` on each identification run, from that run's estimate: every "
        "storey's shear from the floors' accelerations (masses as identified, floor 1's the unit), screened "
        "on its own. c, k per kg of floor 1. 'Own law': the storey's c, k refitted to its own shear, "
        "without the other storeys.",
        "",
        "| model | run | storey | model's c, k | own law c, k | screening | top effect (score, cv gain) | named |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
    ]


def _sweep(
    model: str, storeys: int, runs: list[str], folder: Path, jobs: int, launcher: str, extra: list[str] = ()
) -> None:
    cmd = [
        sys.executable,
        "train.py",
        "experiment=shake_table",
        f"data.path='{MODELS_DIR.relative_to(ROOT) / model}'",
        "data.run=" + ",".join(f"'{r}'" for r in runs),
        f"system.n_storeys={storeys}",
        f"hydra.sweep.dir={folder}",
        f"hydra.launcher.n_jobs={jobs}",
        "skip_done=true",
        *extra,
    ]
    run_logged(cmd, folder.name, ROOT, launcher)


def _runs(folder: Path) -> dict[str, Path]:
    """run label -> run folder of a finished run (its label read from its own config)."""
    import yaml

    out = {}
    for m in sorted(folder.glob("*/metrics.json")) if folder.is_dir() else []:
        if not (m.parent / "complete.json").is_file():  # a run that did not finish
            continue
        cfg = yaml.safe_load((m.parent / ".hydra" / "config.yaml").read_text())
        out[str(cfg["data"]["run"])] = m.parent
    return out


def identified(run: Path):
    """(system, values) of a finished run, from its own config and metrics."""
    import hydra
    from omegaconf import OmegaConf

    cfg = OmegaConf.load(run / ".hydra" / "config.yaml")
    system = hydra.utils.instantiate(cfg.system)
    fixed = {s.name: float(s.init) for s in system.param_specs() if not s.trainable}
    return system, {**fixed, **json.loads((run / "metrics.json").read_text())["params"]}


def floor_nrmse(pred: np.ndarray, meas: np.ndarray) -> list[float]:
    from pidyn.reporting import nrmse

    return [
        float(nrmse(pred[:, j], meas[:, j])) if np.all(np.isfinite(pred[:, j])) else float("inf")
        for j in range(meas.shape[1])
    ]


def predict_runs(model: str, ident_run: Path, others: list[str]) -> list[dict]:
    """The model identified on one run simulated from rest over each other run's table motion,
    and mdof's SRIM identified on the same fitting part, simulated the same way: NRMSE per floor
    of the absolute accelerations over the other run's span."""
    from pidyn.baselines.peers import io_arrays, simulate_realization, srim
    from pidyn.data.imu import xsens_record
    from pidyn.simulate import simulate_response

    system, values = identified(ident_run)
    n = system.n_dof
    ident_rec = xsens_record(MODELS_DIR / model, MODELS[model][1], fit_share=0.65)
    peer = srim(ident_rec, orders=(2 * n, 2 * n + 2, 2 * n + 4))
    rows = []
    for label in others:
        rec = xsens_record(MODELS_DIR / model, label)
        U, Y = io_arrays(rec)
        sim = simulate_response(system, values, rec)
        ours = floor_nrmse(sim["a"] + rec.f[:, None], Y.T)
        theirs = (
            floor_nrmse(simulate_realization(*peer.realization, U).T, Y.T)
            if peer.realization is not None
            else [None] * n
        )
        rows.append(
            {
                "model": model,
                "identified_on": MODELS[model][1],
                "predicted_run": label,
                "duration_s": float(rec.t[-1]),
                "pga_m_s2": rec.meta.pga,
                **{f"pidyn_a{j + 1}": ours[j] for j in range(n)},
                **{f"srim_a{j + 1}": theirs[j] for j in range(n)},
                "pidyn_mean": float(np.mean(ours)),
                "srim_mean": None if theirs[0] is None else float(np.mean(theirs)),
                "srim_order": peer.order,
            }
        )
    return rows


def run_rows(folder: Path, model: str) -> list[dict]:
    """One row per identified run: the fundamental mode with its intervals, the within-run
    held-out NRMSE per floor, SRIM's beside it, the alignment, the wall time."""
    rows = []
    for label, run in _runs(folder).items():
        m = json.loads((run / "metrics.json").read_text())
        modal = json.loads((run / "modal.json").read_text())
        modes = modal.get("modes") or [{}]
        base = (
            json.loads((run / "baselines.json").read_text()).get("baselines", [])
            if (run / "baselines.json").exists()
            else []
        )
        peer = next((b for b in base if b.get("method") == "srim"), {})
        held = (m.get("heldout") or {}).get("nrmse", {})
        fm = modes[0]
        rows.append(
            {
                "model": model,
                "run": label,
                "frequency_hz": fm.get("frequency_hz"),
                "frequency_ci95": fm.get("frequency_ci95"),
                "damping_ratio": reported_damping(fm)[0],
                "damping_ci95": reported_damping(fm)[1],
                "frequencies_hz": [md["frequency_hz"] for md in modes],
                "heldout": held,
                "heldout_mean": (m.get("heldout") or {}).get("mean_nrmse_a"),
                "srim_heldout_mean": peer.get("heldout_nrmse_a"),
                "srim_fundamental_hz": (peer.get("modes") or [{}])[0].get("frequency_hz"),
                "params": m.get("params"),
                "ci95": m.get("ci95"),
                "wall_s": m.get("wall_seconds"),
                "storey_residuals": modal.get("storey_residuals") or [],
                "start": json.loads((run / "data_start.json").read_text()).get("method")
                if (run / "data_start.json").exists()
                else None,
                "run_dir": str(run),
            }
        )
    return rows


def _fmt(v, fmt=".3f") -> str:
    return cell(v, fmt, missing="n/a")


def _ci(ci, fmt=".3f") -> str:
    return interval(ci, fmt, missing="n/a")


def alignment_rows(base: Path) -> list[dict]:
    """Per model: the held-out NRMSE of its identification run with the floors moved by their
    low-band lags (align=lag) and on the shared clock as it is (align=clock), and the lags."""
    out = []
    for model, (_, ident) in MODELS.items():
        lag = _runs(base / "shake_table" / slug(model)).get(ident)
        clock = _runs(base / "shake_table_clock" / slug(model)).get(ident)
        if lag is None or clock is None:
            continue
        ml, mc = (json.loads((r / "metrics.json").read_text()) for r in (lag, clock))
        al = (ml.get("record_meta") or {}).get("alignment") or {}
        fl = json.loads((lag / "modal.json").read_text())["modes"][0]
        fc = json.loads((clock / "modal.json").read_text())["modes"][0]
        out.append(
            {
                "model": model,
                "run": ident,
                "lags_ms": al.get("lag_ms"),
                "correlation": al.get("lag_correlation"),
                "lag_heldout": (ml.get("heldout") or {}).get("mean_nrmse_a"),
                "clock_heldout": (mc.get("heldout") or {}).get("mean_nrmse_a"),
                "lag_f": fl["frequency_hz"],
                "lag_zeta": fl["damping_ratio"],
                "clock_f": fc["frequency_hz"],
                "clock_zeta": fc["damping_ratio"],
            }
        )
    return out


def prediction_figure(model: str, ident_run: Path, label: str, path: Path) -> None:
    """The top floor's measured and predicted acceleration over another run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pidyn.data.imu import xsens_record
    from pidyn.simulate import simulate_response

    system, values = identified(ident_run)
    rec = xsens_record(MODELS_DIR / model, label)
    sim = simulate_response(system, values, rec)
    n = system.n_dof
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(rec.t, rec.a[:, n - 1] + rec.f, lw=0.6, label="measured")
    ax.plot(rec.t, sim["a"][:, n - 1] + rec.f, lw=0.6, label=f"identified on {MODELS[model][1]}, simulated")
    ax.set(
        xlabel="t (s)", ylabel=f"floor {n} acceleration (m/s^2)", title=f"{model}: run '{label}' predicted"
    )
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def aggregate(base: Path) -> None:
    """experiments/results/real/shake_table.md and its CSVs from a finished study."""
    from pidyn.data.imu import run_labels

    (RESULTS / "figures").mkdir(parents=True, exist_ok=True)
    runs, preds = [], []
    for model, (_, ident) in MODELS.items():
        folder = base / "shake_table" / slug(model)
        rows = run_rows(folder, model) + run_rows(base / "shake_table" / f"{slug(model)}_others", model)
        runs += rows
        ident_run = _runs(folder).get(ident)
        if ident_run is None:
            continue
        others = [r for r in run_labels(MODELS_DIR / model) if r != ident]
        preds += predict_runs(model, ident_run, others)
        if others:
            prediction_figure(
                model, ident_run, others[0], RESULTS / "figures" / f"shake_table_prediction_{slug(model)}.png"
            )
    with (RESULTS / "shake_table_runs.csv").open("w", newline="") as fh:
        keys = [
            "model",
            "run",
            "frequency_hz",
            "frequency_ci95",
            "damping_ratio",
            "damping_ci95",
            "heldout_mean",
            "srim_heldout_mean",
            "srim_fundamental_hz",
            "wall_s",
        ]
        w = csv.DictWriter(fh, keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(runs)
    if preds:
        with (RESULTS / "shake_table_predictions.csv").open("w", newline="") as fh:
            keys = sorted(
                {k for r in preds for k in r},
                key=lambda k: (k not in ("model", "identified_on", "predicted_run"), k),
            )
            w = csv.DictWriter(fh, keys)
            w.writeheader()
            w.writerows(preds)
    lines = report_lines(runs, preds, alignment_rows(base), diagnosis_lines(base))
    (RESULTS / "shake_table.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {RESULTS / 'shake_table.md'}")


def report_lines(
    runs: list[dict], preds: list[dict], align: list[dict], diagnosis: list[str] = ()
) -> list[str]:
    out = [
        "# Mini shake table: three building models measured by wearable IMUs",
        "",
        "Data: `data/mini_shake_table` (Xsens DOT at 120 Hz, one on the table and one per floor; see its README). "
        "Model: a shear building with viscous storey dampers, masses unknown (floor 1's is the unit), "
        "`python train.py experiment=shake_table`; every run split 65 % fitted / 35 % held out. "
        "Peer: mdof's SRIM on the same fitting part (orders 2n to 2n+4, the best stable one).",
        "",
        "## Every run: the fundamental mode with its 95 % interval",
        "",
        "| model | run | f1 (Hz) | 95 % | zeta1 (%) | 95 % | vs the identification run | held-out NRMSE (mean of floors) | SRIM's | SRIM f1 (Hz) | wall (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    out += _run_rows(runs)
    out += _prediction_lines(preds) + _residual_lines(runs) + list(diagnosis) + _timing_lines(align)
    return out


def _run_rows(runs: list[dict]) -> list[str]:
    out: list[str] = []
    for model, (_, ident) in MODELS.items():
        rows = [r for r in runs if r["model"] == model]
        ref = next((r["frequency_hz"] for r in rows if r["run"] == ident), None)
        for r in rows:
            dev = None if ref is None or r["frequency_hz"] is None else r["frequency_hz"] / ref - 1
            z, zci = r["damping_ratio"], r["damping_ci95"] or [None, None]
            out.append(
                f"| {model} | {r['run']} | {_fmt(r['frequency_hz'])} | {_ci(r['frequency_ci95'])} | "
                f"{_fmt(None if z is None else 100 * z, '.2f')} | "
                f"{_ci(None if zci[0] is None else [100 * zci[0], 100 * zci[1]], '.2f')} | "
                f"{'n/a' if dev is None else f'{100 * dev:+.1f} %'}{'' if dev is None or abs(dev) <= AGREE else ' (beyond 5 %)'} | "
                f"{_fmt(r['heldout_mean'])} | {_fmt(r['srim_heldout_mean'])} | {_fmt(r['srim_fundamental_hz'])} | "
                f"{_fmt(r['wall_s'], '.0f')} |"
            )
    return out


def _prediction_lines(preds: list[dict]) -> list[str]:
    out: list[str] = []
    if preds:
        out += [
            "",
            "## Identified on one run, the others predicted (simulated from rest from their table motion)",
            "",
            "NRMSE of the absolute floor accelerations over the whole run, per floor (floor 1 first).",
            "",
            "| model | identified on | predicted run | pidyn per floor | pidyn mean | SRIM per floor | SRIM mean |",
            "|---|---|---|---|---|---|---|",
        ]
        for p in preds:
            n = len([k for k in p if k.startswith("pidyn_a")])
            ours = ", ".join(_fmt(p[f"pidyn_a{j + 1}"]) for j in range(n))
            theirs = ", ".join(_fmt(p[f"srim_a{j + 1}"]) for j in range(n))
            out.append(
                f"| {p['model']} | {p['identified_on']} | {p['predicted_run']} | {ours} | "
                f"{_fmt(p['pidyn_mean'])} | {theirs} | {_fmt(p['srim_mean'])} |"
            )
    return out


def _residual_lines(runs: list[dict]) -> list[str]:
    from pidyn.runs.building_report import residual_table

    resid = [r for r in runs if r["run"] == MODELS[r["model"]][1] and r["storey_residuals"]]
    if not resid:
        return []
    return [
        "",
        "## What the shear model leaves of each storey's force (identification run, held-out part)",
        "",
        "F_i = -sum_(j>=i) m_j a_j from the floors' accelerations against the identified storey force on the "
        "integrated drifts (`building.md` of each run); the share of the residual each simple force shape "
        "would explain says where to look.",
        "",
        *residual_table({r["model"]: r["storey_residuals"] for r in resid}),
    ]


def _timing_lines(align: list[dict]) -> list[str]:
    out: list[str] = []
    if align:
        out += [
            "",
            "## The sensors' timing",
            "",
            "Each floor's lag against the table where the floor moves with it (0.2-2 Hz), after the sensors' shared "
            "clock; `align=lag` (the default) moves each floor by it, `align=clock` keeps the clock as it is.",
            "",
            "| model | run | lags (ms, table first) | f1 lag / clock (Hz) | zeta1 lag / clock (%) | held-out NRMSE lag / clock |",
            "|---|---|---|---|---|---|",
        ]
        for a in align:
            out.append(
                f"| {a['model']} | {a['run']} | {', '.join(f'{v:.1f}' for v in a['lags_ms'] or [])} | "
                f"{a['lag_f']:.3f} / {a['clock_f']:.3f} | {100 * a['lag_zeta']:.2f} / {100 * a['clock_zeta']:.2f} | "
                f"{_fmt(a['lag_heldout'])} / {_fmt(a['clock_heldout'])} |"
            )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--aggregate", type=Path, help="only aggregate this study folder (outputs/real/<stamp>)")
    ap.add_argument("--resume", type=Path, help="an interrupted study's folder: its finished runs are kept")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--launcher", default="joblib")
    a = ap.parse_args()
    base = a.aggregate or a.resume or ROOT / "outputs" / "real" / time.strftime("%Y-%m-%d_%H-%M-%S")
    if not a.aggregate:
        run_sweeps(base, a.jobs, a.launcher)
        diagnose_models(base)
    aggregate(base)


if __name__ == "__main__":
    main()
