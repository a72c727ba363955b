"""Aggregate multirun job folders into the paper's tables (markdown + CSV).

    python experiments/aggregate.py outputs/table3/multiruns/<stamp> [--out experiments/results/table3]
    python experiments/aggregate.py SWEEP_A SWEEP_B ... --out experiments/results/scaling

Each job folder holds metrics.json, baselines.json and cramer_rao.json; jobs that failed
(no metrics.json) are listed and skipped. Rows are grouped into cells by system, noise,
batch size, earthquake scaling and stretching; per parameter the table shows the truth, the
paper's values, PIDynNet's mean +- std and RMS error over seeds, the Cramer-Rao bound, and
each baseline's RMS error. Several sweep folders can be aggregated together (cells run at
different times, seeds added later); with more than one cell a system gets a summary table,
one row per cell, so trends across noise, scaling or batch size read at a glance. Each cell
also gets Figure 3 (PIDynNet's and the UKF's estimates over record time for every seed, with
the Cramer-Rao std), written to figures/ beside the markdown and linked from it.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
from omegaconf import OmegaConf

from pidyn.baselines.registry import entries
from pidyn.runs.folder import is_complete

# Paper Tables I-III (value, error %), PIDynNet and UKF.
PAPER = {
    ("duffing", 0.0): {
        "PIDynNet": {"c": (0.494, 1.19), "k1": (14.981, 0.13), "k3": (122.392, 1.99)},
        "UKF": {"c": (0.513, 2.86), "k1": (14.564, 2.91), "k3": (118.164, 1.53)},
    },
    ("bouc_wen", 0.0): {
        "PIDynNet": {
            "c": (0.295, 1.50),
            "k": (11.954, 0.38),
            "beta": (0.982, 1.77),
            "gamma": (1.963, 1.87),
            "n": (2.051, 2.57),
        },
        "UKF": {
            "c": (0.286, 4.58),
            "k": (11.987, 0.11),
            "beta": (0.988, 1.25),
            "gamma": (2.051, 2.57),
            "n": (2.064, 3.21),
        },
    },
    ("bouc_wen", 0.025): {
        "PIDynNet": {
            "c": (0.301, 0.37),
            "k": (12.032, 0.27),
            "beta": (1.017, 1.72),
            "gamma": (1.952, 2.41),
            "n": (1.989, 0.56),
        },
        "UKF": {
            "c": (0.292, 2.53),
            "k": (12.016, 0.13),
            "beta": (0.975, 2.49),
            "gamma": (2.022, 1.08),
            "n": (1.960, 2.02),
        },
    },
    ("bouc_wen", 0.05): {
        "PIDynNet": {
            "c": (0.294, 1.84),
            "k": (11.987, 0.11),
            "beta": (1.027, 2.70),
            "gamma": (1.950, 2.50),
            "n": (2.020, 1.02),
        },
        "UKF": {
            "c": (0.316, 5.49),
            "k": (11.956, 0.36),
            "beta": (0.971, 2.86),
            "gamma": (1.948, 2.58),
            "n": (2.064, 3.18),
        },
    },
}
#: the parametric estimators in the tables' order, and their labels (from the estimator registry)
METHODS = [name for name, e in entries().items() if e.parametric]
LABEL = {name: e.label for name, e in entries().items()}


def _from_config(d: Path, job: dict) -> None:
    """Fill the excitation keys older metrics.json files lack from the job's own config."""
    cfg_file = d / ".hydra" / "config.yaml"
    missing = [k for k in ("eq_scale", "eq_stretch") if k not in job]
    if missing and cfg_file.exists():
        cfg = OmegaConf.load(cfg_file)
        for k in missing:
            if k in cfg:
                job[k] = float(cfg[k])


def load_jobs(root: Path, label: str = "") -> tuple[list[dict], list[str]]:
    if not root.is_dir():
        raise SystemExit(f"{root}: not a sweep folder")
    jobs, failed = [], []
    for d in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        m = d / "metrics.json"
        if not m.exists() or not is_complete(d):  # only a finished run's results count
            failed.append(f"{label}{d.name}")
            continue
        job = json.loads(m.read_text())
        _from_config(d, job)
        b = d / "baselines.json"
        job["_baselines"] = json.loads(b.read_text())["baselines"] if b.exists() else []
        c = d / "cramer_rao.json"
        job["_crb"] = json.loads(c.read_text()) if c.exists() else None
        job["_dir"] = d.name
        s = d / "subperiod_state.json"
        job["_trajectory"] = json.loads(s.read_text()).get("trajectory", []) if s.exists() else []
        jobs.append(job)
    return jobs, failed


def cell_key(j: dict) -> tuple:
    return (
        j["system"],
        j["record"],
        float(j["noise"]),
        int(j["batch_size"]),
        float(j.get("eq_scale", 1.0)),
        float(j.get("eq_stretch", 1.0)),
    )


def load_cells(roots: Path | list[Path]) -> tuple[dict[tuple, list[dict]], list[str]]:
    roots = [roots] if isinstance(roots, Path) else list(roots)
    cells: dict[tuple, list[dict]] = defaultdict(list)
    failed: list[str] = []
    for root in roots:
        jobs, f = load_jobs(root, f"{root.name}/" if len(roots) > 1 else "")
        failed += f
        for j in jobs:
            cells[cell_key(j)].append(j)
    return cells, failed


def figure_name(key: tuple) -> str:
    system, record, noise, batch, scale, stretch = key
    return f"{system}_{record}_x{scale:g}_stretch{stretch:g}_noise{100 * noise:g}_batch{batch}".replace(
        ".", "p"
    )


def plot_cells(cells: dict[tuple, list[dict]], fig_dir: Path, prefix: str) -> dict[tuple, str]:
    """Figure 3 per cell (PIDynNet and UKF estimates over record time, every seed); returns
    each cell's file name."""
    from pidyn.reporting import plot_convergence_seeds

    fig_dir.mkdir(parents=True, exist_ok=True)
    names = {}
    for key, js in sorted(cells.items()):
        runs = {
            "PIDynNet": [j["_trajectory"] for j in js],
            "UKF": [b.get("trajectory") or [] for j in js for b in j["_baselines"] if b["method"] == "ukf"],
        }
        crb = [j["_crb"]["std_pct"] for j in js if j["_crb"]]
        bound = (
            {n: float(np.nanmean([c.get(n, np.nan) for c in crb])) for n in js[0]["params"]} if crb else None
        )
        name = f"{prefix}_{figure_name(key)}.png"
        system, record, noise, batch, scale, stretch = key
        if plot_convergence_seeds(
            fig_dir / name,
            runs,
            js[0]["truth"],
            bound,
            title=f"{system} under {record} x{scale:g} (stretch {stretch:g}), noise "
            f"{100 * noise:g} %, batch {batch}: {len(js)} seed(s)",
        ):
            names[key] = name
    return names


def aggregate(roots: Path | list[Path]) -> tuple[pd.DataFrame, list[str]]:
    cells, failed = load_cells(roots)
    return table(cells), failed


def _pidynnet(j: dict) -> dict:
    """PIDynNet's own estimate: ``pidynnet`` in runs with a refinement stage, else the run's params."""
    return j.get("pidynnet") or {"params": j["params"], "error_pct": j["error_pct"]}


def _refined(js: list[dict]) -> list[dict]:
    return [j for j in js if "pidynnet" in j and j.get("refine", "none") != "none"]


def _refined_columns(js: list[dict], n: str, truth: float | None, crb: float) -> dict:
    """PIDynNet + refinement: mean, std, RMS error, RMS / Cramer-Rao std, 95 % interval coverage."""
    ref = _refined(js)
    if not ref:
        return {
            k: np.nan
            for k in (
                "refined_mean",
                "refined_std",
                "refined_rms_err",
                "refined_over_crb",
                "coverage",
                "ci_half_pct",
                "refine_seconds",
            )
        }
    vals = np.array([j["params"][n] for j in ref])
    errs = np.array([j["error_pct"].get(n, np.nan) for j in ref])
    rms = float(np.sqrt(np.nanmean(errs**2)))
    cis = [j["ci95"][n] for j in ref if j.get("ci95") and n in j["ci95"]]
    # noise-free data: the interval measures the integrator's misfit, not noise; coverage is undefined
    noisy = any((j.get("noise") or 0) > 0 for j in ref)
    cover = [lo <= truth <= hi for lo, hi in cis] if truth is not None and noisy else []
    return {
        "refined_mean": vals.mean(),
        "refined_std": vals.std(ddof=1) if len(vals) > 1 else 0.0,
        "refined_rms_err": rms,
        "refined_over_crb": rms / crb if crb and crb > 0 else np.nan,
        "coverage": float(np.mean(cover)) if cover else np.nan,
        "ci_half_pct": float(np.mean([100 * (hi - lo) / 2 / abs(truth) for lo, hi in cis]))
        if cis and truth
        else np.nan,
        "refine_seconds": float(np.mean([j["refinement"]["seconds"] for j in ref if j.get("refinement")])),
    }


def _compared_rms(js: list[dict], source: str, n: str) -> float:
    """RMS error of the refinement from PIDynNet's parameters with segment states from
    ``source`` (``model.refine.compare_states``), where the runs have it."""
    e = [
        j["refine_compare"][source]["error_pct"].get(n)
        for j in js
        if source in (j.get("refine_compare") or {})
    ]
    e = [x for x in e if x is not None]
    return float(np.sqrt(np.mean(np.square(e)))) if e else np.nan


def table(cells: dict[tuple, list[dict]]) -> pd.DataFrame:
    """One row per cell and parameter."""
    rows = []
    for key, js in sorted(cells.items()):
        system, record, noise, batch, scale, stretch = key
        names = list(js[0]["params"])
        paper = PAPER.get((system, noise), {}) if scale == 1.0 and stretch == 1.0 else {}
        for n in names:
            truth = js[0]["truth"].get(n)
            vals = np.array([_pidynnet(j)["params"][n] for j in js])
            errs = np.array([_pidynnet(j)["error_pct"].get(n, np.nan) for j in js])
            row = {
                "system": system,
                "record": record,
                "noise": noise,
                "batch_size": batch,
                "eq_scale": scale,
                "eq_stretch": stretch,
                "param": n,
                "truth": truth,
                "seeds": len(js),
                "paper_pidynnet": paper.get("PIDynNet", {}).get(n, (np.nan, np.nan))[0],
                "paper_pidynnet_err": paper.get("PIDynNet", {}).get(n, (np.nan, np.nan))[1],
                "paper_ukf_err": paper.get("UKF", {}).get(n, (np.nan, np.nan))[1],
                "pidynnet_mean": vals.mean(),
                "pidynnet_std": vals.std(ddof=1) if len(vals) > 1 else 0.0,
                "pidynnet_err_mean": np.nanmean(errs),
                "pidynnet_rms_err": float(np.sqrt(np.nanmean(errs**2))),
                "crb_std_pct": np.nanmean([j["_crb"]["std_pct"].get(n, np.nan) for j in js if j["_crb"]])
                if any(j["_crb"] for j in js)
                else np.nan,
                "pidynnet_seconds": np.mean([j["wall_seconds"] for j in js]),
            }
            row.update(_refined_columns(js, n, truth, row["crb_std_pct"]))
            row["integrated_rms_err"] = _compared_rms(js, "integrated", n)
            for mth in METHODS:
                e = [b.get("error_pct", {}).get(n) for j in js for b in j["_baselines"] if b["method"] == mth]
                e = [x for x in e if x is not None]
                row[f"{mth}_rms_err"] = float(np.sqrt(np.mean(np.square(e)))) if e else np.nan
                ran = [b for j in js for b in j["_baselines"] if b["method"] == mth]
                s = [b["seconds"] for b in ran if b.get("params")]  # a method that did not apply took no time
                row[f"{mth}_seconds"] = float(np.mean(s)) if s else np.nan
                row[f"{mth}_note"] = ran[0].get("note", "") if ran and not s else ""
            rows.append(row)
    return pd.DataFrame(rows)


CELL = ["system", "record", "noise", "batch_size", "eq_scale", "eq_stretch"]


def _num(x, d: int = 3) -> str:
    return "-" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{d}f}"


def _short(x) -> str:
    """Two significant digits for errors that span 0.01 % to 90 %."""
    if _num(x) == "-":
        return "-"
    if 0 < abs(x) < 0.01:
        return "<0.01"
    return f"{x:.2g}" if abs(x) < 10 else f"{x:.0f}"


def summary(df: pd.DataFrame) -> list[str]:
    """One row per cell and one column per parameter: how the errors move across the cells."""
    out = []
    for system, gs in df.groupby("system", sort=False):
        cells = gs.groupby(CELL, sort=False)
        if cells.ngroups < 2:
            continue
        names = list(dict.fromkeys(gs.param))
        out.append(
            f"\n## Summary, {system}: RMS error % over seeds, PIDynNet / PIDynNet + refinement / "
            "output-error LS / UKF (Cramer-Rao std %)\n"
        )
        out.append("| record | scale | stretch | noise % | batch | seeds | " + " | ".join(names) + " |")
        out.append("|---|---|---|---|---|---|" + "---|" * len(names))
        for key, g in cells:
            _, record, noise, batch, scale, stretch = key
            by = g.set_index("param")
            vals = [
                f"{_short(by.pidynnet_rms_err[n])} / {_short(by.refined_rms_err[n])} / "
                f"{_short(by.output_error_rms_err[n])} / "
                f"{_short(by.ukf_rms_err[n])} ({_short(by.crb_std_pct[n])})"
                for n in names
            ]
            out.append(
                f"| {record} | {scale:g} | {stretch:g} | {100 * noise:g} | {batch} | {int(g.seeds.iloc[0])} | "
                + " | ".join(vals)
                + " |"
            )
    return out


def to_markdown(
    df: pd.DataFrame,
    title: str,
    command: str,
    failed: list[str],
    figures: dict[tuple, str] | None = None,
    fig_rel: str = "figures",
) -> str:
    f = _num
    out = [f"# {title}\n", f"Command: `{command}`\n", *summary(df)]
    for key, g in df.groupby(CELL, sort=False):
        system, record, noise, batch, scale, stretch = key
        out.append(
            f"\n## {system} under {record} x{scale:g} (stretch {stretch:g}), noise {100 * noise:g} %, "
            f"batch {batch}, {int(g.seeds.iloc[0])} seed(s)\n"
        )
        out.append(
            "| param | truth | paper PIDynNet (err %) | paper UKF err % | PIDynNet mean +- std | "
            "PIDynNet RMS err % | PIDynNet + refinement RMS err % | CRB std % | refined RMS / CRB | "
            "95 % interval coverage (mean half width %) | EE RMS err % | SINDy RMS err % | OE RMS err % | "
            "UKF RMS err % |"
        )
        out.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        integrated = bool(g.integrated_rms_err.notna().any())
        if integrated:  # the refinement from the same parameters, states from integrated accelerations
            out[-2] += " refinement from integrated accelerations RMS err % |"
            out[-1] += "---|"
        for _, r in g.iterrows():
            out.append(
                f"| {r.param} | {f(r.truth, 4)} | {f(r.paper_pidynnet, 3)} ({f(r.paper_pidynnet_err, 2)}) | "
                f"{f(r.paper_ukf_err, 2)} | {f(r.pidynnet_mean, 4)} +- {f(r.pidynnet_std, 4)} | "
                f"{f(r.pidynnet_rms_err, 2)} | {f(r.refined_rms_err, 3)} | {f(r.crb_std_pct, 3)} | "
                f"{f(r.refined_over_crb, 2)} | {f(r.coverage, 2)} ({f(r.ci_half_pct, 3)}) | "
                f"{f(r.equation_error_rms_err, 2)} | "
                f"{f(r.sindy_rms_err, 2)} | {f(r.output_error_rms_err, 2)} | {f(r.ukf_rms_err, 2)} |"
                + (f" {f(r.integrated_rms_err, 3)} |" if integrated else "")
            )
        r0 = g.iloc[0]
        out.append(
            f"\nWall seconds per run: PIDynNet run {f(r0.pidynnet_seconds, 0)} (of which refinement "
            f"{f(r0.refine_seconds, 1)}), EE {f(r0.equation_error_seconds, 2)}, "
            f"SINDy {f(r0.sindy_seconds, 2)}, OE {f(r0.output_error_seconds, 1)}, UKF {f(r0.ukf_seconds, 1)}."
        )
        na = {LABEL[m]: r0[f"{m}_note"] for m in METHODS if r0.get(f"{m}_note")}
        if na:
            out.append("\n" + "; ".join(f"{m}: {note}" for m, note in na.items()) + ".")
        if figures and key in figures:
            out.append(
                f"\nFigure 3, estimates over record time, every seed, PIDynNet and UKF: "
                f"[{figures[key]}]({fig_rel}/{figures[key]})"
            )
    if failed:
        out.append(f"\nFailed jobs (no metrics.json): {', '.join(failed)}")
    return "\n".join(out) + "\n"


def modes_summary(cells: dict[tuple, list[dict]]) -> str:
    """For buildings: the final estimate's natural frequencies and damping ratios against the
    truth's, RMS error % over seeds per mode, and the smallest mode-shape MAC."""
    out = []
    for key, js in sorted(cells.items()):
        ms = [j["modes"] for j in js if j.get("modes", {}).get("frequency_error_pct")]
        if not ms:
            continue
        first = ms[0]  # seed 0's identified frequencies label the modes
        n = len(ms[0]["frequency_error_pct"])
        out.append(
            f"\n## Modes, {key[0]} under {key[1]} x{key[4]:g}, noise {100 * key[2]:g} %: final estimate, "
            f"{len(ms)} seeds\n"
        )
        out.append("| mode | f (Hz), seed 0 | frequency RMS err % | damping ratio RMS err % | min MAC |")
        out.append("|---|---|---|---|---|")
        for r in range(n):
            fe = np.sqrt(np.mean([m["frequency_error_pct"][r] ** 2 for m in ms]))
            de = np.sqrt(np.mean([m["damping_error_pct"][r] ** 2 for m in ms]))
            mac = min(m["mac"][r] for m in ms)
            out.append(
                f"| {r + 1} | {first['identified']['frequency_hz'][r]:.4f} | {_short(fe)} | {_short(de)} | "
                f"{mac:.6f} |"
            )
    return "\n".join(out) + ("\n" if out else "")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument(
        "root", type=Path, nargs="+", help="one or more multirun folders (outputs/tables/<stamp>/<exp>)"
    )
    ap.add_argument("--out", type=Path, default=None, help="output stem (default: <root>/table)")
    ap.add_argument("--title", default=None)
    ap.add_argument("--command", default="")
    ap.add_argument("--no-figures", action="store_true", help="skip the per-cell Figure 3")
    a = ap.parse_args()
    cells, failed = load_cells(a.root)
    df = table(cells)
    if df.empty:
        raise SystemExit(f"{', '.join(map(str, a.root))}: no finished job (failed: {failed})")
    out = a.out or a.root[0] / "table"
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    figures = {} if a.no_figures else plot_cells(cells, out.parent / "figures", out.name)
    text = to_markdown(df, a.title or a.root[0].parent.parent.name, a.command, failed, figures)
    out.with_suffix(".md").write_text(text + modes_summary(cells))
    print(out.with_suffix(".md").read_text())


if __name__ == "__main__":
    main()
