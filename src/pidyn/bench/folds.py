"""A station's events split into seeded folds, and one model identified from several of them at
once: what the leave-events-out study (``experiments/cross_event.py``) and the studies that look
again at its folds (``experiments/shared_law_check.py``) share, so that they draw the same folds."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from pidyn.data.strong_motion import csmip_record


def event_name(path: Path) -> str:
    """A CSMIP archive's event (``petrolia_25apr1992`` of ``petrolia_25apr1992_ce89324p.zip``)."""
    name = path.name.split(".")[0]
    return name.rsplit("_ce", 1)[0] if "_ce" in name else name


def station_events(records: Path, station: str, direction: str) -> tuple[list[dict], list[dict]]:
    """(events with the direction's most common channel set, the others) with their PGA."""
    rows = []
    for path in sorted(Path(records).glob("*.zip")):
        try:
            rec = csmip_record(path, station=station, direction=direction, on_missing="drop", max_outputs=1)
        except (ValueError, FileNotFoundError) as exc:
            rows.append({"event": event_name(path), "path": str(path), "error": str(exc).splitlines()[0]})
            continue
        meta = rec.meta
        rows.append(
            {
                "event": event_name(path),
                "path": str(path),
                "inputs": list(meta.input_channels),
                "outputs": list(meta.output_channels),
                "pga_g": float(meta.pga) / 9.80665,
            }
        )
    sets = [json.dumps([r["inputs"], r["outputs"]]) for r in rows if "inputs" in r]
    if not sets:
        raise ValueError(f"{records}: no readable event of station {station} in direction {direction}")
    common = max(set(sets), key=sets.count)
    keep = [r for r in rows if "inputs" in r and json.dumps([r["inputs"], r["outputs"]]) == common]
    other = [r for r in rows if r not in keep]
    return keep, other


def folds(rows: list[dict], k: int, seed: int) -> list[list[dict]]:
    """``k`` folds of the events, drawn with ``seed`` (each event predicted once)."""
    order = np.random.default_rng(seed).permutation(len(rows))
    return [[rows[i] for i in order[j::k]] for j in range(k)]


def run_logged_to(cmd: list[str], log: Path, cwd: Path) -> int:
    """``cmd`` run in ``cwd``, its command line and output appended to ``log``; its exit code."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("a") as fh:
        fh.write("+ " + " ".join(cmd) + "\n")
        fh.flush()
        return subprocess.run(cmd, cwd=cwd, stdout=fh, stderr=subprocess.STDOUT).returncode


def identify_several(
    out: Path, station: str, direction: str, label: str, overrides: list[str], train: list[dict], cwd: Path
) -> Path:
    """One model (``overrides`` of ``train.py``; ``label`` names it) from the training events at
    once, in ``out/label/run`` (a finished run is kept)."""
    run = out / label / "run"
    if (run / "complete.json").is_file():
        return run
    paths = ",".join(r["path"] for r in train)
    cmd = [
        sys.executable,
        "train.py",
        "data=csmip",
        f"data.paths=[{paths}]",
        f"data.station={station}",
        f"data.direction={direction}",
        "data.hold_out=false",
        *overrides,
        "baselines.run=[output_error]",
        "baselines.cramer_rao=false",
        "trainer.enable_progress_bar=false",
        f"hydra.run.dir={run}",
    ]
    t0 = time.perf_counter()
    rc = run_logged_to(cmd, out / label / "train.log", cwd)
    print(
        f"  {direction} {label} {out.name}: identified on {len(train)} events, exit {rc}, "
        f"{time.perf_counter() - t0:.0f} s",
        flush=True,
    )
    return run
