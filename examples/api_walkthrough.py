"""pidyn from Python: identify a Duffing oscillator, predict an unseen earthquake, diagnose a model.

    python examples/api_walkthrough.py            # the default schedules (several minutes on 2 cores)
    python examples/api_walkthrough.py --quick    # shortened schedules (what the tests run)

Each step is what a notebook cell would hold; every run also writes its run folder under
``--out`` (default ``outputs/examples``), readable again with ``pidyn.Result.load``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import pidyn

QUICK = {
    "model__schedule__pretrain_iters": 150,
    "model__schedule__pretrain_iters_window": 150,
    "model__schedule__max_iters": 300,
    "model__schedule__max_windows": 3,
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="shortened PIDynNet schedules")
    ap.add_argument("--out", default="outputs/examples")
    a = ap.parse_args()
    out = Path(a.out)
    fast = QUICK if a.quick else {}

    # 1. A record: a Duffing oscillator (c 0.5, k1 15, k3 120) under Kobe 1995, 2.5 % noise on x and x'.
    #    Your own file: pidyn.Record.from_csv("measured.csv") with columns t, ag, x (and v, a).
    record = pidyn.Record.simulate("duffing", excitation="kobe", noise=0.025, duration=20.0, seed=1)
    print(f"record '{record.name}': {len(record.t)} samples, dt {record.dt} s, channels {record.sensors()}")

    # 2. Identify: PIDynNet over subperiod windows, then the multiple-shooting refinement with intervals.
    result = pidyn.identify(
        record, "duffing", init={"k3": 60.0}, baselines="none", logger="none", out_dir=out / "duffing", **fast
    )
    print(result.equation)
    table = result.to_frame()
    print(
        table[["value", "ci95_lo", "ci95_hi", "truth", "error_pct", "pidynnet"]].to_string(
            float_format="%.5g"
        )
    )
    covered = ((table.ci95_lo <= table.truth) & (table.truth <= table.ci95_hi)).sum()
    print(f"the 95 % intervals hold the truth for {covered} of {len(table)} parameters")
    result.plot(out / "duffing" / "estimate_history.png")
    result.save(out / "duffing_saved")

    # 3. Predict the response to an earthquake the identification never saw (El Centro 1940 at half scale).
    pred = pidyn.predict(
        result,
        "el_centro",
        scale=0.5,
        duration=8.0,
        **({"iterations": 150, "lbfgs_steps": 10} if a.quick else {}),
    )
    frame = pred.to_frame()
    r = np.corrcoef(frame.x1_pidynnet, frame.x1_simulated)[0, 1]
    print(
        f"El Centro x0.5: PIDynNet's prediction against the identified model's simulation, correlation {r:.3f}"
    )
    frame.to_csv(out / "prediction_el_centro.csv", index=False)

    # 4. Diagnose: a linear model of a structure that hides quadratic damping (the package's
    #    hidden-effect records; any Record works the same way).
    diagnosis = pidyn.diagnose(
        None,
        nominal="linear",
        data__source__effect="quadratic_damping",
        noise=0.02,
        data_seed=5,
        logger="none",
        out_dir=out / "diagnosis",
        **fast,
    )
    print(f"verdict: {diagnosis.verdict}, causes {diagnosis.causes}; extended model: {diagnosis.extended}")
    print(
        f"held-out NRMSE: nominal {diagnosis.gain['nominal']:.3g}, extended {diagnosis.gain['extended']:.3g}"
    )
    print(f"report: {diagnosis.report}")


if __name__ == "__main__":
    main()
