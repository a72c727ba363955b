"""Does the polish from rest stop short? Each fold's estimate of a leave-events-out study, polished
further by output error from rest (up to ``--nfev`` evaluations, from where the run's polish ended),
predicts the fold's unseen events again; the table sets the run's predictions beside these.

    python experiments/polish_budget_check.py --out outputs/cross_event_polished --direction longitudinal

Writes experiments/results/real/polish_budget_<station>_<direction>.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from omegaconf import open_dict

from pidyn.refine.output_error import fit_output_error
from pidyn.runs.prediction import Identified, score

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"


def fold_rows(run_dir: Path, records: Path, nfev: int) -> tuple[str, list[tuple[str, float, float]]]:
    """The fold's further polish (a line) and, per predicted event, (event, the run's NRMSE, now)."""
    run = Identified.load(run_dir)
    system, record, values = run.for_record()
    t0 = time.perf_counter()
    fit = fit_output_error(record, system, values, 4, max_nfev=nfev)
    line = f"{fit.nfev} evaluations, cost {fit.cost:.6g}, {time.perf_counter() - t0:.0f} s"
    rows = []
    for saved in sorted((run_dir.parent / "predictions").glob("*/prediction.json")):
        p = json.loads(saved.read_text())
        data = run.cfg.data.copy()
        with open_dict(data):
            data.path, data.paths = str(records / f"{p['record']}.zip"), None
        sys_e, rec_e, vals_e = run.for_record(data)
        rows.append(
            (p["record"], p["mean_nrmse_a"], score(sys_e, {**vals_e, **fit.params}, rec_e)["mean_nrmse_a"])
        )
    return line, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--out", type=Path, required=True, help="the study's output folder (cross_event.py --out)"
    )
    ap.add_argument("--station", default="CE89324")
    ap.add_argument("--direction", default="longitudinal")
    ap.add_argument("--records", type=Path, default=ROOT / "data" / "painter_street" / "records")
    ap.add_argument("--nfev", type=int, default=100)
    args = ap.parse_args()
    lines, rows = [], []
    for run_dir in sorted((args.out / args.station / args.direction).glob("fold*/default/run")):
        line, got = fold_rows(run_dir, args.records, args.nfev)
        lines.append(f"- {run_dir.parts[-3]}: {line}")
        rows += got
        print(lines[-1], flush=True)
    before, after = np.median([r[1] for r in rows]), np.median([r[2] for r in rows])
    moved = max(abs(r[2] - r[1]) for r in rows)
    out = [
        f"# The polish from rest, further: {args.station} {args.direction}",
        "",
        f"`python experiments/polish_budget_check.py --out {args.out} --direction {args.direction} --nfev {args.nfev}`:",
        "each fold's estimate polished on by output error from rest, from where its run's 20-evaluation polish ended.",
        "",
        *lines,
        "",
        f"Median NRMSE over the {len(rows)} unseen events: {before:.4f} as run, {after:.4f} polished further; "
        f"the largest change of one event {moved:.4f}.",
        "",
        "| event | as run | polished further |",
        "|---|---|---|",
        *[f"| {e.removesuffix('_' + args.station.lower() + 'p')} | {a:.4f} | {b:.4f} |" for e, a, b in rows],
    ]
    path = RESULTS / f"polish_budget_{args.station.lower()}_{args.direction}.md"
    path.write_text("\n".join(out) + "\n")
    print(path)


if __name__ == "__main__":
    main()
