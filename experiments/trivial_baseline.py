"""The prediction that knows nothing beside a published study's held-out scores, without running
the study again: it depends on the record and its split only.

For every row of a strong-motion study's CSV (``experiments/results/real/painter_street.csv``),
the event's record is read as its identification read it (the station's channel sets, one output
for a one-mode model, the same step and fitting share), and the deck "moving with its support"
(the support, or the mean of the supports, that best predicts the fitting part;
``pidyn.adequacy.trivial_predictions``) is scored on the held-out part. Writes a markdown section
to stdout and the rows to ``<csv stem>_trivial.csv``.

    python experiments/trivial_baseline.py experiments/results/real/painter_street.csv data/painter_street/records
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def trivial_heldout(path: Path, station: str, direction: str) -> tuple[float, str]:
    """The held-out NRMSE of knowing nothing on one event-direction, and what it predicted."""
    from pidyn.adequacy import trivial_predictions
    from pidyn.assessment import ground_acceleration
    from pidyn.data.strong_motion import csmip_record
    from pidyn.reporting import nrmse

    rec = csmip_record(path, station=station, direction=direction, on_missing="drop", max_outputs=1)
    split = rec.meta.split
    label, pred = trivial_predictions(rec, split.fit)["a"]
    m = (rec.t >= split.heldout[0] - 1e-9) & (rec.t <= split.heldout[1] + 1e-9)
    meas = rec.a[:, 0] + ground_acceleration(rec)
    return nrmse(pred[m], meas[m]), label


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", type=Path)
    ap.add_argument("records", type=Path)
    ap.add_argument("--station", default="CE89324")
    ap.add_argument("--suffix", default="_ce89324p.zip")
    a = ap.parse_args()
    df = pd.read_csv(a.csv)
    rows = []
    for r in df[df["status"].str.startswith("ok")].itertuples():  # a model the record rejects is scored too
        triv, label = trivial_heldout(a.records / f"{r.event}{a.suffix}", a.station, r.direction)
        rows.append(
            {
                "event": r.event,
                "direction": r.direction,
                "role": r.role,
                "heldout_nrmse_a": r.heldout_nrmse_a,
                "srim_heldout_nrmse_a": r.srim_heldout_nrmse_a,
                "trivial_heldout_nrmse_a": triv,
                "trivial": label,
                "beats_trivial": bool(r.heldout_nrmse_a < triv),
            }
        )
    out = pd.DataFrame(rows)
    out.to_csv(a.csv.with_name(a.csv.stem + "_trivial.csv"), index=False)
    lines = [
        "| event | direction | role | held-out NRMSE: ours / SRIM / knowing nothing | knowing nothing is |",
        "|---|---|---|---|---|",
    ]
    for r in out.itertuples():
        srim = "-" if not np.isfinite(r.srim_heldout_nrmse_a) else f"{r.srim_heldout_nrmse_a:.3f}"
        flag = "" if r.beats_trivial else " **(worse)**"
        lines.append(
            f"| {r.event} | {r.direction} | {r.role} | {r.heldout_nrmse_a:.3f}{flag} / {srim} / "
            f"{r.trivial_heldout_nrmse_a:.3f} | {r.trivial} |"
        )
    srim_ok = out[np.isfinite(out["srim_heldout_nrmse_a"])]
    for role in ("untouched", "tuning"):
        g = out[out["role"] == role]
        s = srim_ok[srim_ok["role"] == role]
        lines.append(
            f"\n- {role}: ours below knowing nothing on {int(g['beats_trivial'].sum())} of {len(g)} "
            f"event-directions (median {g['heldout_nrmse_a'].median():.3f} against "
            f"{g['trivial_heldout_nrmse_a'].median():.3f}); SRIM below it on "
            f"{int((s['srim_heldout_nrmse_a'] < s['trivial_heldout_nrmse_a']).sum())} of {len(s)}."
        )
    print("\n".join(lines))


if __name__ == "__main__":
    main()
