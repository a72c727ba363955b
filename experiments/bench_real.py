"""make bench's "real records" section: on the shipped Painter Street events, per event, the wall
time and the held-out NRMSE of pidyn's default, of plain output error from the data's start, and
of mdof's SRIM, side by side (results/bench_real.csv and .md).

Each event is one ``train.py`` run of the default bridge model (``data=csmip``, no ``system=``)
with the two peers as its baselines, in-process after PIDynNet so that each is timed alone:

* pidyn: the run's own stages (build, PIDynNet, refinement, report), without the peers;
* output error: the baseline fitted from the data's start (the run's starting values on a
  measured record), its held-out NRMSE from its parameters simulated from rest as pidyn's is;
* SRIM: its own held-out NRMSE and seconds (the order of lowest fitting-part error among the
  stable ones).

Rows are written as each event finishes; a second call skips the events already in the CSV
(``--fresh`` starts over). Events used while the methods were set up are reported apart.

    python experiments/bench_real.py [--direction transverse|longitudinal|both] [--events a,b]
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from real import RECORDS, TUNING, events

from pidyn.bench.tables import cell

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results"
RUNS = ROOT / "outputs" / "bench_real"
FIELDS = [
    "event",
    "direction",
    "role",
    "pidyn_wall_s",
    "pidyn_heldout",
    "oe_s",
    "oe_heldout",
    "srim_s",
    "srim_heldout",
    "trivial_heldout",
    "command_wall_s",
    "note",
]


def run_event(event: str, direction: str) -> dict:
    run_dir = RUNS / f"{event}_{direction}"
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        "data=csmip",
        f"data.path={RECORDS / 'records' / f'{event}_ce89324p.zip'}",
        "data.station=CE89324",
        f"data.direction={direction}",
        "data.on_missing=drop",
        "baselines.run=[output_error,srim]",
        "baselines.parallel=false",
        "baselines.cramer_rao=false",
        "trainer.enable_progress_bar=false",
        "resume=false",
        f"hydra.run.dir={run_dir}",
    ]
    t0 = time.perf_counter()
    rc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode
    wall = time.perf_counter() - t0
    row = {"event": event, "direction": direction, "role": "tuning" if event in TUNING else "untouched"}
    if rc != 0 or not (run_dir / "metrics.json").exists():
        failed = run_dir / "failed.json"
        why = json.loads(failed.read_text()).get("message", "") if failed.exists() else f"exit {rc}"
        return {**row, "command_wall_s": wall, "note": why.splitlines()[0] if why else f"exit {rc}"}
    metrics = json.loads((run_dir / "metrics.json").read_text())
    stages = metrics.get("stage_seconds", {})
    peers = {b["method"]: b for b in json.loads((run_dir / "baselines.json").read_text())["baselines"]}
    srim = peers.get("srim", {})
    return {
        **row,
        "pidyn_wall_s": sum(v for k, v in stages.items() if k != "baselines_wait"),
        "pidyn_heldout": (metrics.get("heldout") or {}).get("mean_nrmse_a"),
        "oe_s": peers.get("output_error", {}).get("seconds"),
        "oe_heldout": _oe_heldout(run_dir, peers.get("output_error")),
        "srim_s": srim.get("seconds"),
        "srim_heldout": srim.get("heldout_nrmse_a"),
        "trivial_heldout": (metrics.get("adequacy") or {}).get("trivial_heldout_nrmse"),
        "command_wall_s": wall,
    }


def _oe_heldout(run_dir: Path, oe: dict | None) -> float | None:
    """The output-error baseline's parameters simulated over the record from rest, scored on the
    held-out part as the run scores its own model."""
    if not oe or not oe.get("params"):
        return None
    from pidyn.assessment import heldout_scores
    from pidyn.runs.prediction import Identified
    from pidyn.simulate import simulate_response

    system, record, values = Identified.load(run_dir).for_record()
    split = record.meta.split
    if not split:
        return None
    sim = simulate_response(system, {**values, **oe["params"]}, record)
    return heldout_scores(sim, record, split.heldout)["mean_nrmse_a"]


def read_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with path.open() as fh:
        return [{k: (v if v != "" else None) for k, v in r.items()} for r in csv.DictReader(fh)]


def write_rows(path: Path, rows: list[dict]) -> None:
    tmp = path.with_suffix(".tmp")
    with tmp.open("w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        w.writerows([{k: r.get(k) for k in FIELDS} for r in rows])
    tmp.replace(path)


def _f(v, fmt: str = ".3f") -> str:
    return cell(v, fmt, missing="")


def markdown(rows: list[dict]) -> list[str]:
    lines = [
        "## Real records: the Painter Street events, side by side",
        "",
        "Per event, `train.py data=csmip` (the default bridge model) with plain output error from the data's",
        "start and mdof's SRIM as its baselines, run one after the other in the same command. Held-out: the",
        "mean NRMSE of the deck accelerations on the last 35 % of the shaking, every model simulated from",
        "rest. Knowing nothing: the deck moving with the mean of its supports. Seconds as this machine ran",
        "them (2 cores, with whatever else it ran at the time: compare within a row, not between rows).",
        "",
    ]
    for direction in ("transverse", "longitudinal"):
        rs = [r for r in rows if r["direction"] == direction]
        if not rs:
            continue
        lines += [
            f"### {direction}",
            "",
            "| event | role | pidyn s | pidyn held-out | OE s | OE held-out | SRIM s | SRIM held-out | knowing nothing |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in sorted(rs, key=lambda r: (r["role"], r["event"])):
            if r.get("note") and not r.get("pidyn_heldout"):
                lines.append(f"| {r['event']} | {r['role']} | not run: {r['note']} |  |  |  |  |  |  |")
                continue
            lines.append(
                f"| {r['event']} | {r['role']} | {_f(r.get('pidyn_wall_s'), '.1f')} | {_f(r.get('pidyn_heldout'))} | "
                f"{_f(r.get('oe_s'), '.2f')} | {_f(r.get('oe_heldout'))} | {_f(r.get('srim_s'), '.2f')} | "
                f"{_f(r.get('srim_heldout'))} | {_f(r.get('trivial_heldout'))} |"
            )
        lines += ["", *summary(rs), ""]
    return lines


def summary(rows: list[dict]) -> list[str]:
    out = []
    for role in ("untouched", "tuning"):
        rs = [r for r in rows if r["role"] == role]
        if not rs:
            continue
        cells = []
        for key, name in (("pidyn", "pidyn"), ("oe", "output error"), ("srim", "SRIM")):
            held = [float(r[f"{key}_heldout"]) for r in rs if r.get(f"{key}_heldout") not in (None, "")]
            secs = [
                float(r[f"{key}_wall_s" if key == "pidyn" else f"{key}_s"])
                for r in rs
                if r.get(f"{key}_heldout") not in (None, "")
            ]
            finite = [h for h in held if np.isfinite(h)]
            if finite:
                cells.append(
                    f"{name} median held-out {np.median(finite):.3f} on {len(finite)} of {len(rs)} "
                    f"(median {np.median(secs):.1f} s)"
                )
        label = "kept out of all tuning" if role == "untouched" else "used while the methods were set up"
        out.append(f"- Events {label}: " + "; ".join(cells) + ".")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--direction", default="transverse", choices=["transverse", "longitudinal", "both"])
    ap.add_argument(
        "--events", default=None, help="comma-separated archive names (default: every shipped event)"
    )
    ap.add_argument("--fresh", action="store_true", help="run every event again")
    args = ap.parse_args()
    csv_path, md_path = OUT / "bench_real.csv", OUT / "bench_real.md"
    rows = [] if args.fresh else read_rows(csv_path)
    done = {(r["event"], r["direction"]) for r in rows}
    directions = ["transverse", "longitudinal"] if args.direction == "both" else [args.direction]
    todo = [
        (e, d)
        for d in directions
        for e in (args.events.split(",") if args.events else events())
        if (e, d) not in done
    ]
    for i, (event, direction) in enumerate(todo, 1):
        print(f"[{i}/{len(todo)}] {event} {direction}", flush=True)
        rows.append(run_event(event, direction))
        write_rows(csv_path, rows)
        md_path.write_text("\n".join(markdown(rows)) + "\n")
    md_path.write_text("\n".join(markdown(rows)) + "\n")
    print(f"wrote {md_path}")


if __name__ == "__main__":
    main()
