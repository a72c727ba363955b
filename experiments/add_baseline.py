"""Run one classical baseline on the finished jobs of a sweep, from their saved configs.

Every run folder holds its resolved config (``.hydra/config.yaml``), so the very same record
can be rebuilt and a baseline added later without training PIDynNet again:

    python experiments/add_baseline.py outputs/tables/<stamp>/table1 --method sindy
    python experiments/aggregate.py outputs/tables/<stamp>/table1 --out experiments/results/table1 ...
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import hydra
from omegaconf import OmegaConf, open_dict

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sweep", type=Path)
    ap.add_argument(
        "--method", default="sindy", help="a baseline of conf/baselines, or cramer_rao (the bound)"
    )
    ap.add_argument(
        "--keep-saved-settings",
        action="store_true",
        help="use the method's settings from each job's saved config, not today's conf/baselines/default.yaml",
    )
    a = ap.parse_args()
    current = OmegaConf.load(ROOT / "src" / "pidyn" / "conf" / "baselines" / "default.yaml")
    from pidyn.runs.build import build_record
    from pidyn.runs.methods import run_baselines

    done = 0
    for job in sorted(p for p in a.sweep.iterdir() if (p / "metrics.json").exists()):
        cfg = OmegaConf.load(job / ".hydra" / "config.yaml")
        with open_dict(cfg):
            cfg.paths.output_dir = str(job)
            cfg.baselines.run = [] if a.method == "cramer_rao" else [a.method]  # cramer_rao: the bound again
            cfg.baselines.cramer_rao = a.method == "cramer_rao"
            if not a.keep_saved_settings and a.method in current:
                cfg.baselines[a.method] = current[a.method]  # e.g. the UKF's likelihood-tuned random walk
            cfg.baselines.setdefault("sindy", {"threshold": 0.01})
        system = hydra.utils.instantiate(cfg.system)
        record = build_record(cfg, system)
        metrics = json.loads((job / "metrics.json").read_text())
        old_path = job / "baselines.json"
        old = json.loads(old_path.read_text())["baselines"] if old_path.exists() else []
        ident = {**metrics.get("pidynnet", {}).get("params", {}), **metrics["params"]}
        new = run_baselines(cfg, system, record, job, ident)  # writes baselines.json with the new one only
        merged = [b for b in old if b["method"] != a.method] + new
        old_path.write_text(json.dumps({"baselines": merged}, indent=2, default=float))
        metrics.setdefault("baselines", {}).update(
            {b["method"]: {"error_pct": b.get("error_pct"), "seconds": b["seconds"]} for b in new}
        )
        (job / "metrics.json").write_text(json.dumps(metrics, indent=2, default=float))
        done += 1
        print(f"{job.name}: " + "; ".join(f"{b['method']} {b.get('error_pct')}" for b in new), flush=True)
    print(f"{done} job(s) updated")


if __name__ == "__main__":
    main()
