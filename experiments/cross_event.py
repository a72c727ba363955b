"""Leave events out: one model of a bridge, identified on some of its earthquakes, predicts the others.

For each direction, the station's events that carry its full channel set are split into folds
(seeded). Each fold's events are predicted by models identified on all the other events at once
(``train.py data=csmip 'data.paths=[...]'``), simulated from rest under each predicted event's own
support motions (``predict.py``): the cross-event linear model and, beside it, a nonlinear one.
Per event, in one table, beside them: the per-event model's score on its own held-out part (from
the per-event study's CSV) and knowing nothing (the deck moving with its support).

    python experiments/cross_event.py                 # Painter Street, both directions, 5 folds
    python experiments/cross_event.py --station CE58658 --records data/hayward_ce58658/records

Run folders go to outputs/cross_event/<station>/ (a run that finished is not run again); the
tables to experiments/results/real/cross_event_<station>.md and .csv, the figure of the largest
event predicted by a model that never saw it to experiments/results/real/figures/.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from pidyn.bench.folds import event_name, folds, identify_several, run_logged_to, station_events
from pidyn.bench.tables import median
from pidyn.cores import share_cores

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"
#: the models compared; the first is the reference linear model of the layout
SYSTEMS = {
    "linear": ["system=linear"],
    "duffing": ["system=duffing", "system.signed_k3=true"],
    "rigid_deck": ["system=rigid_deck"],  # every deck channel, each support its own spring (transverse)
    "amplitude": ["system=amplitude"],  # stiffness and damping that follow the response's recent amplitude
    "default": [],  # what data=csmip gives several events without system= (the amplitude model, its scale from them)
}
#: models of the deck's motion across it only (along it, a rigid deck is the linear model)
ACROSS_ONLY = {"rigid_deck"}
#: the linear model of each model's own layout, scored beside it (a linear model is its own)
LINEAR_OF = {"duffing": "linear", "amplitude": "linear", "default": "linear"}
#: a strong event (the issue's bar: the nonlinear model must beat the linear one there)
STRONG_G = 0.2


def identify(
    out: Path, station: str, direction: str, system: str, train: list[dict], extra: list[str] = ()
) -> Path:
    """One model from the training events at once (a finished run is kept); ``extra``: further
    overrides of every identification (``--set``)."""
    return identify_several(out, station, direction, system, [*SYSTEMS[system], *extra], train, ROOT)


def predict(run: Path, linear: Path | None, row: dict, station: str, direction: str, out: Path) -> dict:
    folder = out / row["event"]
    if not (folder / "complete.json").is_file():
        cmd = [
            sys.executable,
            "predict.py",
            f"run={run}",
            "data=csmip",
            f"data.path={row['path']}",
            f"data.station={station}",
            f"data.direction={direction}",
            f"hydra.run.dir={folder}",
        ]
        if linear is not None and linear != run:
            cmd.append(f"linear_run={linear}")
        run_logged_to(cmd, out / "predict.log", ROOT)
    saved = folder / "prediction.json"
    return json.loads(saved.read_text()) if saved.is_file() else {}


def fold_job(args, out: Path, direction: str, k: int, train: list[dict], test: list[dict]) -> list[dict]:
    fold_dir = out / direction / f"fold{k}"
    systems = [s for s in args.systems if direction == "transverse" or s not in ACROSS_ONLY]
    runs = {s: identify(fold_dir, args.station, direction, s, train, args.set) for s in systems}
    rows = []
    for row in test:
        res = {}
        for s, run in runs.items():
            linear = runs.get(LINEAR_OF.get(s, ""))  # the linear model of the same layout, if another
            if (run / "complete.json").is_file():
                res[s] = predict(run, linear, row, args.station, direction, fold_dir / s / "predictions")
        rows.append({**row, "direction": direction, "fold": k, "n_train": len(train), "results": res})
    peer = srim_fold(train, test, args.station, direction)
    for row in rows:
        row["srim_nrmse_a"] = peer.get(row["event"])
    return rows


def srim_fold(train: list[dict], test: list[dict], station: str, direction: str, gap_s: float = 10.0) -> dict:
    """mdof's SRIM on the training events at once (laid end to end with ``gap_s`` of rest between
    them, so no event's end runs into the next), the stable order that fits them best, each test
    event simulated from rest under its own inputs: NRMSE of its output by event (empty without mdof).
    Orders 2, 4, 6 and block rows 30 and 100: pooled, SRIM's slowest pole sits at the unit circle
    at 100 rows on some folds."""
    try:
        import mdof
    except ImportError:
        return {}
    from pidyn.baselines.peers import io_arrays, simulate_realization
    from pidyn.data.strong_motion import csmip_record
    from pidyn.reporting import nrmse

    def arrays(row):
        return io_arrays(csmip_record(row["path"], station=station, direction=direction, max_outputs=1))

    parts = [arrays(r) for r in train]
    gap = np.zeros((parts[0][0].shape[0], int(gap_s / 0.02)))
    U = np.concatenate([np.concatenate([u, gap], axis=1) for u, _ in parts], axis=1)
    Y = np.concatenate([np.concatenate([y, gap[: y.shape[0]]], axis=1) for _, y in parts], axis=1)
    best = None
    for order, horizon in [(o, h) for o in (2, 4, 6) for h in (30, 100)]:
        try:
            A, B, C, D = mdof.system(U, Y, dt=0.02, method="srim", order=order, horizon=horizon)
        except Exception:  # an order SRIM cannot realise on these records
            continue
        out = simulate_realization(A, B, C, D, U)
        if np.max(np.abs(np.linalg.eigvals(A))) < 1.0 and np.all(np.isfinite(out)):
            err = float(np.mean([nrmse(out[j], Y[j]) for j in range(Y.shape[0])]))
            if best is None or err < best[0]:
                best = (err, (A, B, C, D))
    if best is None:
        return {r["event"]: None for r in test}
    scores = {}
    for r in test:
        u, y = arrays(r)
        out = simulate_realization(*best[1], u)
        scores[r["event"]] = float(np.mean([nrmse(out[j], y[j]) for j in range(y.shape[0])]))
    return scores


def per_event(csv_path: Path) -> dict[tuple[str, str], dict]:
    """The per-event study's held-out scores (each event's model on the rest of its own record)."""
    if not csv_path.is_file():
        return {}
    with csv_path.open() as fh:  # the station tables name an event by its archive (``..._ce58658p``)
        rows = list(csv.DictReader(fh))
    for r in rows:
        r.setdefault("heldout_nrmse_a", r.get("heldout_nrmse"))
    return {(event_name(Path(r["event"])), r["direction"]): r for r in rows}


def _f(v, fmt=".3f") -> str:
    if isinstance(v, float) and np.isinf(v):  # the model's simulation blew up: the worst prediction
        return "diverged"
    return (
        "-"
        if v in (None, "", "nan") or (isinstance(v, float) and not np.isfinite(v))
        else format(float(v), fmt)
    )


def table(rows: list[dict], own: dict, systems: list[str]) -> list[dict]:
    out = []
    for r in rows:
        res = r["results"]
        line = {
            "event": r["event"],
            "direction": r["direction"],
            "fold": r["fold"],
            "pga_g": r["pga_g"],
            "per_event_heldout_nrmse_a": _num(
                (own.get((r["event"], r["direction"])) or {}).get("heldout_nrmse_a")
            ),
        }
        ref = list((res.get(systems[0]) or {}).get("nrmse") or {})  # the reference model's channels
        for s in systems:
            line[f"{s}_nrmse_a"] = (res.get(s) or {}).get("mean_nrmse_a")
            # "linear" where the run's own events chose the linear model beside it (pidyn.runs.model_choice)
            line[f"{s}_model"] = (res.get(s) or {}).get("model_choice")
            # False where the run's events could not tell its two models apart
            line[f"{s}_decisive"] = (res.get(s) or {}).get("model_choice_decisive")
            scores = (res.get(s) or {}).get("nrmse") or {}
            line[f"{s}_nrmse_ref"] = median([scores.get(c) for c in ref]) if ref else None
            # the linear model of the same layout, identified on the same events in its run
            if s in LINEAR_OF:
                line[f"{s}_linear_nrmse_a"] = (res.get(s) or {}).get("linear_mean_nrmse_a")
        line["srim_nrmse_a"] = r.get("srim_nrmse_a")
        first = next((v for v in res.values() if v), {})
        line["trivial_nrmse_a"] = first.get("trivial_mean_nrmse_a")
        line["trivial"] = first.get("trivial")
        # the event's PGA against the training events' range (None: within it)
        line["beyond_training"] = first.get("beyond_training")
        out.append(line)
    return out


def _num(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def own_linear_lines(rows: list[dict], systems: list[str], strong: list[dict]) -> list[str]:
    """Each nonlinear model against the linear model of its own run: the same layout, identified on
    the same events from the same data (a column from an earlier study may have read them otherwise)."""
    out = []
    for s in systems:
        key = f"{s}_linear_nrmse_a"
        if not any(r.get(key) is not None for r in rows):
            continue
        pairs = [r for r in strong if r.get(key) is not None]
        better = [r for r in pairs if _lt(r[f"{s}_nrmse_a"], r[key])]
        out.append(
            f"- the {s} model against the linear model of its own run (the same layout and events): median "
            f"{_f(median([r[key] for r in rows]))} for that linear model; strong events (PGA >= {STRONG_G} g) "
            f"predicted better by the {s} model: {len(better)} of {len(pairs)}"
            + (
                f" (not: {', '.join(r['event'] for r in pairs if r not in better)})"
                if len(better) < len(pairs)
                else ""
            )
        )
        out += _choice_line(rows, s)
    return out


def _choice_line(rows: list[dict], s: str) -> list[str]:
    """Which folds' runs chose the linear model beside their own, and on which the choice was a coin."""
    if not any(r.get(f"{s}_model") for r in rows):
        return []
    n = len({r["fold"] for r in rows})
    linear = sorted({r["fold"] for r in rows if r.get(f"{s}_model") == "linear"})
    undecided = sorted({r["fold"] for r in rows if r.get(f"{s}_decisive") is False})
    text = (
        f"- the {s} model's runs chose the linear model beside them on {len(linear)} of {n} folds"
        f"{f' ({linear})' if linear else ''}"
    )
    if any(r.get(f"{s}_decisive") is not None for r in rows):  # studies before it was recorded: not said
        text += (
            f"; their own events could not tell the two apart on {len(undecided)} of {n}"
            f"{f' ({undecided})' if undecided else ''}"
        )
    return [text]


def summary_lines(lines: list[dict], all_systems: list[str], others: dict[str, list[dict]]) -> list[str]:
    """Per direction, the medians and counts of the models identified in it."""
    out = []
    for direction in sorted({r["direction"] for r in lines}):
        rows = [r for r in lines if r["direction"] == direction]
        out += [f"### {direction}", ""]
        systems = [s for s in all_systems if any(r[f"{s}_nrmse_a"] is not None for r in rows)]
        meds = {s: median([r[f"{s}_nrmse_a"] for r in rows]) for s in systems}
        own = median([r["per_event_heldout_nrmse_a"] for r in rows])
        triv = median([r["trivial_nrmse_a"] for r in rows])
        peer = median([r.get("srim_nrmse_a") for r in rows])
        out.append(
            f"- median NRMSE over {len(rows)} events, each predicted by models that never saw it: "
            + ", ".join(f"{s} {_f(m)}" for s, m in meds.items())
            + f"; SRIM on the same events {_f(peer)}; knowing nothing {_f(triv)}; each event's own model on "
            f"its own held-out part {_f(own)}"
        )
        for s in _other_channels(rows, systems):
            out.append(
                f"- {s} on the reference model's channels ({systems[0]}'s): median "
                f"{_f(median([r[f'{s}_nrmse_ref'] for r in rows]))}"
            )
        strong = [r for r in rows if r["pga_g"] >= STRONG_G]
        for nl in systems[1:] if strong else []:
            better = [r for r in strong if _lt(r[f"{nl}_nrmse_a"], r[f"{systems[0]}_nrmse_a"])]
            out.append(
                f"- strong events (PGA >= {STRONG_G} g): the {nl} model predicts {len(better)} of {len(strong)} "
                f"better than the {systems[0]} model"
            )
        out += own_linear_lines(rows, systems, strong)
        for s in systems:
            worse = [r["event"] for r in rows if not _lt(r[f"{s}_nrmse_a"], r["trivial_nrmse_a"])]
            out.append(
                f"- {s}: {len(worse)} of {len(rows)} no better than knowing nothing"
                + (f" ({', '.join(worse)})" if worse else "")
            )
        if others.get(direction):
            out.append(
                "- not predicted (another channel set than the model's): "
                + ", ".join(
                    f"{o['event']} ({o.get('error') or [o.get('inputs'), o.get('outputs')]})"
                    for o in others[direction]
                )
            )
        out.append("")
    return out


def _other_channels(rows: list[dict], systems: list[str]) -> list[str]:
    """The models scored on other channels than the reference (first) model's: a deck's every channel."""
    return [
        s
        for s in systems[1:]
        if any(r.get(f"{s}_nrmse_ref") not in (None, r.get(f"{s}_nrmse_a")) for r in rows)
    ]


def _lt(a, b) -> bool:
    return a is not None and b is not None and float(a) < float(b)


def markdown(lines: list[dict], systems: list[str], others: dict, args, seconds: float, n_runs: int) -> str:
    head = [
        f"# Leave events out: station {args.station}",
        "",
        f"`python experiments/cross_event.py --station {args.station} --folds {args.folds} --seed {args.seed} "
        f"--systems {','.join(args.systems)}{_extra(args)}` "
        f"({n_runs} identifications, {seconds / 60:.0f} min of run time on 2 cores, two at a time). Each event is predicted by models identified on the events "
        "of the other folds at once, simulated from rest under its own support motions; NRMSE of the deck "
        "acceleration over the event's shaking span (a model of every deck channel: their mean). `SRIM, same "
        "events`: mdof's SRIM identified on the same training events at once (laid end to end with 10 s of "
        "rest between them), its stable order that fits them best. `per-event` is each event's own model on "
        "the held-out part of its own record (the per-event study), `knowing nothing` the deck moving with "
        "its support.",
        "",
    ]
    head += summary_lines(lines, systems, others)
    other = _other_channels(lines, systems)
    cols = [
        "event",
        "direction",
        "fold",
        "PGA (g)",
        *systems,
        *[f"{s} on {systems[0]}'s channels" for s in other],
    ]
    mine = [s for s in systems if any(r.get(f"{s}_linear_nrmse_a") is not None for r in lines)]
    cols += [f"linear of {s}'s run" for s in mine]
    cols += ["SRIM, same events", "knowing nothing", "per-event (own held-out)"]
    head += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in sorted(lines, key=lambda r: (r["direction"], -r["pga_g"])):
        cells = [_f(r[f"{s}_nrmse_a"]) for s in systems] + [_f(r[f"{s}_nrmse_ref"]) for s in other]
        cells += [_f(r.get(f"{s}_linear_nrmse_a")) for s in mine]
        cells += [_f(r.get("srim_nrmse_a")), _f(r["trivial_nrmse_a"]), _f(r["per_event_heldout_nrmse_a"])]
        head.append(
            f"| {r['event']} | {r['direction']} | {r['fold']} | {r['pga_g']:.3f} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(head) + "\n"


def period_figure(out: Path, station: str, directions: list[str], per_event_csv: Path, path: Path) -> None:
    """Each event's own period (with its interval; a model that does not describe its event left
    out) against the event's PGA, and each fold's cross-event linear model's period as a band: one
    model of the bridge against 25 per-event fits."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    own = per_event(per_event_csv)
    fig, axes = plt.subplots(1, len(directions), figsize=(5.2 * len(directions), 3.8), squeeze=False)
    for ax, direction in zip(axes[0], directions):
        rows = [r for (e, d), r in own.items() if d == direction and _num(r.get("period_s"))]
        for r in rows:
            lo, hi = json.loads(r["period_ci95"]) if r.get("period_ci95") else (None, None)
            pga, per = float(r["pga_g"]), float(r["period_s"])
            if lo is not None and hi is not None:
                ax.plot([pga, pga], [lo, hi], color="0.6", lw=1)
            ax.plot(pga, per, "o", color="0.25", ms=3.5)
        for k, modal in enumerate(sorted((out / direction).glob("fold*/linear/run/modal.json"))):
            mode = json.loads(modal.read_text())["modes"][0]
            lo, hi = mode.get("period_ci95") or (mode["period_s"], mode["period_s"])
            ax.axhspan(lo, hi, alpha=0.15, color=f"C{k}")
            ax.axhline(mode["period_s"], lw=1, color=f"C{k}", label=f"cross-event model, fold {k}")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("event PGA at the supports (g)")
        ax.set_ylabel("first period (s)")
        ax.set_title(f"{station} {direction}: per-event fits (points) and one model (bands)", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--station", default="CE89324")
    ap.add_argument("--records", type=Path, default=ROOT / "data" / "painter_street" / "records")
    ap.add_argument("--per-event", type=Path, default=RESULTS / "painter_street.csv")
    ap.add_argument("--directions", default="transverse,longitudinal")
    ap.add_argument("--systems", default="linear,duffing")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "outputs" / "cross_event")
    ap.add_argument("--figure-event", default="petrolia_25apr1992")
    ap.add_argument(
        "--name", default="", help="a suffix of the results' names (a second study beside the first)"
    )
    ap.add_argument(
        "--beside",
        type=Path,
        default=None,
        help="an earlier study's CSV: its models' columns shown beside this run's (nothing of it run again)",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        help="an override of every identification, e.g. --set data.record_weighting=0.5 (with its own --out)",
    )
    args = ap.parse_args()
    args.systems = [s for s in args.systems.split(",") if s]
    unknown = set(args.systems) - set(SYSTEMS)
    if unknown:
        raise SystemExit(f"--systems: unknown {sorted(unknown)}; known {sorted(SYSTEMS)}")
    return args


def write_results(args, out: Path, rows: list[dict], others: dict) -> Path:
    """The table (CSV and markdown), the chosen event's prediction figure and the period figure."""
    lines = table(rows, per_event(args.per_event), args.systems)
    systems = beside(lines, args.beside, args.systems) + args.systems
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = f"cross_event_{args.station.lower()}" + (f"_{args.name}" if args.name else "")
    with (RESULTS / f"{stem}.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lines[0]))
        w.writeheader()
        w.writerows(lines)
    walls = [
        json.loads(m.read_text()).get("wall_seconds", 0.0) for m in out.glob("*/fold*/*/run/metrics.json")
    ]
    (RESULTS / f"{stem}.md").write_text(markdown(lines, systems, others, args, float(sum(walls)), len(walls)))
    for r in rows:  # the chosen event predicted by the last model named, which never saw it
        if r["event"] == args.figure_event:
            fold = out / r["direction"] / f"fold{r['fold']}" / args.systems[-1]
            src = fold / "predictions" / r["event"] / "figures" / "prediction.png"
            if src.is_file():
                dst = RESULTS / "figures" / f"{stem}_{r['event']}_{r['direction']}.png"
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src, dst)
    if "linear" in args.systems:
        figure = RESULTS / "figures" / f"{stem}_period.png"
        period_figure(out, args.station, args.directions.split(","), args.per_event, figure)
    return RESULTS / f"{stem}.md"


def _extra(args) -> str:
    """The command line's options that name a second study beside an earlier one."""
    out = f" --name {args.name}" if args.name else ""
    out += "".join(f" --set {o}" for o in args.set)
    if args.beside is not None:
        path = args.beside.resolve()
        out += f" --beside {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name}"
    return out


def beside(lines: list[dict], path: Path | None, systems: list[str]) -> list[str]:
    """The models of an earlier study's CSV (``path``) that this run did not identify, their columns
    added to ``lines`` by event and direction; returns their names, the linear model first."""
    if path is None:
        return []
    with path.open() as fh:
        old = {(r["event"], r["direction"]): r for r in csv.DictReader(fh)}
    names = [k[: -len("_nrmse_a")] for k in next(iter(old.values())) if k.endswith("_nrmse_a")]
    names = [n for n in names if n in SYSTEMS and n not in systems]
    for line in lines:
        row = old.get((line["event"], line["direction"])) or {}
        for n in names:
            line[f"{n}_nrmse_a"] = _num(row.get(f"{n}_nrmse_a"))
            line[f"{n}_nrmse_ref"] = _num(row.get(f"{n}_nrmse_ref"))
        if (
            line.get("srim_nrmse_a") is None
        ):  # the same seeded folds: SRIM's models are the same (mdof is optional)
            line["srim_nrmse_a"] = _num(row.get("srim_nrmse_a"))
    return sorted(names, key=lambda n: n != "linear")


def main() -> None:
    args = _args()
    out = args.out / args.station
    jobs, others = [], {}
    for direction in args.directions.split(","):
        keep, other = station_events(args.records, args.station, direction)
        others[direction] = other
        parts = folds(keep, args.folds, args.seed)
        print(f"{direction}: {len(keep)} events in {args.folds} folds; {len(other)} with another channel set")
        for k, test in enumerate(parts):
            train = [r for r in keep if r not in test]
            jobs.append((direction, k, train, test))
    share_cores(args.jobs)
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        done = list(pool.map(lambda j: fold_job(args, out, *j), jobs))
    print(write_results(args, out, [r for part in done for r in part], others).read_text())


if __name__ == "__main__":
    main()
