"""One table per strong-motion station sweep: for every event and direction, whether the identified
model describes the record, its held-out NRMSE beside the prediction that knows nothing, and the
period and damping with their intervals, only where the model is adequate.

Reads a Hydra sweep of ``train.py data=csmip`` (``experiment=hayward``, ``experiment=painter_street``)
and writes ``<out>.md`` and ``<out>.csv``; any station, nothing here knows one:

    python train.py experiment=hayward hydra.sweep.dir=outputs/hayward/identify
    python experiments/station_table.py outputs/hayward/identify experiments/results/real/hayward
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import yaml

from pidyn.assessment import reported_damping
from pidyn.bench.tables import cell, interval, load_json


def rows(sweep: Path) -> list[dict]:
    """One row per job folder of the sweep (a failed or unfinished job says why)."""
    out = []
    for cfg_path in sorted(sweep.glob("*/.hydra/config.yaml")):
        run = cfg_path.parent.parent
        cfg = yaml.safe_load(cfg_path.read_text())
        row = {
            "event": cfg["data"].get("event") or Path(str(cfg["data"]["path"])).stem,
            "direction": cfg["data"].get("direction"),
        }
        metrics, failed = load_json(run / "metrics.json"), load_json(run / "failed.json")
        if failed or metrics is None or not (run / "complete.json").is_file():
            row["status"] = "failed: " + (failed or {}).get("message", "did not finish")
            out.append(row)
            continue
        ad = metrics["adequacy"]
        mode = (metrics.get("modal") or [{}])[0]
        meta = metrics.get("record_meta") or {}
        row.update(
            status="adequate" if ad["adequate"] else "not adequate",
            pga_g=(meta.get("pga") or {}).get("input_g")
            if isinstance(meta.get("pga"), dict)
            else meta.get("pga"),
            fit_nrmse=ad["fit_nrmse"],
            heldout_nrmse=ad["heldout_nrmse"],
            trivial_nrmse=ad["trivial_heldout_nrmse"],
            trivial=ad["trivial"],
            beats_trivial=ad["predicts"],
            period_s=mode.get("period_s"),
            period_ci95=mode.get("period_ci95"),
            period_profile_ci95=mode.get("period_profile_ci95"),
            damping=reported_damping(mode)[0],
            damping_ci95=reported_damping(mode)[1],
            reasons="; ".join(ad["reasons"]),
        )
        out.append(row)
    return out


def markdown(table: list[dict], title: str, command: str) -> str:
    ok = [r for r in table if r["status"] == "adequate"]
    done = [r for r in table if not r["status"].startswith("failed")]
    worse = [r for r in done if r.get("beats_trivial") is False]
    lines = [
        f"# {title}",
        "",
        f"Command: `{command}`. Every event and direction identified on its fitting part (the first 65 % "
        "of the shaking) and scored on the rest, beside the prediction that knows nothing on the same span "
        "(the deck moving with its support, the support or mean of supports that best predicts the "
        "fitting part). Period and damping are given only where the model is adequate "
        "(`docs/trust.md`).",
        "",
        f"**{len(ok)} of {len(done)} finished records adequate; {len(worse)} predict their held-out part "
        f"worse than knowing nothing; {len(table) - len(done)} failed.**",
        "",
        "| event | direction | verdict | fit NRMSE | held-out NRMSE | knowing nothing | period (s) | 95 % (Wald) | "
        "95 % (profile) | damping | 95 % |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table:
        if r["status"].startswith("failed"):
            lines.append(f"| {r['event']} | {r['direction']} | {r['status']} | | | | | | | | |")
            continue
        shown = r["status"] == "adequate"
        lines.append(
            f"| {r['event']} | {r['direction']} | {r['status']} | {cell(r['fit_nrmse'], '.3g')} | "
            f"{cell(r['heldout_nrmse'], '.3g')}{'' if r['beats_trivial'] is not False else ' (worse)'} | "
            f"{cell(r['trivial_nrmse'], '.3g')} | "
            + (
                f"{cell(r['period_s'], '.4g')} | {interval(r['period_ci95'], '.4g')} | {interval(r['period_profile_ci95'], '.4g')} | "
                f"{cell(r['damping'], '.3f')} | {interval(r['damping_ci95'], '.3f')} |"
                if shown
                else "- | - | - | - | - |"
            )
        )
    reasons = [r for r in done if r["status"] != "adequate"]
    if reasons:
        lines += ["", "Why a model was not adequate:", ""]
        lines += [f"- {r['event']} {r['direction']}: {r['reasons']}" for r in reasons]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sweep", type=Path)
    ap.add_argument("out", type=Path, help="path without suffix: <out>.md and <out>.csv")
    ap.add_argument("--title", default=None)
    ap.add_argument("--command", default="python train.py experiment=hayward")
    a = ap.parse_args()
    table = rows(a.sweep)
    if not table:
        sys.exit(f"{a.sweep}: no job folder with .hydra/config.yaml")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".md").write_text(markdown(table, a.title or a.out.name, a.command))
    keys = sorted({k for r in table for k in r})
    with open(a.out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(table)
    print(a.out.with_suffix(".md").read_text())


if __name__ == "__main__":
    main()
