"""How often the held-out check fails a correct model, and how often it catches a change
(``make heldout-calibration``).

Clean records: a linear SDOF (m=1, c=0.5, k=15) under every shipped ground motion (its first
25 s at PGA 3 m/s^2), with measurement noise of 0, 2.5, 5 and 10 % of each channel's RMS and
the fitting part ending at 50, 60, 70 and 80 % of the record: 13 x 4 x 4 = 208 records, none of
them drawn by the diagnosis benchmarks (other seeds, other shares). Changed records: the same
grid at 5 % noise with the stiffness falling by 15 or 30 % a third of the way into the
held-out part (104 records).

On each, the nominal model is what the diagnosis's polish makes of it: the linear model
fitted by output error to the fitting part (``pidyn.refine.output_error``) from a start 20 %
off, simulated over the whole record from the measured initial state. Then the held-out check
of the diagnosis (``pidyn.discrepancy.heldout_check.heldout_check``), with the sensitivities of the
simulated response to the fitted parameters, as ``diagnose`` runs it; beside it the earlier
rule (the ratio of the two parts' simulation errors above the noise, failing beyond 3).

Writes ``experiments/results/heldout_calibration.{md,csv}``.

    python experiments/heldout_calibration.py
    python experiments/heldout_calibration.py --records el_centro kobe --noises 0.05 --quick
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

from pidyn.cores import share_cores  # noqa: E402
from pidyn.data.sources import synthetic_from_motion  # noqa: E402
from pidyn.discrepancy.heldout_check import (  # noqa: E402
    HELDOUT_BAND,
    SETTLE_PERIODS,
    heldout_check,
    simulation_sensitivity,
)
from pidyn.excitation.ground_motion import SHIPPED, prepare  # noqa: E402
from pidyn.refine.output_error import fit_output_error  # noqa: E402
from pidyn.simulate import simulate_response  # noqa: E402
from pidyn.systems.sdof import LinearSDOF, SDOFSystem  # noqa: E402
from pidyn.systems.terms import LinearStiffness, StiffnessLoss, ViscousDamping  # noqa: E402
from pidyn.weak_form import measurement_noise, smooth_signals  # noqa: E402

NOISES = (0.0, 0.025, 0.05, 0.1)
SHARES = (0.5, 0.6, 0.7, 0.8)
DROPS = (0.15, 0.3)
DURATION, DT, PGA = 25.0, 0.01, 3.0
TRUTH = {"m": 1.0, "c": 0.5, "k": 15.0}
OLD_RATIO = 3.0


def record_names() -> list[str]:
    return sorted(SHIPPED)


def make_record(name: str, noise: float, share: float, drop: float, seed: int):
    """The simulated record and its split (fit, held-out) in seconds."""
    gm = prepare(name, duration=DURATION, dt=DT)
    gm = prepare(name, duration=DURATION, dt=DT, scale=PGA / gm.pga)
    fit_end = share * float(gm.t[-1])
    if drop > 0:
        t_d = fit_end + (float(gm.t[-1]) - fit_end) / 3.0
        system = SDOFSystem(
            [
                ViscousDamping(TRUTH["c"]),
                LinearStiffness(TRUTH["k"]),
                StiffnessLoss(drop, t_d, 0.0, DURATION + 1),
            ],
            name="linear_with_loss",
        )
        params = {**TRUTH, "drop": drop, "t_d": t_d}
    else:
        system, params = LinearSDOF(TRUTH["c"], TRUTH["k"]), dict(TRUTH)
    record = synthetic_from_motion(system, gm, noise=noise, data_seed=seed, params=params)
    return record, (0.0, fit_end), (fit_end, float(gm.t[-1]))


def judge(record, fit: tuple[float, float], held: tuple[float, float]) -> dict:
    """The nominal linear model fitted on the fitting part, then both checks on the record."""
    nominal = LinearSDOF(TRUTH["c"], TRUTH["k"])
    start = {"c": 1.2 * TRUTH["c"], "k": 0.8 * TRUTH["k"]}
    res = fit_output_error(record.segment(*fit), nominal, init=start, max_nfev=40)
    values = {**TRUTH, **res.params}
    period = 2 * np.pi * np.sqrt(TRUTH["m"] / TRUTH["k"])
    xs, vs = smooth_signals(record.t, record.x[:, 0], record.v[:, 0], period)
    x0 = np.array([record.x[0, 0], vs[0]])  # as diagnose starts its free run: measured x, smoothed x'

    def simulate(p: dict[str, float]) -> np.ndarray:  # the forced response, from rest (as diagnose)
        return simulate_response(nominal, {**values, **p}, record)["x"][:, 0]

    sim = simulate_response(nominal, values, record, state0=x0)["x"][:, 0]
    names = list(res.params)
    jac = simulation_sensitivity(simulate, values, names)
    m_fit = (record.t >= fit[0]) & (record.t <= fit[1])
    m_ho = (record.t > fit[1]) & (record.t <= held[1])
    period = 2 * np.pi * np.sqrt(values["m"] / values["k"])
    settle = int(round(SETTLE_PERIODS * period / record.dt))
    noise_std = measurement_noise(record.t, record.x[:, 0], period)
    check = heldout_check(
        record.x[:, 0],
        sim,
        m_fit,
        m_ho,
        noise_std,
        sensitivity=jac,
        band=(record.dt, HELDOUT_BAND / period),
        settle=settle,
    )
    return {
        "statistic": check.statistic,
        "p_value": check.p_value,
        "failed": check.failed,
        "old_ratio": check.ratio,
        "old_failed": bool(check.ratio is not None and check.ratio > OLD_RATIO),
        "dof_fit": check.dof[0] if check.dof else None,
        "dof_heldout": check.dof[1] if check.dof else None,
        "k_error_pct": 100 * (values["k"] / TRUTH["k"] - 1),
    }


def cases(records: list[str], noises, shares, quick: bool) -> list[dict]:
    out = []
    for r_i, name in enumerate(records):
        for n_i, noise in enumerate(noises):
            for s_i, share in enumerate(shares):
                seed = 90_000 + 100 * r_i + 10 * n_i + s_i  # seeds no benchmark draws
                out.append({"record": name, "noise": noise, "share": share, "drop": 0.0, "seed": seed})
        for s_i, share in enumerate(shares):
            for d_i, drop in enumerate(DROPS[:1] if quick else DROPS):
                seed = 95_000 + 100 * r_i + 10 * s_i + d_i
                out.append({"record": name, "noise": 0.05, "share": share, "drop": drop, "seed": seed})
    return out


def one(case: dict) -> dict:
    t0 = time.perf_counter()
    record, fit, held = make_record(case["record"], case["noise"], case["share"], case["drop"], case["seed"])
    return {**case, **judge(record, fit, held), "seconds": time.perf_counter() - t0}


def run(todo: list[dict], jobs: int) -> pd.DataFrame:
    """Every case, ``jobs`` at a time (one process each), with a line every 20 cases."""
    from concurrent.futures import ProcessPoolExecutor

    rows = []
    share_cores(jobs)
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        for n, row in enumerate(pool.map(one, todo), 1):
            rows.append(row)
            if n % 20 == 0 or n == len(todo):
                print(
                    f"[{n}/{len(todo)}] {row['record']} noise {row['noise']:g} share {row['share']:g}",
                    flush=True,
                )
    return pd.DataFrame(rows)


def summary_lines(df: pd.DataFrame) -> list[str]:
    clean, changed = df[df["drop"] == 0], df[df["drop"] > 0]
    lines = [
        "| records | cases | calibrated check fails | earlier ratio rule fails |",
        "|---|---|---|---|",
        f"| clean (false alarms) | {len(clean)} | {int(clean.failed.sum())} ({100 * clean.failed.mean():.1f} %) | "
        f"{int(clean.old_failed.sum())} ({100 * clean.old_failed.mean():.1f} %) |",
    ]
    for drop, g in changed.groupby("drop"):
        lines.append(
            f"| stiffness -{100 * drop:.0f} % in the held-out part (detections) | {len(g)} | "
            f"{int(g.failed.sum())} ({100 * g.failed.mean():.1f} %) | "
            f"{int(g.old_failed.sum())} ({100 * g.old_failed.mean():.1f} %) |"
        )
    lines += [
        "",
        "False alarms per noise level and fitting share (clean records; calibrated / earlier rule):",
        "",
    ]
    table = clean.groupby(["noise", "share"]).agg(calibrated=("failed", "sum"), earlier=("old_failed", "sum"))
    lines += ["| noise | fitting share | cases | calibrated | earlier |", "|---|---|---|---|---|"]
    for (noise, share), r in table.iterrows():
        n = int(((clean.noise == noise) & (clean.share == share)).sum())
        lines.append(f"| {noise:g} | {share:g} | {n} | {int(r.calibrated)} | {int(r.earlier)} |")
    missed = changed[~changed.failed.astype(bool)]
    if len(missed):
        lines += [
            "",
            "Changes the calibrated check missed: "
            + "; ".join(f"{r.record} drop {r.drop:g} share {r.share:g}" for r in missed.itertuples()),
        ]
    alarms = clean[clean.failed.astype(bool)]
    if len(alarms):
        lines += [
            "",
            "False alarms of the calibrated check: "
            + "; ".join(
                f"{r.record} noise {r.noise:g} share {r.share:g} (p {r.p_value:.2g})"
                for r in alarms.itertuples()
            ),
        ]
    return lines


def write(df: pd.DataFrame, out: Path, command: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "heldout_calibration.csv", index=False)
    lines = [
        "# The held-out check: false alarms on clean records, detections of a change",
        "",
        (__doc__ or "").split("\n\n")[1].replace("\n", " "),
        "",
        (__doc__ or "").split("\n\n")[2].replace("\n", " "),
        "",
        f"Command: `{command}` (`make heldout-calibration`); code {_commit()}; {platform.machine()}, "
        f"{time.strftime('%Y-%m-%d')}; {df.seconds.sum():.0f} s in all.",
        "",
        *summary_lines(df),
        "",
    ]
    (out / "heldout_calibration.md").write_text("\n".join(lines))


def _commit() -> str:
    from pidyn.runs.provenance import code_commit

    return code_commit(ROOT)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--records", nargs="*", default=None, help="shipped records (default: every one)")
    ap.add_argument("--noises", nargs="*", type=float, default=list(NOISES))
    ap.add_argument("--shares", nargs="*", type=float, default=list(SHARES))
    ap.add_argument("--quick", action="store_true", help="one stiffness loss per record and share")
    ap.add_argument("--out", type=Path, default=ROOT / "experiments" / "results")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    known = record_names()
    records = a.records or known
    unknown = sorted(set(records) - set(known))
    if unknown:
        ap.error(f"unknown record(s) {unknown}; choose from {', '.join(known)}")
    df = run(cases(records, a.noises, a.shares, a.quick), a.jobs)
    write(df, a.out, "python " + " ".join(["experiments/heldout_calibration.py", *sys.argv[1:]]))
    print("\n".join(summary_lines(df)))


if __name__ == "__main__":
    main()
