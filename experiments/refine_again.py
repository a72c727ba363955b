"""Run the refinement stage again on the finished jobs of a sweep, from their saved configs,
PIDynNet estimates and network states, without training PIDynNet again:

    python experiments/refine_again.py outputs/tables/<stamp>/table3
    python experiments/refine_again.py SWEEP --set initial_state=free --set segment_length=2.0
    python experiments/aggregate.py SWEEP --out experiments/results/table3 ...

The refinement settings are today's ``conf/model/refine/multiple_shooting.yaml`` (the job's
own ``starts`` and ``compare_states`` kept), then the ``--set`` overrides. Each job's
``metrics.json``, ``refinement.json`` and ``identified_params.yaml`` are rewritten; the
PIDynNet part of them (``pidynnet``, windows, baselines) is left as it was.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import hydra
import numpy as np
import yaml
from omegaconf import OmegaConf, open_dict

ROOT = Path(__file__).resolve().parents[1]


def _settings(saved: dict | str | None, overrides: list[str]) -> dict:
    current = OmegaConf.to_container(
        OmegaConf.load(ROOT / "src" / "pidyn" / "conf" / "model" / "refine" / "multiple_shooting.yaml")
    )
    assert isinstance(current, dict)
    if isinstance(saved, dict):
        for key in ("starts", "compare_states"):
            if key in saved:
                current[key] = saved[key]
    for item in overrides:
        key, _, value = item.partition("=")
        if key not in current:
            raise SystemExit(f"--set {item}: unknown refinement setting '{key}'; known: {', '.join(current)}")
        current[key] = yaml.safe_load(value)
    return current


def refine_job(job: Path, overrides: list[str]) -> dict:
    from pidyn.models.schedule import WindowResult
    from pidyn.reporting import write_json, write_yaml
    from pidyn.runs.build import build_record
    from pidyn.runs.methods import run_refinement
    from pidyn.runs.metrics import channel_nrmse, relative_errors
    from pidyn.runs.report import identified_params, refined_metrics
    from pidyn.simulate import simulate_response

    cfg = OmegaConf.load(job / ".hydra" / "config.yaml")
    with open_dict(cfg):
        cfg.model.refine = _settings(
            OmegaConf.to_container(cfg.model.get("refine"), resolve=True)
            if OmegaConf.is_config(cfg.model.get("refine"))
            else None,
            overrides,
        )
    system = hydra.utils.instantiate(cfg.system)
    record = build_record(cfg, system)
    metrics = json.loads((job / "metrics.json").read_text())
    windows = json.loads((job / "windows.json").read_text())["windows"]
    results = [WindowResult(**w) for w in windows]
    bpath = job / "baselines.json"
    baselines = json.loads(bpath.read_text())["baselines"] if bpath.exists() else []
    pidyn_values = metrics["pidynnet"]["params"]
    refined = run_refinement(cfg, system, record, pidyn_values, baselines, results)
    if refined is None:
        raise SystemExit(f"{job}: model.refine is none")
    names = list(pidyn_values)
    truths = {n: (record.truth or {}).get(n) for n in names}
    values = dict(refined.params)
    final = {**{s.name: float(s.init) for s in system.param_specs()}, **values}
    errors = relative_errors(values, truths)
    sim = simulate_response(system, final, record, state0=np.array(refined.initial_state))
    notes = [n for r in results for n in (r.notes or [])] + refined.notes
    for key in ("covered", "refine_compare"):
        metrics.pop(key, None)
    metrics.update(
        {
            "params": values,
            "error_pct": errors,
            "max_error_pct": max(errors.values()) if errors else None,
            "mean_error_pct": float(np.mean(list(errors.values()))) if errors else None,
            "sim_nrmse": channel_nrmse(sim, record),
            "notes": notes,
            "refine": "multiple_shooting",
        }
    )
    metrics.update(refined_metrics(refined, names, truths))
    write_json(job / "metrics.json", metrics)
    write_json(job / "refinement.json", refined.to_dict())
    units = {s.name: s.unit for s in system.param_specs()}
    write_yaml(
        job / "identified_params.yaml",
        identified_params(system, final, values, truths, units, refined, notes),
    )
    return metrics


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sweep", type=Path, help="a multirun folder (its jobs are sub-folders) or one run folder")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a refinement setting (conf/model/refine/multiple_shooting.yaml), repeatable",
    )
    a = ap.parse_args()
    jobs = (
        [a.sweep]
        if (a.sweep / "metrics.json").exists()
        else sorted(
            p for p in a.sweep.iterdir() if (p / "metrics.json").exists() and (p / "windows.json").exists()
        )
    )
    if not jobs:
        raise SystemExit(f"{a.sweep}: no finished job (metrics.json and windows.json) found")
    for job in jobs:
        m = refine_job(job, a.set)
        err = ", ".join(f"{k} {v:.3g}" for k, v in (m.get("error_pct") or {}).items())
        print(
            f"{job.name}: initial state {m['refinement'].get('initial_state_mode')}; errors % {err or '-'}",
            flush=True,
        )
    print(f"{len(jobs)} job(s) refined again")


if __name__ == "__main__":
    main()
