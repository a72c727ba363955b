"""How often the building's fit test fails a correct model (``make fit-test-calibration``).

Clean shear buildings (``pidyn.discrepancy.fit_test``): from seed 9000 + i, 3 to 5 storeys drawn
as the building benchmark draws them (masses 0.8-1.2 kg, stiffness tapering from 150-250 N/m to
half that at the top, 2 % damping-like dashpots, one building in three with a floor between the
first and the top unmeasured), under every shipped ground motion (its first 20 s at PGA 3 m/s^2),
with measurement noise of 0, 1, 2.5 and 5 % of each floor's RMS at the default fitting share
0.65, and at 3 % noise with the fitting part ending at 50 and 80 % of the record:
13 x 6 = 78 records, none drawn by the benchmark (other seeds). On each, the nominal building as
the diagnosis makes it (``storey_nominal.nominal_fit``: the start from the data and the config's, each
refined on the fitting part), then the fit test of every measured floor.

Writes ``experiments/results/fit_test_calibration.{md,csv}``; finished records are kept in the
CSV and skipped on a rerun.

    python experiments/fit_test_calibration.py
    python experiments/fit_test_calibration.py --records el_centro kobe --jobs 1
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

from pidyn.bench.draws import draw_building, draw_sensors  # noqa: E402
from pidyn.bench.grid import calibration_args, finished, run_grid  # noqa: E402
from pidyn.discrepancy.settings import FitTestSettings  # noqa: E402
from pidyn.excitation.ground_motion import SHIPPED  # noqa: E402

GRID = [(0.0, 0.65), (0.01, 0.65), (0.025, 0.65), (0.05, 0.65), (0.03, 0.5), (0.03, 0.8)]


def one(args: tuple[int, str, float, float]) -> dict:
    """The nominal fit and fit test of one clean building."""
    from pidyn.config import compose
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.discrepancy.case import split_spans
    from pidyn.discrepancy.settings import DiagnosisSettings
    from pidyn.discrepancy.storey_choice import building_fit_test
    from pidyn.discrepancy.storey_nominal import nominal_fit
    from pidyn.excitation.ground_motion import prepare
    from pidyn.runs.methods import refine_plan
    from pidyn.systems.shear_building import ShearBuilding

    i, record, noise, share = args
    rng = np.random.default_rng(9000 + i)
    n, masses, stiff, damp = draw_building(rng)  # as the building benchmark draws them
    sensors = draw_sensors(rng, n)
    gm = prepare(record, scale=1.0, duration=20.0, dt=0.02)
    gm = prepare(record, scale=3.0 / float(np.max(np.abs(gm.acc))), duration=20.0, dt=0.02)
    true = ShearBuilding(n, masses, damp, stiff)
    rec = synthetic_from_motion(true, gm, noise=noise, data_seed=9000 + i, channels=("a",), sensors=sensors)
    rec.meta = rec.meta.with_(noise=None, noise_levels=None)  # as from a file
    cfg = compose("diagnose", groups={"system": "shear_building"}, values={"system.n_storeys": n})
    settings = DiagnosisSettings.from_mapping({"fit_share": share})
    refine_settings = replace(refine_plan(cfg)[2], states="integrated")
    nominal = ShearBuilding(n, masses)
    fit, _ = split_spans(rec, share)
    t0 = time.perf_counter()
    values, _ = nominal_fit(rec, nominal, fit, refine_settings)
    test = building_fit_test(rec, nominal, values, fit, settings)
    worst = test["channels"][test["worst"]]
    return {
        "i": i,
        "record": record,
        "noise": noise,
        "fit_share": share,
        "n_storeys": n,
        "sensors": " ".join(map(str, sensors)),
        "failed": bool(test["failed"]),
        "worst_floor": test["worst"],
        "worst_nrmse": worst["nrmse"],
        "worst_noise": worst["noise"],
        "worst_ratio": worst["ratio"],
        "worst_excess": worst["excess"],
        "noise_method": worst.get("noise_method"),
        "seconds": time.perf_counter() - t0,
    }


def write_table(df: pd.DataFrame, path: Path, seconds: float, ran: int) -> None:
    """The table; the headline also re-judges every record at the thresholds now set (on its worst
    floor by excess), so a changed threshold is read against the same clean records."""
    th = FitTestSettings()
    fails = int(df["failed"].sum())
    now = int(((df["worst_ratio"] >= th.rms_ratio) & (df["worst_excess"] >= th.min_excess)).sum())
    run = f"{seconds:.0f} s in this run" if ran else "no record run again: the rows are the CSV's"
    noisy = df[df["noise"] > 0]
    lines = [
        "# The building fit test: false alarms on clean records",
        "",
        (__doc__ or "").split("\n\n")[1].replace("\n", " "),
        "",
        f"Command: `python experiments/fit_test_calibration.py` (`make fit-test-calibration`); "
        f"{platform.machine()}, {time.strftime('%Y-%m-%d')}; {run}.",
        "",
        f"**False alarms: {fails} of {len(df)} clean records ({100 * fails / max(len(df), 1):.1f} %)** "
        f"(each record's verdict as its run made it). At the thresholds now set (fails at "
        f"{th.rms_ratio:g} times the noise and {th.min_excess:g} of the signal above it), judged on each "
        f"record's worst floor: {now} of {len(df)}. Largest residual over noise on any record: "
        f"{df['worst_ratio'].max():.2f} times, {noisy['worst_ratio'].max():.2f} on the records with noise "
        f"(a noise-free record's floor is the solver's error, and fails only by the excess); largest "
        f"excess over the noise: {df['worst_excess'].max():.4f} of the floor's signal.",
        "",
        "| noise | fitting share | records | false alarms | median worst ratio | max worst ratio | max excess |",
        "|---|---|---|---|---|---|---|",
    ]
    for (noise, share), g in df.groupby(["noise", "fit_share"]):
        lines.append(
            f"| {noise:g} | {share:g} | {len(g)} | {int(g['failed'].sum())} | {g['worst_ratio'].median():.2f} | "
            f"{g['worst_ratio'].max():.2f} | {g['worst_excess'].max():.4f} |"
        )
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    args = calibration_args(__doc__, SHIPPED, ROOT / "experiments" / "results")
    logging.basicConfig(level=logging.WARNING)
    csv = args.results / "fit_test_calibration.csv"
    done, have = finished(csv, ["record", "noise", "fit_share"], args.fresh)
    todo = []
    for record in args.records:
        for g, (noise, share) in enumerate(GRID):
            i = sorted(SHIPPED).index(record) * len(GRID) + g  # a record's seeds whatever else runs
            if (record, noise, share) not in have:
                todo.append((i, record, noise, share))

    def describe(r: dict) -> str:
        return (
            f"{r['record']} noise {r['noise']:g} share {r['fit_share']:g}: worst {r['worst_floor']} ratio "
            f"{r['worst_ratio']:.2f}{' FAILED' if r['failed'] else ''}"
        )

    df, seconds = run_grid(csv, done, todo, one, describe, args.jobs)
    write_table(df, args.results / "fit_test_calibration.md", seconds, len(todo))


if __name__ == "__main__":
    main()
