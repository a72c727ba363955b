"""What a shake-table model's identification run can teach about its other runs, read from the
records alone (no model): for each floor of each run, how much of its motion lies where the
identification run shows the floor does not respond, and how well the run's own motion is
predicted linearly from its own table.

Three numbers per floor of a predicted run:

- ``share above``: the share of the floor's rms above ``--above`` Hz (a model of the storeys
  has its modes below it, the identification run's floor/table gain there is listed beside);
- ``gain-matched floor``: the least NRMSE of any prediction whose spectrum magnitude at every
  frequency is the identification run's measured floor/table gain (Welch H1) times the run's
  own table spectrum, phases chosen best. A linear model that reproduces the identification
  run's gain cannot do better. Where the identification run's coherence is low (a resonance
  whose frequency moves with the amplitude), its measured gain is smeared and the floor is weak;
- ``own linear``: a causal FIR filter (``--taps`` samples) from the run's own table to the floor,
  fitted by ridge least squares on the run's first ``--fit-share`` and scored on the rest: what
  the run's own linear content allows, with no other run involved.

    python experiments/shake_table_reach.py      # about 20 s; results/real/shake_table_reach.md
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from pidyn.data.imu import run_labels, xsens_record
from pidyn.signals import transfer_function

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"
MODELS_DIR = ROOT / "data" / "mini_shake_table"
#: model folder -> the run each is identified on (experiments/shake_table.py's)
MODELS = {
    "Flexible 3 story": "Northridge",
    "Stiff 3 story": "Northridge",
    "Stiff 1 story": "Northridge Trial 1",
}


def absolute(path: Path, run: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The table's acceleration, the floors' absolute accelerations and the step, as pidyn reads them."""
    rec = xsens_record(path, run)
    return rec.f, rec.a + rec.f[:, None], float(rec.meta.dt)


def gain(table: np.ndarray, floor: np.ndarray, step: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """The floor/table gain |H1| over frequency (``pidyn.signals.transfer_function``, Welch)."""
    tf = transfer_function(table, floor, step, nperseg)
    return tf.freq, np.abs(tf.h)


def gain_matched_floor(h_f, h, table, floor, step) -> float:
    """min over phases of NRMSE(prediction, floor) for |P| = |H| |G|: sqrt(sum (|Y| - |P|)^2 / sum |Y|^2)."""
    f = np.fft.rfftfreq(len(table), step)
    y = np.abs(np.fft.rfft(floor))
    p = np.interp(f, h_f, h) * np.abs(np.fft.rfft(table))
    return float(np.sqrt(np.sum((y - p) ** 2) / np.sum(y**2)))


def share_above(floor: np.ndarray, step: float, above: float) -> float:
    f = np.fft.rfftfreq(len(floor), step)
    y2 = np.abs(np.fft.rfft(floor)) ** 2
    return float(np.sqrt(y2[f > above].sum() / y2.sum()))


def lagged(u: np.ndarray, taps: int) -> np.ndarray:
    out = np.zeros((len(u), taps))
    for j in range(taps):
        out[j:, j] = u[: len(u) - j]
    return out


def own_linear(table: np.ndarray, floors: np.ndarray, taps: int, fit_share: float) -> list[float]:
    """Each floor's NRMSE on the run's last part by a ridge FIR fitted on its first part."""
    x = lagged(table, taps)
    n = int(fit_share * len(table))
    gram = x[:n].T @ x[:n]
    w = np.linalg.solve(gram + 1e-3 * np.trace(gram) / taps * np.eye(taps), x[:n].T @ floors[:n])
    pred, meas = x[n:] @ w, floors[n:]
    return [
        float(np.sqrt(np.mean((pred[:, i] - meas[:, i]) ** 2) / np.mean(meas[:, i] ** 2)))
        for i in range(floors.shape[1])
    ]


def rows(above: float, taps: int, fit_share: float, nperseg: int) -> list[dict]:
    out = []
    for model, ident in MODELS.items():
        path = MODELS_DIR / model
        g0, a0, step = absolute(path, ident)
        gains = [gain(g0, a0[:, i], step, nperseg) for i in range(a0.shape[1])]
        for run in run_labels(path):
            if run == ident:
                continue
            g, a, _ = absolute(path, run)
            own = own_linear(g, a, taps, fit_share)
            for i in range(a.shape[1]):
                h_f, h = gains[i]
                out.append(
                    {
                        "model": model,
                        "identified on": ident,
                        "run": run,
                        "floor": i + 1,
                        "share above": share_above(a[:, i], step, above),
                        "identification gain above": float(np.median(h[h_f > above])),
                        "gain-matched floor": gain_matched_floor(h_f, h, g, a[:, i], step),
                        "own linear": own[i],
                    }
                )
    return out


def table(rows_: list[dict], above: float) -> str:
    head = (
        f"| model | identified on | run | floor | rms share above {above:g} Hz | the identification run's gain there "
        "(median) | gain-matched floor | own linear (held out) |\n|---|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r['model']} | {r['identified on']} | {r['run']} | {r['floor']} | {r['share above']:.3f} | "
        f"{r['identification gain above']:.3f} | {r['gain-matched floor']:.3f} | {r['own linear']:.3f} |\n"
        for r in rows_
    )
    means = {}
    for r in rows_:
        means.setdefault((r["model"], r["run"]), []).append(r)
    tail = "\n| model | run | mean gain-matched floor | mean own linear |\n|---|---|---|---|\n" + "".join(
        f"| {m} | {run} | {np.mean([r['gain-matched floor'] for r in rs]):.3f} | "
        f"{np.mean([r['own linear'] for r in rs]):.3f} |\n"
        for (m, run), rs in means.items()
    )
    return head + body + tail


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--above", type=float, default=30.0, help="Hz: above every storey mode of the 3-storey models"
    )
    ap.add_argument("--taps", type=int, default=240, help="FIR length in samples (2 s at 120 Hz)")
    ap.add_argument(
        "--fit-share", type=float, default=0.65, help="the run's first share fitted (the studies' split)"
    )
    ap.add_argument("--nperseg", type=int, default=1024, help="Welch segment (samples) for the gains")
    ap.add_argument("--out", type=Path, default=RESULTS / "shake_table_reach")
    args = ap.parse_args(argv)
    found = rows(args.above, args.taps, args.fit_share, args.nperseg)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(found[0]))
        w.writeheader()
        w.writerows(found)
    cmd = "python experiments/shake_table_reach.py" + "".join(f" {a}" for a in (argv or sys.argv[1:]))
    text = f"# What the identification run can teach about the other runs\n\n`{cmd}`\n\n" + table(
        found, args.above
    )
    args.out.with_suffix(".md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
