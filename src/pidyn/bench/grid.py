"""What the calibration studies share: their command line, and a grid of seeded records run in a
process pool, each finished row kept in the CSV at once (a rerun skips them)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

from pidyn.cores import share_cores


def calibration_args(doc: str | None, records: Iterable[str], results: Path) -> argparse.Namespace:
    """``--records``, ``--jobs``, ``--results`` (default ``results``) and ``--fresh`` (run every
    record again)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--records", nargs="*", default=sorted(records))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--results", type=Path, default=results)
    ap.add_argument("--fresh", action="store_true", help="run every record again (a changed test)")
    return ap.parse_args()


def finished(csv: Path, keys: list[str], fresh: bool = False) -> tuple[pd.DataFrame, set[tuple]]:
    """The rows already in ``csv`` and their keys (nothing with ``fresh``)."""
    done = pd.read_csv(csv) if csv.exists() and not fresh else pd.DataFrame()
    return done, set(zip(*(done.get(k, []) for k in keys))) if len(done) else set()


def run_grid(
    csv: Path,
    done: pd.DataFrame,
    todo: list[tuple],
    one: Callable,
    describe: Callable[[dict], str],
    jobs: int,
) -> tuple[pd.DataFrame, float]:
    """``one`` over ``todo`` (a row or a list of rows each), every finished one appended to ``csv``
    and said in a line; returns every row and the seconds this run took."""
    t0, rows = time.perf_counter(), [done] if len(done) else []
    share_cores(jobs)
    with ProcessPoolExecutor(jobs) as pool:
        for k, out in enumerate(pool.map(one, todo), start=1):
            out = out if isinstance(out, list) else [out]
            rows.append(pd.DataFrame(out))
            pd.concat(rows, ignore_index=True).to_csv(csv, index=False)  # each finished record is kept
            print(f"[{k}/{len(todo)}] " + "; ".join(describe(r) for r in out), flush=True)
    return (pd.concat(rows, ignore_index=True) if rows else done), time.perf_counter() - t0
