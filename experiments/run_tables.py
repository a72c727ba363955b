"""Run the table experiments as Hydra multiruns and aggregate each into markdown + CSV.

    python experiments/run_tables.py                     # full fidelity (hours on 2 cores)
    python experiments/run_tables.py --smoke             # minutes: tiny budgets, one seed (CI)
    python experiments/run_tables.py --only table1 table2

Full results go to experiments/results/<experiment>.{md,csv} with the command and machine;
smoke results to outputs/tables-smoke/.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ["table1", "table2", "table3", "scaling"]
SMOKE = {
    "table1": ["debug=smoke", "hydra.sweeper.params.seed=0", "hydra.sweeper.params.batch_size='100,400'"],
    "table2": ["debug=smoke", "hydra.sweeper.params.seed=0"],
    "table3": ["debug=smoke", "hydra.sweeper.params.seed=0", "hydra.sweeper.params.system=duffing"],
    "scaling": [
        "debug=smoke",
        "hydra.sweeper.params.seed=0",
        "hydra.sweeper.params.eq_stretch=1",
        "hydra.sweeper.params.noise=0.05",
    ],
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--only", nargs="*", default=EXPERIMENTS)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    stamp = time.strftime("%Y-%m-%d_%H-%M-%S")
    base = ROOT / "outputs" / ("tables-smoke" if a.smoke else "tables") / stamp
    for exp in a.only:
        sweep_dir = base / exp
        extra = SMOKE[exp] if a.smoke else []
        cmd = [
            sys.executable,
            "train.py",
            f"experiment={exp}",
            f"hydra.sweep.dir={sweep_dir}",
            f"hydra.launcher.n_jobs={a.jobs}",
            *extra,
        ]
        print("+", " ".join(cmd[1:]), flush=True)
        t0 = time.perf_counter()
        rc = subprocess.run(cmd, cwd=ROOT).returncode
        print(f"  {exp}: exit {rc} after {time.perf_counter() - t0:.0f} s", flush=True)
        out = (base / f"{exp}") if a.smoke else ROOT / "experiments" / "results" / exp
        machine = f"{platform.machine()}, {a.jobs} parallel jobs, one thread each"
        agg = [
            sys.executable,
            "experiments/aggregate.py",
            str(sweep_dir),
            "--out",
            str(out),
            "--title",
            f"{exp} ({'smoke' if a.smoke else 'full'}; {machine})",
            "--command",
            f"python experiments/run_tables.py {'--smoke ' if a.smoke else ''}--only {exp} --jobs {a.jobs}"
            f"  (runs: python train.py experiment={exp} {' '.join(extra)})".rstrip(),
        ]
        if subprocess.run(agg, cwd=ROOT, stdout=subprocess.DEVNULL).returncode != 0:
            raise SystemExit(f"{exp}: aggregation failed (see {sweep_dir})")


if __name__ == "__main__":
    main()
