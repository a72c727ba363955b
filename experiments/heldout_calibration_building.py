"""How often the building's held-out test fails a correct model (``make heldout-calibration-building``).

Clean shear buildings: from seed 12000 + i, 3 to 6 storeys (masses 0.8-1.2 kg, stiffness tapering
from 150-250 N/m to half that at the top, 2 % damping-like dashpots), every floor measured or, one
building in three, every floor but one between the first and the top, under every shipped ground
motion (its first ``duration`` seconds at PGA 3 m/s^2), with measurement noise as a fraction of
each floor's RMS. The grid per ground motion: noise 0, 1, 2 and 5 % at the fitting share 0.65 of
40 s (the held-out part is the record's quieter end), 2 % at the shares 0.5 and 0.8 of 40 s, 2 % on
20 s, and 3 % on 60 s (a long quiet coda held out): 13 x 8 = 104 records, none drawn by the
benchmark (other seeds). On each, the nominal building as the diagnosis makes it
(``storey_nominal.nominal_fit`` on the fitting part), then the held-out test of every measured
floor (``storeys.building_heldout_test``) at the diagnosis's level.

Writes ``experiments/results/heldout_calibration_building.{md,csv}``; finished records are kept in
the CSV and skipped on a rerun.

    python experiments/heldout_calibration_building.py
    python experiments/heldout_calibration_building.py --records landers kocaeli --jobs 1
"""

from __future__ import annotations

import logging
import platform
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

from pidyn.bench.grid import calibration_args, finished, run_grid  # noqa: E402
from pidyn.excitation.ground_motion import SHIPPED  # noqa: E402

#: (noise, fitting share, duration in s)
GRID = [
    (0.0, 0.65, 40.0),
    (0.01, 0.65, 40.0),
    (0.02, 0.65, 40.0),
    (0.05, 0.65, 40.0),
    (0.02, 0.5, 40.0),
    (0.02, 0.8, 40.0),
    (0.02, 0.65, 20.0),
    (0.03, 0.65, 60.0),
]


def draw(rng: np.random.Generator) -> tuple[int, list[float], list[float], list[float], list[int]]:
    """Storeys, masses, stiffnesses, dashpots and measured floors of a seeded clean building."""
    n = int(rng.integers(3, 7))
    masses = [round(float(m), 3) for m in rng.uniform(0.8, 1.2, n)]
    k0 = float(rng.uniform(150.0, 250.0))
    stiff = [round(k0 * (1 - 0.5 * j / max(n - 1, 1)), 2) for j in range(n)]
    damp = [round(0.02 * 2 * np.sqrt(k * m), 4) for k, m in zip(stiff, masses)]
    sensors = list(range(1, n + 1))
    if rng.random() < 1 / 3:
        sensors.remove(int(rng.integers(2, n)))
    return n, masses, stiff, damp, sensors


def one(args: tuple[int, str, float, float, float]) -> dict:
    """The nominal fit and held-out test of one clean building."""
    from pidyn.config import compose
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.discrepancy.case import split_spans
    from pidyn.discrepancy.settings import DiagnosisSettings
    from pidyn.discrepancy.storey_choice import Study
    from pidyn.discrepancy.storey_nominal import heldout_nrmse, nominal_fit
    from pidyn.discrepancy.storeys import building_heldout_test
    from pidyn.excitation.ground_motion import prepare
    from pidyn.runs.methods import refine_plan
    from pidyn.systems.shear_building import ShearBuilding

    i, record, noise, share, duration = args
    rng = np.random.default_rng(12000 + i)
    n, masses, stiff, damp, sensors = draw(rng)
    gm = prepare(record, scale=1.0, duration=duration, dt=0.02)
    gm = prepare(record, scale=3.0 / float(np.max(np.abs(gm.acc))), duration=duration, dt=0.02)
    true = ShearBuilding(n, masses, damp, stiff)
    rec = synthetic_from_motion(true, gm, noise=noise, data_seed=12000 + i, channels=("a",), sensors=sensors)
    rec.meta = rec.meta.with_(noise=None, noise_levels=None)  # as from a file
    cfg = compose("diagnose", groups={"system": "shear_building"}, values={"system.n_storeys": n})
    settings = DiagnosisSettings.from_mapping({"fit_share": share})
    refine_settings = replace(refine_plan(cfg)[2], states="integrated")
    nominal = ShearBuilding(n, masses)
    fit, held = split_spans(rec, share)
    t0 = time.perf_counter()
    values, _ = nominal_fit(rec, nominal, fit, refine_settings)
    study = Study(rec, nominal, settings, refine_settings, fit, held)
    test = building_heldout_test(study, {"system": nominal, "values": values})
    m_fit, m_held = (rec.t <= fit[1]), (rec.t > fit[1])
    quiet = float(np.sqrt(np.nanmean(rec.a[m_held] ** 2)) / np.sqrt(np.nanmean(rec.a[m_fit] ** 2)))
    return {
        "i": i,
        "record": record,
        "noise": noise,
        "fit_share": share,
        "duration": duration,
        "n_storeys": n,
        "sensors": " ".join(map(str, sensors)),
        "failed": bool(test["failed"]),
        "p_min": test["p_min"],
        "level": test["level"],
        "failed_floors": " ".join(test["failed_floors"]),
        "heldout_over_fit_rms": quiet,
        "fit_nrmse": heldout_nrmse(rec, nominal, values, fit).mean,
        "heldout_nrmse": heldout_nrmse(rec, nominal, values, held).mean,
        "seconds": time.perf_counter() - t0,
    }


def write_table(df: pd.DataFrame, path: Path, seconds: float, ran: int) -> None:
    fails = int(df["failed"].sum())
    run = f"{seconds:.0f} s in this run" if ran else "no record run again: the rows are the CSV's"
    quiet = df[df["heldout_over_fit_rms"] < 1.0]
    lines = [
        "# The building held-out test: false alarms on clean records",
        "",
        (__doc__ or "").split("\n\n")[1].replace("\n", " "),
        "",
        f"Command: `python experiments/heldout_calibration_building.py` (`make heldout-calibration-building`); "
        f"{platform.machine()}, {time.strftime('%Y-%m-%d')}; {run}.",
        "",
        f"**False alarms: {fails} of {len(df)} clean records ({100 * fails / max(len(df), 1):.1f} %)**; "
        f"{int(quiet['failed'].sum())} of the {len(quiet)} whose held-out part is quieter than the fitting "
        f"part. Least p-value over all records {df['p_min'].min():.3g} (the level per floor "
        f"{df['level'].min():.3g}-{df['level'].max():.3g}).",
        "",
        "| noise | fitting share | duration (s) | records | false alarms | median held-out / fit RMS | "
        "least p | median held-out NRMSE |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (noise, share, dur), g in df.groupby(["noise", "fit_share", "duration"]):
        lines.append(
            f"| {noise:g} | {share:g} | {dur:g} | {len(g)} | {int(g['failed'].sum())} | "
            f"{g['heldout_over_fit_rms'].median():.2f} | {g['p_min'].min():.3g} | {g['heldout_nrmse'].median():.3g} |"
        )
    failed = df[df["failed"]]
    if len(failed):
        lines += ["", "Failed records:", ""]
        lines += [
            f"- {r.record}, {r.n_storeys} storeys, noise {r.noise:g}, share {r.fit_share:g}, {r.duration:g} s: "
            f"p {r.p_min:.3g} on {r.failed_floors}"
            for r in failed.itertuples()
        ]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    args = calibration_args(__doc__, SHIPPED, ROOT / "experiments" / "results")
    logging.basicConfig(level=logging.WARNING)
    csv = args.results / "heldout_calibration_building.csv"
    done, have = finished(csv, ["record", "noise", "fit_share", "duration"], args.fresh)
    todo = []
    for record in args.records:
        for g, (noise, share, duration) in enumerate(GRID):
            i = sorted(SHIPPED).index(record) * len(GRID) + g  # a record's seeds whatever else runs
            if (record, noise, share, duration) not in have:
                todo.append((i, record, noise, share, duration))

    def describe(r: dict) -> str:
        return (
            f"{r['record']} {r['n_storeys']} storeys noise {r['noise']:g} share {r['fit_share']:g} "
            f"{r['duration']:g} s: p {r['p_min']:.3g}{' FAILED' if r['failed'] else ''} ({r['seconds']:.0f} s)"
        )

    df, seconds = run_grid(csv, done, todo, one, describe, args.jobs)
    write_table(df, args.results / "heldout_calibration_building.md", seconds, len(todo))


if __name__ == "__main__":
    main()
