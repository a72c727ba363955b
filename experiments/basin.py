"""Basin of attraction: from how far away does each estimator still find the parameters?

    python experiments/basin.py --cell duffing --starts 50          # make basin runs every cell
    python experiments/basin.py --cell bouc_wen_x3 --starts 50 --methods ms_measured output_error ukf

For one noise-free record per cell, ``--starts`` starting guesses are drawn (seeded): every
parameter log-uniform in [1/3, 3] x its truth (stiffness k, k1 in [1/2, 2] x). From each
start the same record is identified by
  * ``pidynnet``: PIDynNet (shortened schedule, stated in the output) + multiple-shooting
    refinement from its estimate and networks only;
  * ``output_error``: single-shooting output error from rest;
  * ``ms_measured``: the same multiple-shooting refinement, its segment states taken from
    the measured x and x' (no networks);
  * ``ukf``: the unscented Kalman filter, its random walk tuned by the innovation likelihood.
Success: every parameter within 1 % of the truth. Each start's result is saved as it
finishes (``outputs/basin/<cell>/<method>_<i>.json``), so an interrupted study resumes; rows of
the committed ``basin_<cell>.csv`` whose start matches the drawn one are kept, so a study can be
extended to more starts. ``--shard k/n`` runs only starts i with i % n == k (for parallel
processes) and writes no summary; a last run without ``--shard`` collects them. ``--collect``
runs nothing and writes the table from the starts finished so far, saying so: committed, it
lets a study that does not fit in one sitting resume elsewhere.
Writes experiments/results/basin_<cell>.{md,csv} and a figure of the starts coloured by outcome.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

from pidyn.errors import errors_pct  # noqa: E402

CELLS = {
    "duffing": {"system": "duffing", "excitation": "kobe", "eq_scale": 1.0},
    "bouc_wen_x1": {"system": "bouc_wen", "excitation": "el_centro", "eq_scale": 1.0},
    "bouc_wen_x3": {"system": "bouc_wen", "excitation": "el_centro", "eq_scale": 3.0},
}
METHODS = ["pidynnet", "output_error", "ms_measured", "ukf"]
#: PIDynNet's schedule in this study (the refinement needs a start and states, not PIDynNet's best)
SHORT = [
    "model.schedule.pretrain_iters=500",
    "model.schedule.pretrain_iters_window=500",
    "model.schedule.max_iters=1000",
    "model.schedule.max_windows=4",
]
STIFF = {"k", "k1"}


def compose(overrides: list[str], out: Path):
    """The train config with ``overrides``, its run folder ``out`` (the package's one composer)."""
    from pidyn.config import compose as compose_config

    return compose_config(
        "train",
        overrides=overrides,
        output_dir=out,
        root_dir=ROOT,
        values={"trainer.enable_progress_bar": False},
    )


def draw_starts(truth: dict[str, float], n: int, seed: int = 0) -> list[dict[str, float]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        out.append(
            {
                k: float(v * np.exp(rng.uniform(*(np.log([0.5, 2.0]) if k in STIFF else np.log([1 / 3, 3])))))
                for k, v in truth.items()
            }
        )
    return out


def _clip_start(cfg, start: dict[str, float]) -> dict[str, float]:
    """Boxed parameters (Bouc-Wen n in [0.5, 6]) keep their draw inside the box."""
    import hydra

    from pidyn.params import clip_to_bounds

    specs = {s.name: s for s in hydra.utils.instantiate(cfg.system).param_specs()}
    return {k: clip_to_bounds(specs[k], v) for k, v in start.items()}


def run_one(cell: dict, method: str, start: dict[str, float], out: Path) -> dict:
    import hydra

    from pidyn.baselines import output_error, unscented_kalman_filter
    from pidyn.refine import RefineSettings, refine
    from pidyn.runs.build import build_record
    from pidyn.tasks.train import train

    base = [
        f"system={cell['system']}",
        f"excitation={cell['excitation']}",
        f"eq_scale={cell['eq_scale']}",
        "logger=none",
        "noise=0",
    ]
    inits = [f"system.params.{k}.init={v!r}" for k, v in start.items()]
    t0 = time.perf_counter()
    if method == "pidynnet":
        cfg = compose(
            base + inits + SHORT + ["baselines=none", "model.refine.starts=[]", "resume=false"], out
        )
        m = train(cfg)
        return {
            "params": m["params"],
            "pidynnet_params": m["pidynnet"]["params"],
            "seconds": time.perf_counter() - t0,
        }
    cfg = compose(base + inits, out)
    system = hydra.utils.instantiate(cfg.system)
    record = build_record(cfg, system)
    if method == "output_error":
        res = output_error(record, system, init=start, max_nfev=200)
        params = res.params
    elif method == "ms_measured":
        params = refine(system, record, {"start": start}, RefineSettings(states="measured")).params
    elif method == "ukf":
        params = unscented_kalman_filter(
            record, system, noise_level=0.0, init=start, tune=list(cfg.baselines.ukf.tune)
        ).params
    else:
        raise ValueError(f"unknown method '{method}'; choose from {METHODS}")
    return {"params": params, "seconds": time.perf_counter() - t0}


def main() -> None:
    ap = _parser()
    a = ap.parse_args()
    if a.collect and a.shard:
        ap.error("--collect gathers every shard's results; give no --shard")
    shard = tuple(int(v) for v in a.shard.split("/")) if a.shard else (0, 1)
    import logging

    logging.basicConfig(level=logging.WARNING)
    import hydra
    import torch

    torch.set_num_threads(1)
    cell = CELLS[a.cell]
    work = ROOT / "outputs" / "basin" / a.cell
    work.mkdir(parents=True, exist_ok=True)
    cfg0 = compose([f"system={cell['system']}"], work / "probe")
    truth = hydra.utils.instantiate(cfg0.system).true_values()
    truth = {s.name: truth[s.name] for s in hydra.utils.instantiate(cfg0.system).param_specs() if s.trainable}
    starts = [_clip_start(cfg0, s) for s in draw_starts(truth, a.starts, a.seed)]
    stem = ROOT / "experiments" / "results" / f"basin_{a.cell}"
    kept = committed_rows(stem.with_suffix(".csv"), starts, truth)
    rows = []
    for i, start in enumerate(starts):
        if i % shard[1] != shard[0]:
            continue
        for method in a.methods:
            f = work / f"{method}_{i:03d}.json"
            if (i, method) in kept:
                rows.append(kept[(i, method)])
                continue
            r = _result(cell, method, start, work / f"{method}_{i:03d}", f, a.collect)
            if r is None:
                continue
            rows.append(_row(i, method, r, start, truth))
    if a.shard:
        return
    if not rows:
        print("no finished starts to collect")
        return
    df = pd.DataFrame(rows)
    df.to_csv(stem.with_suffix(".csv"), index=False)
    write_summary(df, stem, a, cell, truth)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cell", choices=list(CELLS), default="duffing")
    ap.add_argument("--starts", type=int, default=50)
    ap.add_argument("--methods", nargs="*", default=METHODS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shard", default=None, help="k/n: run only starts i with i %% n == k, no summary")
    ap.add_argument(
        "--machine-note", default="", help="how the starts were run (parallel shards), for the summary"
    )
    ap.add_argument(
        "--collect",
        action="store_true",
        help="run nothing: write the table from the starts finished so far (an interrupted study, "
        "committed, resumes from it)",
    )
    return ap


def _result(cell: dict, method: str, start: dict, folder: Path, f: Path, collect: bool) -> dict | None:
    """One start's result: read back when done, else run (None when only collecting)."""
    if f.exists():
        return json.loads(f.read_text())
    if collect:
        return None
    try:
        r = run_one(cell, method, start, folder)
    except Exception as exc:  # a diverging start is an outcome, not a crash of the study
        r = {"params": {}, "seconds": float("nan"), "error": str(exc)[:300]}
    r["start"] = start
    f.write_text(json.dumps(r, default=float))
    return r


def _row(i: int, method: str, r: dict, start: dict, truth: dict) -> dict:
    """The table's row of one start and method (printed as it is made)."""
    errs = errors_pct(r["params"], truth)
    max_err = max(errs.values()) if r["params"] else float("inf")
    print(f"start {i:3d} {method:13s} max error {max_err:10.4g} %  {r['seconds']:.0f} s", flush=True)
    return {
        "start": i,
        "method": method,
        "max_error_pct": max_err,
        "success": bool(np.isfinite(max_err) and max_err <= 1.0),
        "seconds": r["seconds"],
        **{f"start_{k}": start[k] / truth[k] for k in truth},
    }


def committed_rows(path: Path, starts: list[dict[str, float]], truth: dict[str, float]) -> dict:
    """Rows of an earlier study's CSV, keyed (start, method), kept where the start is the same draw."""
    if not path.exists():
        return {}
    kept = {}
    for r in pd.read_csv(path).to_dict("records"):
        i = int(r["start"])
        if i < len(starts) and all(
            np.isclose(r[f"start_{k}"], starts[i][k] / truth[k], rtol=1e-9) for k in truth
        ):
            kept[(i, r["method"])] = r
    return kept


def write_summary(df: pd.DataFrame, stem: Path, a, cell: dict, truth: dict) -> None:
    lines = [
        f"# Basin of attraction: {a.cell} ({cell['system']} under {cell['excitation']} x{cell['eq_scale']:g}, "
        "noise-free)\n",
        f"Command: `python experiments/basin.py --cell {a.cell} --starts {a.starts}`  ",
        f"Machine: {platform.machine()}, one thread{'; ' + a.machine_note if a.machine_note else ''}  ",
        f"Starts: {a.starts}, each parameter log-uniform in [1/3, 3] x truth (k, k1 in [1/2, 2] x), seed {a.seed}. "
        "Success: every parameter within 1 % of the truth.  ",
        f"PIDynNet's schedule here: {' '.join(SHORT)}; then the multiple-shooting refinement from its "
        "estimate and networks only.\n",
        *_progress_line(df, a),
        "| method | success rate | median seconds | median max error % |",
        "|---|---|---|---|",
    ]
    label = {
        "pidynnet": "PIDynNet + refinement",
        "output_error": "output error (single shooting)",
        "ms_measured": "multiple shooting, states from measured x, x'",
        "ukf": "UKF (tuned)",
    }
    rates = {}
    for m, g in df.groupby("method", sort=False):
        rates[m] = g.success.mean()
        lines.append(
            f"| {label.get(m, m)} | {g.success.mean():.2f} ({int(g.success.sum())}/{len(g)}) | "
            f"{np.nanmedian(g.seconds):.0f} | {np.nanmedian(g.max_error_pct):.3g} |"
        )
    if "pidynnet" in rates:
        best_other = max((v for k, v in rates.items() if k != "pidynnet"), default=np.nan)
        verdict = (
            "PIDynNet's start beats every other method here"
            if rates["pidynnet"] > best_other
            else "PIDynNet's start ties with the best other method here"
            if rates["pidynnet"] == best_other
            else "PIDynNet's start does **not** beat the best other method here"
        )
        lines.append(f"\n{verdict} ({rates['pidynnet']:.2f} against {best_other:.2f}).")
    fig = stem.parent / "figures" / f"{stem.name}.png"
    plot_starts(df, list(truth), fig)
    lines.append(f"\nStarts coloured by outcome: [{fig.name}](figures/{fig.name})")
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _progress_line(df: pd.DataFrame, a) -> list[str]:
    """Says how far an interrupted study got (the table covers the finished starts only)."""
    done = df.groupby("start").method.nunique()
    full = int((done == len(set(df.method))).sum())
    if full >= a.starts and len(done) >= a.starts:
        return []
    return [
        f"**Partial: {len(done)} of the {a.starts} starts have results ({full} with every method).** The study "
        f"resumes from this table: `python experiments/basin.py --cell {a.cell} --starts {a.starts}` (or in "
        "shards with `--shard k/n`, then `--collect`).\n"
    ]


def plot_starts(df: pd.DataFrame, names: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    methods = list(dict.fromkeys(df.method))
    a, b = names[0], names[-1]
    fig, axes = plt.subplots(1, len(methods), figsize=(3.4 * len(methods), 3.2), squeeze=False, sharey=True)
    for ax, m in zip(axes[0], methods):
        g = df[df.method == m]
        ok = g.success.to_numpy()
        ax.scatter(g[f"start_{a}"][ok], g[f"start_{b}"][ok], c="tab:green", s=18, label="found (<= 1 %)")
        ax.scatter(g[f"start_{a}"][~ok], g[f"start_{b}"][~ok], c="tab:red", marker="x", s=18, label="missed")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{m}: {ok.mean():.2f}", fontsize=9)
        ax.set_xlabel(f"start {a} / truth")
    axes[0][0].set_ylabel(f"start {b} / truth")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
