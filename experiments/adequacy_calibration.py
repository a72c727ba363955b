"""How often the adequacy test rejects a correct model (``make adequacy-calibration``), and how
often it catches a wrong one.

Clean records: the linear, Duffing and Bouc-Wen systems of the package's configs at their true
parameters, under every shipped ground motion (30 s from 2 s before its 5 % Arias time; dt 0.01), measured as
displacement and velocity with noise of 1, 2.5 and 5 % of each channel's RMS (seeded by the row),
and one in three as an accelerometer alone: 13 x 3 x 3 = 117 records. On each, the model is fitted
by output error (``pidyn.refine.output_error``, the refinement's estimator) on the first 65 % from
its true values, and the adequacy test (``pidyn.adequacy.check_adequacy``) judges its simulation
over the record with the last 35 % held out, as the identification of a split record does. A
false alarm is a clean record the test rejects.

The same fits of a wrong model are the test's power: a linear model fitted to the Duffing and
Bouc-Wen records (and the record of a response unrelated to its input, its channels shuffled in
time) must be rejected.

Writes ``experiments/results/adequacy_calibration.{md,csv}``; finished rows are kept and skipped on
a rerun.

    python experiments/adequacy_calibration.py
    python experiments/adequacy_calibration.py --records el_centro --jobs 1
"""

from __future__ import annotations

import logging
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

from pidyn.bench.grid import calibration_args, finished, run_grid  # noqa: E402
from pidyn.excitation.ground_motion import SHIPPED  # noqa: E402

SYSTEMS = ("linear", "duffing", "bouc_wen")
NOISES = (0.01, 0.025, 0.05)
FIT_SHARE, DURATION = 0.65, 30.0


def shaking_start(record: str, lead: float = 2.0) -> float:
    """Where a record's shaking starts: its 5 % Arias time, less ``lead`` seconds (a fitting part
    of silence determines nothing, whatever the test)."""
    from pidyn.excitation.ground_motion import load_record

    gm = load_record(record)
    arias = np.cumsum(np.square(gm.acc))
    t5 = float(gm.t[np.searchsorted(arias, 0.05 * arias[-1])])
    return max(t5 - lead, 0.0)


def judge(model, values: dict[str, float], target, cut: float) -> tuple[dict, float]:
    """``model`` fitted by output error on ``target`` up to ``cut`` from ``values``, and the
    adequacy test of its simulation with the rest held out; the seconds it took."""
    from pidyn.adequacy import check_adequacy
    from pidyn.refine.output_error import fit_output_error
    from pidyn.simulate import rk4_stability, simulate_response

    t0 = time.perf_counter()
    est = fit_output_error(target.segment(None, cut), model, values, max_nfev=40)
    final = {**values, **est.params}
    sim = simulate_response(model, final, target)
    stability = rk4_stability(model, final, target.dt)
    res = check_adequacy(sim, target, (0.0, cut), (cut, float(target.t[-1])), stability=stability)
    return res, time.perf_counter() - t0


def one(args: tuple[int, str, str, float]) -> list[dict]:
    """The clean record's fit and test, and the wrong model's (linear on a nonlinear record, or
    the linear model on a response unrelated to its input: the channels shuffled in time)."""
    from dataclasses import replace

    from pidyn.config import make_system
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.excitation.ground_motion import prepare

    i, record, system_name, noise = args
    channels = ("a",) if i % 3 == 2 else ("x", "v")
    system = make_system(system_name)
    gm = prepare(record, duration=DURATION, dt=0.01, start=shaking_start(record))
    rec = synthetic_from_motion(system, gm, noise=noise, data_seed=7000 + i, channels=channels)
    cut = float(rec.t[-1]) * FIT_SHARE
    cases = [("clean", system, rec.truth, rec)]
    if system_name != "linear":  # started from the true c and initial stiffness
        lin = make_system("linear")
        start = {
            **lin.true_values(),
            "c": rec.truth.get("c", 0.5),
            "k": rec.truth.get("k", rec.truth.get("k1")),
        }
        cases.append(("linear on " + system_name, lin, start, rec))
    else:
        perm = np.random.default_rng(7000 + i).permutation(len(rec.t))
        shuffled = replace(rec, **{c: getattr(rec, c)[perm] for c in channels}, clean=None, meta={})
        cases.append(("unrelated response", system, rec.truth, shuffled))
    out = []
    for kind, model, values, target in cases:
        res, seconds = judge(model, values, target, cut)
        out.append(
            {
                "i": i,
                "record": record,
                "system": system_name,
                "noise": noise,
                "channels": "".join(channels),
                "case": kind,
                **{k: res[k] for k in ("adequate", "explains", "predicts", "within_noise", "fit_nrmse")},
                "heldout_nrmse": res["heldout_nrmse"],
                "trivial_heldout_nrmse": res["trivial_heldout_nrmse"],
                "reasons": "; ".join(res["reasons"]),
                "seconds": seconds,
            }
        )
    return out


def write_table(df: pd.DataFrame, path: Path, seconds: float, ran: int) -> None:
    clean = df[df["case"] == "clean"]
    wrong = df[df["case"] != "clean"]
    fails = int((~clean["adequate"].astype(bool)).sum())
    caught = int((~wrong["adequate"].astype(bool)).sum())
    run = f"{seconds:.0f} s in this run" if ran else "no record run again: the rows are the CSV's"
    lines = [
        "# The adequacy test: false alarms on clean records, and wrong models caught",
        "",
        (__doc__ or "").split("\n\n")[1].replace("\n", " "),
        "",
        f"Command: `python experiments/adequacy_calibration.py` (`make adequacy-calibration`); "
        f"{platform.machine()}, {time.strftime('%Y-%m-%d')}; {run}.",
        "",
        f"**False alarms: {fails} of {len(clean)} clean records ({100 * fails / max(len(clean), 1):.1f} %).** "
        f"Wrong models rejected: {caught} of {len(wrong)}.",
        "",
        "| case | system | noise | records | adequate | explains | predicts | within noise | median fit NRMSE | "
        "median held-out NRMSE | median knowing nothing |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (case, system, noise), g in df.groupby(["case", "system", "noise"]):
        lines.append(
            f"| {case} | {system} | {noise:g} | {len(g)} | {int(g['adequate'].sum())} | {int(g['explains'].sum())} | "
            f"{int((g['predicts'] == True).sum())} | {int((g['within_noise'] == True).sum())} | "  # noqa: E712
            f"{g['fit_nrmse'].median():.3g} | {g['heldout_nrmse'].median():.3g} | {g['trivial_heldout_nrmse'].median():.3g} |"
        )
    alarms = clean[~clean["adequate"].astype(bool)]
    if len(alarms):
        lines += ["", "False alarms:", ""]
        lines += [
            f"- {r.system} {r.record} noise {r.noise:g} ({r.channels}): {r.reasons}"
            for r in alarms.itertuples()
        ]
    missed = wrong[wrong["adequate"].astype(bool)]
    if len(missed):
        lines += ["", "Wrong models passed:", ""]
        lines += [
            f"- {r.case}, {r.record} noise {r.noise:g} ({r.channels}): fit NRMSE {r.fit_nrmse:.3g}, held-out "
            f"{r.heldout_nrmse:.3g}"
            for r in missed.itertuples()
        ]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    args = calibration_args(__doc__, SHIPPED, ROOT / "experiments" / "results")
    logging.basicConfig(level=logging.ERROR)
    csv = args.results / "adequacy_calibration.csv"
    done, have = finished(csv, ["record", "system", "noise"], args.fresh)
    todo = []
    for record in args.records:
        for s, system in enumerate(SYSTEMS):
            for k, noise in enumerate(NOISES):
                i = (sorted(SHIPPED).index(record) * len(SYSTEMS) + s) * len(NOISES) + k
                if (record, system, noise) not in have:
                    todo.append((i, record, system, noise))

    def describe(r: dict) -> str:
        return (
            f"{r['case']} {r['system']} {r['record']} {r['noise']:g}: {'ok' if r['adequate'] else 'REJECTED'}"
        )

    df, seconds = run_grid(csv, done, todo, one, describe, args.jobs)
    write_table(df, args.results / "adequacy_calibration.md", seconds, len(todo))


if __name__ == "__main__":
    main()
