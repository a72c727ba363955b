"""Hit rate of the diagnosis over a seeded sweep of hidden effects (``make discrepancy-bench``).

Case i hides effect ``[none, *library][i % 8]`` in a linear structure under a record, magnitude
and noise level (uniform in 0-5 %) drawn from seed 1000 + i, and runs the full diagnosis
(``diagnose.py``) in its own process. Finished cases are skipped on a rerun (resumable).
Writes ``experiments/results/discrepancy_bench.{md,csv,json}``: top-1 accuracy, false
``discrepancy`` rate on clean data, median held-out gain, parameter errors, seconds per diagnosis.

    python experiments/discrepancy_bench.py --cases 50 --jobs 2
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pidyn.discrepancy.effects import EFFECTS  # noqa: E402

NAMES = ["none", *sorted(EFFECTS)]
FAST = ["model.schedule.pretrain_iters=300", "model.schedule.pretrain_iters_window=300",
        "model.schedule.max_iters=500"]


def run_case(i: int, out: Path, extra: list[str]) -> dict:
    effect = NAMES[i % len(NAMES)]
    folder = out / f"case_{i:03d}_{effect}"
    result = folder / "diagnosis.json"
    if not result.exists():
        cmd = [sys.executable, str(ROOT / "diagnose.py"), f"data.source.effect={effect}", f"data_seed={1000 + i}",
               "noise=null", "logger=none", "trainer.enable_progress_bar=false", "num_threads=1",
               f"hydra.run.dir={folder}", *extra]
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
        if proc.returncode != 0 or not result.exists():
            return {"case": i, "hidden": effect, "error": (proc.stderr or proc.stdout)[-800:]}
    d = json.loads(result.read_text())
    hidden = d["hidden"] or {}
    row = {"case": i, "hidden": effect, "found": d["cause"] or "none", "verdict": d["verdict"],
           "record": d["record"], "noise": d.get("noise"), "seconds": d["wall_seconds"],
           "nrmse_nominal": d["gain"]["nominal"], "nrmse_extended": d["gain"]["extended"],
           "top_score": d["ranking"][0]["score"]}
    if effect != "none" and d["cause"] == effect:
        key = EFFECTS[effect].key
        truth = (hidden.get("parameters") or {}).get(key)
        est = d["parameters"].get(key)
        if truth and est is not None:
            row["param"] = key
            row["param_error_pct"] = 100 * abs(est - truth) / abs(truth)
    return row


def summarise(df: pd.DataFrame) -> dict:
    ok = df[df.get("error").isna()] if "error" in df else df
    eff = ok[ok.hidden != "none"]
    clean = ok[ok.hidden == "none"]
    ratio = (eff.nrmse_extended / eff.nrmse_nominal).dropna()
    return {
        "cases": int(len(df)),
        "failed_runs": int(len(df) - len(ok)),
        "top1_accuracy": float((ok.hidden == ok.found).mean()),
        "top1_accuracy_effects": float((eff.hidden == eff.found).mean()) if len(eff) else None,
        "missed_effects_rate": float((eff.found == "none").mean()) if len(eff) else None,
        "false_discrepancy_rate": float((clean.verdict == "discrepancy").mean()) if len(clean) else None,
        "median_heldout_nrmse_ratio_extended_over_nominal": float(ratio.median()) if len(ratio) else None,
        "median_param_error_pct": float(ok["param_error_pct"].median()) if "param_error_pct" in ok else None,
        "median_seconds_per_diagnosis": float(ok.seconds.median()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=50)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "outputs" / "discrepancy_bench")
    ap.add_argument("--full", action="store_true", help="PIDynNet's default schedule (default: a shorter one)")
    ap.add_argument("--results", type=Path, default=ROOT / "experiments" / "results")
    args, extra = ap.parse_known_args()
    extra = ([] if args.full else FAST) + extra
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futs = {pool.submit(run_case, i, args.out, extra): i for i in range(args.cases)}
        for n, fut in enumerate(as_completed(futs), 1):
            r = fut.result()
            rows.append(r)
            status = r.get("error") and "FAILED" or f"found {r['found']} ({r['seconds']:.0f} s)"
            print(f"[{n}/{args.cases}] case {r['case']} hidden {r['hidden']}: {status}", flush=True)
    df = pd.DataFrame(rows).sort_values("case")
    summary = summarise(df)
    summary["schedule"] = "default" if args.full else "short: " + " ".join(FAST)
    summary["total_case_seconds"] = float(df["seconds"].sum()) if "seconds" in df else None  # 2 cases at a time
    rows_per = []
    for name, g in df.groupby("hidden"):
        errs = g["param_error_pct"] if "param_error_pct" in g else pd.Series(dtype=float)
        rows_per.append({"hidden": name, "cases": len(g), "top1": float((g.found == name).mean()),
                         "median_param_error_pct": float(errs.median()) if errs.notna().any() else np.nan,
                         "median_nrmse_ratio": float((g.nrmse_extended / g.nrmse_nominal).median())
                         if name != "none" else np.nan})
    per = pd.DataFrame(rows_per).set_index("hidden")
    args.results.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.results / "discrepancy_bench.csv", index=False)
    (args.results / "discrepancy_bench.json").write_text(json.dumps({"summary": summary, "per_effect": per.reset_index().to_dict("records")}, indent=2, default=float))
    lines = ["# Diagnosis benchmark: hidden effects", "",
             f"{summary['cases']} seeded cases (linear SDOF m=1, c=0.5, k=15; one library effect or none hidden; "
             "shipped records scaled to PGA 3 m/s^2; noise uniform 0-5 %; fit 0-16 s, held out 16-25 s). "
             f"PIDynNet schedule: {summary['schedule']}.", "",
             "| metric | value |", "|---|---|"]
    lines += [f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in summary.items()]
    lines += ["", "| hidden effect | cases | top-1 | median parameter error % | median NRMSE ratio ext/nom |",
              "|---|---|---|---|---|"]
    for name, r in per.iterrows():
        lines.append(f"| {name} | {int(r.cases)} | {r.top1:.2f} | {r.median_param_error_pct:.3g} | {r.median_nrmse_ratio:.3g} |")
    misses = df[df.hidden != df.found]
    if len(misses):
        lines += ["", "Misses: " + "; ".join(f"case {r.case} {r.hidden} -> {r.found}" for r in misses.itertuples())]
    (args.results / "discrepancy_bench.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
