"""Does one model of a structure fit each of its own records as well as its linear model does?

A leave-events-out fold's model (``experiments/cross_event.py``, the same seeded folds) is scored
on every event of the station, the events it was identified on as well as those it never saw,
beside the linear model of the same layout fitted on the same events (``metrics.json``'s
``linear_model``). An event that the nonlinear model predicts worse than the linear one *although
it was fitted on it* is not a failure to generalise: the law shared by all the records is at odds
with that event, and no choice of the law's parameters fixes it without losing others.

For a model with an amplitude-dependent term, each event's envelope (its 95th percentile over the
event) and the model's period there are shown: the amplitude at which the shared law places the
event, and how soft it makes the structure there.

    python experiments/shared_law_check.py --fold 3 --fold 4
    python experiments/shared_law_check.py --fold 3 --fold 4 --drop petroliaaftershock2_26apr1992 --name no_as2
    python experiments/shared_law_check.py --fold 3 --fold 4 --set system.several_records.law=curved --name curved

Run folders go to outputs/shared_law/<station>/<name>/ (a finished run is reused); the table to
experiments/results/real/shared_law_<station>[_<name>].md.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from pidyn.bench.folds import folds, identify_several, station_events
from pidyn.runs.prediction import Identified, score

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"


def _args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--station", default="CE89324")
    p.add_argument("--records", type=Path, default=ROOT / "data" / "painter_street" / "records")
    p.add_argument("--direction", default="transverse")
    p.add_argument("--folds", type=int, default=5)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fold", type=int, action="append", required=True, help="a fold whose model is scored")
    p.add_argument(
        "--drop", action="append", default=[], help="an event left out of every fold's training too"
    )
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="an override of every identification"
    )
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--name", default="")
    return p.parse_args()


def score_event(run: Identified, path: str) -> dict:
    """The run's model and its linear model simulated from rest over one event's shaking span."""
    data = OmegaConf.create(OmegaConf.to_container(run.cfg.data, resolve=False))
    data.paths, data.path, data.hold_out = None, path, False
    out = {}
    for label, model in (("model", run), ("linear", run.linear_beside())):
        if model is None:
            continue
        system, record, values = model.for_record(data)
        scored = score(system, values, record)  # what predict.py scores: every deck channel's NRMSE
        out[label] = scored["mean_nrmse_a"]
        term = next((t for t in system.terms if t.name == "amplitude_softening"), None)
        if label == "model" and term is not None:
            e95 = float(np.quantile(np.asarray(scored["sim"]["z"])[:, 0], 0.95))
            stiff, _ = term.factors({k: torch.tensor(v) for k, v in values.items()}, torch.tensor(e95))
            out["e95"] = e95
            out["period_at_e95"] = float(2 * np.pi / np.sqrt(values[term.stiffness] * float(stiff)))
    return out


def main() -> None:
    args = _args()
    rows, _ = station_events(args.records, args.station, args.direction)
    parts = folds(rows, args.folds, args.seed)
    name = args.name or "all"
    out = ROOT / "outputs" / "shared_law" / args.station.lower() / name
    trains = {k: [r for r in rows if r not in parts[k] and r["event"] not in args.drop] for k in args.fold}

    def identify(k: int) -> Path:
        return identify_several(
            out / f"fold{k}", args.station, args.direction, "default", args.set, trains[k], ROOT
        )

    with ThreadPoolExecutor(args.jobs) as pool:
        runs = dict(zip(args.fold, pool.map(identify, args.fold)))
    lines = []
    for row in sorted(rows, key=lambda r: -r["pga_g"]):
        cells = [row["event"], f"{row['pga_g']:.3f}"]
        for k in args.fold:
            run = Identified.load(runs[k])
            seen = "test" if row in parts[k] else ("dropped" if row["event"] in args.drop else "fitted")
            s = score_event(run, row["path"])
            mark = "**" if s.get("model", 0) > s.get("linear", np.inf) else ""
            cells += [
                seen,
                f"{mark}{s['model']:.3f}{mark}",
                f"{s['linear']:.3f}",
                f"{s['e95']:.2f} / {s['period_at_e95']:.3f}" if "e95" in s else "-",
            ]
        lines.append("| " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    head = ["event", "PGA (g)"]
    for k in args.fold:
        head += [f"fold {k}", "model", "linear beside", "e95 / period there (s)"]
    text = [
        f"# One model's fit to each of its records: station {args.station}, {args.direction}",
        "",
        f"`python experiments/shared_law_check.py {' '.join(f'--fold {k}' for k in args.fold)}"
        + "".join(f" --drop {d}" for d in args.drop)
        + "".join(f" --set {o}" for o in args.set)
        + (f" --name {args.name}" if args.name else "")
        + f"` (seed {args.seed}, {args.folds} folds, the default model of several records). NRMSE of the"
        " deck acceleration over each event's shaking span, simulated from rest; **bold**: the"
        " nonlinear model worse than the linear model of its own run.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
        *lines,
        "",
    ]
    suffix = f"_{args.name}" if args.name else ""
    path = RESULTS / f"shared_law_{args.station.lower()}{suffix}.md"
    path.write_text("\n".join(text))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
