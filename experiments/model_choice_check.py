"""Does the model choice of a run from several records pick the model that predicts unseen events?

Over a leave-events-out study's run folders (``experiments/cross_event.py --systems default``):
each fold's default run chose between its amplitude model and the linear model beside it by its
own training events, each left out and predicted by both refitted without it
(``pidyn.runs.model_choice``, ``metrics.json``'s ``model_choice``). The fold's test events, which
the choice never saw, were predicted by both (``prediction.json``). Per event: the amplitude
model, the linear model, the model the run chose, and knowing nothing. A run that finished before
the choice was part of an identification gets it computed here, by the same function, from its
own folder.

    python experiments/model_choice_check.py --out outputs/cross_event --station CE58658
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

from pidyn.bench.tables import median

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"
STRONG_G = 0.2


def run_choice(run_dir: Path, overrides: dict | None = None) -> tuple[dict, str]:
    """The run's ``model_choice`` and where it came from (the identification, or computed here:
    always where ``overrides`` change its settings)."""
    metrics = json.loads((run_dir / "metrics.json").read_text())
    if metrics.get("model_choice") and not overrides:
        return metrics["model_choice"], "identification"
    from pidyn.runs.model_choice import ChoiceSettings, choose_model  # lazy: torch loads with it
    from pidyn.runs.prediction import Identified

    run = Identified.load(run_dir)
    system, record, values = run.for_record()
    settings = ChoiceSettings.of({**(run.cfg.get("model_choice") or {}), **(overrides or {})})
    hold_out = bool(run.cfg.data.get("hold_out"))
    return choose_model(
        run.cfg, system, record, values, metrics.get("linear_model"), settings, hold_out
    ), "here"


def rows_of(out: Path, station: str, overrides: dict | None = None) -> list[dict]:
    rows = []
    for run_dir in sorted((out / station).glob("*/fold*/default/run")):
        if not (run_dir / "complete.json").is_file():
            continue
        direction, fold = run_dir.parts[-4], run_dir.parts[-3]
        t0 = time.perf_counter()
        choice, source = run_choice(run_dir, overrides)
        print(
            f"{direction} {fold}: {choice['chosen']} ({source}, {time.perf_counter() - t0:.0f} s)", flush=True
        )
        for saved in sorted((run_dir.parent / "predictions").glob("*/prediction.json")):
            p = json.loads(saved.read_text())
            amplitude = p.get("nonlinear_mean_nrmse_a", p["mean_nrmse_a"])
            linear = p.get("linear_mean_nrmse_a")
            rows.append(
                {
                    "direction": direction,
                    "fold": fold,
                    "event": p["record"],
                    "pga_g": None if p.get("pga") is None else p["pga"] / 9.80665,
                    "choice": choice["chosen"],
                    "choice_mean_amplitude": choice["mean_nrmse_a"]["nonlinear"],
                    "choice_mean_linear": choice["mean_nrmse_a"]["linear"],
                    "amplitude": amplitude,
                    "linear": linear,
                    "chosen": linear if choice["chosen"] == "linear" else amplitude,
                    "knowing_nothing": p.get("trivial_mean_nrmse_a"),
                    "choice_source": source,
                    "choice_seconds": choice.get("seconds"),
                }
            )
    return rows


def summary(rows: list[dict], direction: str) -> list[str]:
    mine = [r for r in rows if r["direction"] == direction]
    if not mine:
        return []
    folds = {r["fold"]: r["choice"] for r in mine}
    strong = [r for r in mine if (r["pga_g"] or 0.0) >= STRONG_G]
    better = lambda key: sum(r[key] < r["linear"] for r in strong)  # noqa: E731
    right = sum((r["chosen"] <= min(r["amplitude"], r["linear"])) for r in mine)
    return [
        f"- **{direction}**, {len(mine)} events in {len(folds)} folds; the linear model chosen in "
        f"{sum(c == 'linear' for c in folds.values())} of them. Median NRMSE over the unseen events: "
        f"amplitude {median([r['amplitude'] for r in mine]):.3f}, linear {median([r['linear'] for r in mine]):.3f}, "
        f"chosen {median([r['chosen'] for r in mine]):.3f}; the chosen model is the better of the two on "
        f"{right} of {len(mine)} events. Strong events (PGA at least {STRONG_G} g): "
        f"{len(strong)}, the amplitude model better than the linear one on {better('amplitude')}, "
        f"the chosen model on {better('chosen')}."
    ]


def write(rows: list[dict], station: str, out: Path, name: str = "", overrides: dict | None = None) -> Path:
    stem = RESULTS / f"model_choice_{station.lower()}{'_' + name if name else ''}"
    sets = "".join(f" --set {k}={v}" for k, v in (overrides or {}).items())
    with stem.with_suffix(".csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    fmt = lambda v: "" if v is None else f"{v:.3f}"  # noqa: E731
    lines = [
        f"# Which model a run from several events stands behind: {station}",
        "",
        f"`python experiments/model_choice_check.py --out {out.relative_to(ROOT) if out.is_relative_to(ROOT) else out.name} "
        f"--station {station}{sets}{' --name ' + name if name else ''}` over the leave-events-out study's default runs. Each fold's run chose between its "
        "amplitude model and the linear model of the same layout by its own training events, each left out and "
        "predicted by both refitted without it (`pidyn.runs.model_choice`); the fold's test events, which the "
        "choice never saw, are predicted by both. NRMSE: mean over the deck channels, from rest over the event.",
        "",
        *[line for d in ("transverse", "longitudinal") for line in summary(rows, d)],
        "",
        "| direction | fold | event | PGA (g) | chosen | amplitude | linear | chosen's NRMSE | knowing nothing |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['direction']} | {r['fold']} | {r['event']} | {fmt(r['pga_g'])} | {r['choice']} | "
            f"{fmt(r['amplitude'])} | {fmt(r['linear'])} | {fmt(r['chosen'])} | {fmt(r['knowing_nothing'])} |"
        )
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return stem.with_suffix(".md")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=ROOT / "outputs" / "cross_event")
    ap.add_argument("--station", default="CE89324")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a model_choice setting for every run (the choice is then computed here), e.g. start=run",
    )
    ap.add_argument("--name", default="", help="suffix of the result files")
    args = ap.parse_args()
    overrides = {}
    for item in args.set:
        key, _, value = item.partition("=")
        overrides[key] = int(value) if value.isdigit() else value
    rows = rows_of(args.out.resolve(), args.station, overrides)
    if not rows:
        raise SystemExit(f"{args.out}/{args.station}: no finished default run with predictions")
    print(f"wrote {write(rows, args.station, args.out.resolve(), args.name, overrides)}")


if __name__ == "__main__":
    main()
