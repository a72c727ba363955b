"""Which support misses what: the rigid deck's diagnosis of every shipped event of a station,
across the deck (transverse), as one Hydra multirun.

Each event's nominal linear deck is refined on its fitting part; every library effect at every
support is scored by what it would change in the deck channels, the best few are refined, and one
is named only where it predicts the held-out channels better. The events looked at while the
methods were set up (``real.TUNING``) are reported apart from the others.

    python experiments/deck_diagnosis.py                          # Painter Street (CE89324), two jobs
    python experiments/deck_diagnosis.py --resume outputs/deck_diagnosis/<stamp>
    python experiments/deck_diagnosis.py --events petrolia_25apr1992 riodell82

Writes experiments/results/real/deck_diagnosis_<station>.md and .csv.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np
from real import TUNING

from pidyn.bench.launch import run_logged
from pidyn.cores import share_cores

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"
STATIONS = {"CE89324": ROOT / "data" / "painter_street" / "records"}


def events(station: str) -> list[str]:
    suffix = f"_{station.lower()}p.zip"
    return sorted(p.name[: -len(suffix)] for p in STATIONS[station].glob(f"*{suffix}"))


def run(base: Path, station: str, chosen: list[str], jobs: int) -> None:
    """The multirun; folders that hold their diagnosis are kept (``skip_done``)."""
    share_cores(jobs)
    cmd = [
        sys.executable,
        "diagnose.py",
        "-m",
        "data=csmip",
        "system=rigid_deck",
        f"data.station={station}",
        "data.direction=transverse",
        "data.on_missing=drop",
        f"data.records={STATIONS[station]}",
        f"data.event={','.join(chosen)}",
        f"data.path=${{data.records}}/${{data.event}}_{station.lower()}p.zip",
        "hydra/launcher=joblib",
        f"hydra.launcher.n_jobs={jobs}",
        f"hydra.sweep.dir={base}",
        "hydra.sweep.subdir=${data.event}",
        "trainer.enable_progress_bar=false",
        "skip_done=true",
    ]
    run_logged(cmd, "deck diagnosis", ROOT)


def rows(base: Path, chosen: list[str]) -> list[dict]:
    """One row per event: its verdict, where, the held-out errors, the notes' codes."""
    out = []
    for event in chosen:
        path = base / event / "diagnosis.json"
        if not path.exists():
            failed = base / event / "failed.json"
            why = json.loads(failed.read_text())["message"] if failed.exists() else "not run"
            out.append({"event": event, "status": f"no diagnosis: {why}", "role": role(event)})
            continue
        d = json.loads(path.read_text())
        g = d["gain"]
        out.append(
            {
                "event": event,
                "status": "ok",
                "role": role(event),
                "verdict": d["verdict"],
                "findings": "; ".join(f"{f['effect']} at support {f['at']}" for f in d["findings"]),
                "heldout_nominal": g["nominal"],
                "heldout_extended": g.get("extended"),
                "heldout_trivial": g.get("trivial"),
                "tried": len(d.get("steps") or []),
                "best_score": (d.get("ranking") or [{}])[0].get("share"),
                "best_candidate": _best(d),
                "fit_test_failed": bool(d["fit_test"]["failed"]),
                "note_codes": ";".join(sorted(set(d.get("note_codes") or []))),
                "wall_s": d.get("wall_seconds"),
            }
        )
    return out


def role(event: str) -> str:
    return "tuning" if event in TUNING else "kept out"


def _best(d: dict) -> str:
    r = (d.get("ranking") or [None])[0]
    return "" if r is None else f"{r['effect']} at support {r['support']}"


def write(station: str, table: list[dict], base: Path) -> None:
    """The markdown table (tuning events and the others apart) and the CSV."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = f"deck_diagnosis_{station.lower()}"
    keys = sorted({k for r in table for k in r})
    with open(RESULTS / f"{name}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(table)
    lines = [
        f"# Which support misses what: the rigid deck's diagnosis, station {station}, across the deck",
        "",
        f"`python experiments/deck_diagnosis.py` ({time.strftime('%Y-%m-%d')}; runs in `{base.name}`). "
        "The nominal linear deck on its fitting part, every library effect at every support scored by what "
        "it would change in the deck channels, the best three refined, one named only where it predicts the "
        "held-out channels at least 5 % better. Held-out NRMSE: the mean over the deck channels of their "
        "absolute acceleration, simulated from rest; knowing nothing: the deck moving with a support.",
        "",
    ]
    for which in ("kept out", "tuning"):
        part = [r for r in table if r["role"] == which]
        lines += [f"## Events {which} ({len(part)})", "", *_table(part), ""]
        ok = [r for r in part if r["status"] == "ok"]
        if ok:
            verdicts = {v: sum(r["verdict"] == v for r in ok) for v in ("none", "discrepancy", "unexplained")}
            beats = sum(r["heldout_nominal"] < r["heldout_trivial"] for r in ok)
            lines += [
                f"Verdicts: {verdicts}. The nominal deck beats knowing nothing on {beats} of {len(ok)}; "
                f"median held-out NRMSE {np.median([r['heldout_nominal'] for r in ok]):.3f} (knowing nothing "
                f"{np.median([r['heldout_trivial'] for r in ok]):.3f}); median wall {np.median([r['wall_s'] for r in ok]):.0f} s.",
                "",
            ]
    lines += _where(table)
    (RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {RESULTS / name}.md")


def _where(table: list[dict]) -> list[str]:
    """Where the named effects sit, over every diagnosed event: which supports, how often."""
    named = [f for r in table if r["status"] == "ok" and r["findings"] for f in r["findings"].split("; ")]
    if not named:
        return []
    supports = sorted({f.rsplit(" ", 1)[-1] for f in named})
    counts = ", ".join(f"support {j}: {sum(f.endswith(f'support {j}') for f in named)}" for j in supports)
    ok = [r for r in table if r["status"] == "ok"]
    better = sum(
        r["heldout_extended"] is not None and r["heldout_extended"] < r["heldout_trivial"] for r in ok
    )
    return [
        "## Where",
        "",
        f"{len(named)} effects named on {sum(bool(r['findings']) for r in ok)} of {len(ok)} diagnosed events; "
        f"by support: {counts}. An extended deck predicts the held-out channels better than knowing "
        f"nothing on {better} of those {sum(bool(r['findings']) for r in ok)}.",
        "",
    ]


def _table(part: list[dict]) -> list[str]:
    out = [
        "| event | verdict | named | best scored | held-out nominal | extended | knowing nothing | notes | wall (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in part:
        if r["status"] != "ok":
            out.append(f"| {r['event']} | {r['status']} | | | | | | | |")
            continue
        ext = "" if r["heldout_extended"] is None else f"{r['heldout_extended']:.3f}"
        out.append(
            f"| {r['event']} | {r['verdict']} | {r['findings']} | {r['best_candidate']} | "
            f"{r['heldout_nominal']:.3f} | {ext} | {r['heldout_trivial']:.3f} | {r['note_codes']} | {r['wall_s']:.0f} |"
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--station", default="CE89324", choices=sorted(STATIONS))
    ap.add_argument("--events", nargs="*", help="a subset of the station's events (archive names)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--resume", type=Path, help="an interrupted study's folder: its finished runs are kept")
    args = ap.parse_args()
    chosen = args.events or events(args.station)
    base = args.resume or ROOT / "outputs" / "deck_diagnosis" / time.strftime("%Y%m%d-%H%M%S")
    run(base, args.station, chosen, args.jobs)
    write(args.station, rows(base, chosen), base)


if __name__ == "__main__":
    main()
