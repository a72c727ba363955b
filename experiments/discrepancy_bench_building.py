"""The building diagnosis over seeded hidden cases (``make discrepancy-bench-building``).

Case i draws, from seed 5000 + i, a shear building of 3 to 5 storeys (masses 0.8-1.2 kg,
stiffness tapering from 150-250 N/m to half that at the top, 2 % damping-like dashpots), a
shipped record (the first 20 s at PGA 3 m/s^2), a noise level (0-5 % of each floor's RMS
acceleration) and the floors that carry a sensor (every floor, or, one case in three, every
floor but one between the first and the top), and hides kind ``KINDS[i % len(KINDS)]``:
nothing; each library effect in a random storey, sized against that storey's drift; a pair of
effects in two storeys; a trilinear spring (outside the library). The case is written as a
user's file (t, ag and the measured floors' absolute accelerations) and diagnosed by
``diagnose.py system=shear_building ... data=csv`` in its own process. Finished cases are
skipped on a rerun; the table is rewritten after every case.

Scores per kind: top-1 (the first named effect and its storey), storey errors (the effect
right, the storey wrong), false discoveries on clean cases, seconds per diagnosis.

    python experiments/discrepancy_bench_building.py --cases 66 --jobs 2
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

from pidyn.bench.draws import draw_building, draw_sensors  # noqa: E402
from pidyn.cores import share_cores  # noqa: E402
from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Signals  # noqa: E402
from pidyn.discrepancy.hidden import EQUIVALENT, OUTSIDE, RECORDS, _outside_term  # noqa: E402
from pidyn.runs.provenance import code_commit  # noqa: E402  (the checkout's commit, "+dirty" for changed code)

SINGLE = sorted(LIBRARY)
#: seconds of each record, and the share the diagnosis fits (its default ``diagnosis.fit_share``)
DURATION, FIT_SHARE = 20.0, 0.65
KINDS = ["none", *SINGLE, "pair", "trilinear_spring"]
#: effects a pair draws from (a change in time has its own kind)
PAIRABLE = [e for e in SINGLE if not EFFECTS[e].step_in_time]


def draw_case(i: int, duration: float = DURATION) -> dict:
    """The building, record, noise, sensors and hidden effects of case ``i`` (seeded), on the
    first ``duration`` seconds of its record (the same seeded draws at any length; the
    hidden effects are sized against the longer response)."""
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.excitation.ground_motion import prepare
    from pidyn.systems.shear_building import ShearBuilding

    rng = np.random.default_rng(5000 + i)
    kind = KINDS[i % len(KINDS)]
    n, masses, stiff, damp = draw_building(rng)
    record = str(rng.choice(RECORDS))
    noise = float(rng.uniform(0.0, 0.05))
    sensors = draw_sensors(rng, n)
    gm = prepare(record, scale=1.0, duration=duration, dt=0.02)
    gm_scale = 3.0 / float(np.max(np.abs(gm.acc)))
    gm = prepare(record, scale=gm_scale, duration=duration, dt=0.02)
    linear = ShearBuilding(n, masses, damp, stiff)
    ref = synthetic_from_motion(linear, gm, noise=0.0, channels=("a",))
    effects = {"none": [], "pair": None, "trilinear_spring": ["trilinear_spring"]}.get(kind, [kind])
    if effects is None:
        effects = [str(e) for e in rng.choice(PAIRABLE, 2, replace=False)]
    storeys = [int(s) for s in rng.choice(np.arange(1, n + 1), len(effects), replace=False)]
    terms: dict[int, list] = {}
    hidden = []
    for eff, st in zip(effects, storeys):
        s = storey_signals(ref, st, stiff[st - 1], FIT_SHARE * duration)
        if eff in OUTSIDE:
            p = OUTSIDE[eff](rng, s)
            term = _outside_term(eff, p)
        else:
            p = EFFECTS[eff].sample(rng, s)
            term = EFFECTS[eff].term(p, s.context())
        terms.setdefault(st, []).append(term)
        hidden.append({"effect": eff, "storey": st, "params": {k: float(v) for k, v in p.items()}})
    true = ShearBuilding(n, masses, damp, stiff, storey_terms=terms)
    rec = synthetic_from_motion(true, gm, noise=noise, data_seed=5000 + i, channels=("a",), sensors=sensors)
    return {
        "case": i,
        "kind": kind,
        "n_storeys": n,
        "masses": masses,
        "stiffnesses": stiff,
        "record": record,
        "noise": noise,
        "sensors": sensors,
        "hidden": hidden,
        "rec": rec,
    }


def storey_signals(rec, storey: int, k: float, fit_end: float) -> Signals:
    """The storey's drift in the linear building's response (the size of a hidden effect)."""
    x = rec.clean.x if rec.clean is not None else rec.x
    v = rec.clean.v if rec.clean is not None else rec.v
    below_x = x[:, storey - 2] if storey > 1 else 0.0
    below_v = v[:, storey - 2] if storey > 1 else 0.0
    d, dv = x[:, storey - 1] - below_x, v[:, storey - 1] - below_v
    return Signals(rec.t, d, dv, 1.0, k, stiffness=f"k{storey}", t_fit_end=fit_end, damping=f"c{storey}")


def score(case: dict, d: dict) -> dict:
    """Top-1 and storey scores of one diagnosis against what was hidden."""
    hidden, causes, storeys = case["hidden"], d.get("causes") or [], d.get("storeys") or []
    named = list(zip(causes, storeys))
    learned = d.get("learned") or {}
    label = " + ".join(f"{c}@{s}" for c, s in named) or d["verdict"]
    if learned:  # an unexplained building's learned storey force
        label += f" (learned force @{learned['storey']}{'' if learned['kept'] else ', not kept'})"
    out = {"verdict": d["verdict"], "named": label, "learned_storey": learned.get("storey")}
    if not hidden:
        out.update(hit=d["verdict"] == "none", storey_error=False, false_discovery=d["verdict"] != "none")
        return out
    if case["kind"] == "trilinear_spring":
        st = hidden[0]["storey"]
        ok = d["verdict"] == "unexplained" and st in (d.get("unexplained_storey"), learned.get("storey"))
        ok = ok or (bool(named) and named[0][0] in EQUIVALENT["trilinear_spring"] and named[0][1] == st)
        wrong_storey = bool(named) and named[0][0] in EQUIVALENT["trilinear_spring"] and named[0][1] != st
        out.update(hit=ok, storey_error=wrong_storey, false_discovery=False)
        return out
    truth = {(h["effect"], h["storey"]) for h in hidden}
    if case["kind"] == "pair":
        hit = truth <= set(named)
    else:
        hit = bool(named) and named[0] in truth
    effects_right = bool(named) and named[0][0] in {h["effect"] for h in hidden}
    out.update(hit=hit, storey_error=effects_right and not hit, false_discovery=False)
    return out


def _from_label(row: dict) -> dict:
    """What scoring needs of a diagnosis, read back from a row's label ("gap_contact@1 + ...",
    "unexplained (learned force @3, not kept)") where its diagnosis.json is not kept."""
    label, learned = str(row["named"]), {}
    if " (learned force @" in label:
        label, rest = label.split(" (learned force @")
        learned = {"storey": int(rest.split(",")[0].rstrip(")")), "kept": "not kept" not in rest}
    named = [part.split("@") for part in label.split(" + ") if "@" in part]
    return {
        "verdict": row["verdict"],
        "causes": [c for c, _ in named],
        "storeys": [int(st) for _, st in named],
        "learned": learned,
    }


def _rescored(row_path: Path) -> dict:
    row = json.loads(row_path.read_text())
    diag = row_path.parent / "run" / "diagnosis.json"
    if row.get("verdict") == "failed":
        return row
    case = draw_case(int(row["case"]))  # seeded: the same case again
    case.pop("rec")
    row.update(score(case, json.loads(diag.read_text()) if diag.exists() else _from_label(row)))
    return row


def run_case(i: int, out: Path, duration: float = DURATION) -> dict:
    folder = out / f"case_{i:03d}"
    done = folder / "row.json"
    if done.exists():
        return json.loads(done.read_text())
    case = draw_case(i, duration)
    rec = case.pop("rec")
    folder.mkdir(parents=True, exist_ok=True)
    cols = {"t": rec.t, "ag": rec.f, **{f"a{j}": rec.a[:, j - 1] + rec.f for j in case["sensors"]}}
    pd.DataFrame(cols).to_csv(folder / "record.csv", index=False)
    masses = "[" + ",".join(str(m) for m in case["masses"]) + "]"
    cmd = [
        sys.executable,
        str(ROOT / "diagnose.py"),
        "system=shear_building",
        f"system.n_storeys={case['n_storeys']}",
        f"system.masses={masses}",
        "data=csv",
        f"data.path={folder / 'record.csv'}",
        "logger=none",
        f"hydra.run.dir={folder / 'run'}",
    ]
    code = code_commit(ROOT)  # at the start: a resumed benchmark may span several commits
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    diag = folder / "run" / "diagnosis.json"
    row = {k: v for k, v in case.items() if k != "hidden"}
    row["hidden"] = " + ".join(f"{h['effect']}@{h['storey']}" for h in case["hidden"]) or "none"
    row["seconds"] = seconds
    row["code"] = code
    if duration != DURATION:
        row["duration"] = duration
    if proc.returncode != 0 or not diag.exists():
        row.update(
            verdict="failed", named=proc.stderr.strip().splitlines()[-1][:200] if proc.stderr else "failed"
        )
        row.update(hit=False, storey_error=False, false_discovery=False)
    else:
        d = json.loads(diag.read_text())
        row.update(score(case, d))
        row["heldout_nominal"], row["heldout_extended"] = d["gain"]["nominal"], d["gain"]["extended"]
    done.write_text(json.dumps(row, indent=1, default=str))
    return row


def write_results(rows: list[dict], results: Path, name: str, planned: int | None = None) -> None:
    df = pd.DataFrame(rows).sort_values("case")
    results.mkdir(parents=True, exist_ok=True)
    df.to_csv(results / f"{name}.csv", index=False)
    lines = [
        "# The building diagnosis over seeded hidden cases",
        "",
        "`python experiments/discrepancy_bench_building.py` (`make discrepancy-bench-building`); "
        "every case diagnosed by `diagnose.py system=shear_building ... data=csv`, two at a time on 2 cores "
        "(other work beside them for part of the time); each case's code in its row; "
        f"{len(df)} cases finished"
        + (f" of {planned} planned (the run resumes where it stopped)" if planned else "")
        + ".",
        "",
        "| kind | cases | top-1 (effect and storey) | storey errors | false discoveries | median s | max s |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind in KINDS:
        g = df[df.kind == kind]
        if g.empty:
            continue
        fd = f"{int(g.false_discovery.sum())}/{len(g)}" if kind == "none" else "-"
        lines.append(
            f"| {kind} | {len(g)} | {g.hit.mean():.2f} ({int(g.hit.sum())}/{len(g)}) | "
            f"{int(g.storey_error.sum())} | {fd} | {g.seconds.median():.0f} | {g.seconds.max():.0f} |"
        )
    lines += [
        "",
        f"All: top-1 {df.hit.mean():.2f} ({int(df.hit.sum())}/{len(df)}), median {df.seconds.median():.0f} s.",
        "",
        "| case | kind | storeys | sensors | record | noise | hidden | named | held-out NRMSE nominal -> extended | s | code |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in df.to_dict("records"):
        ext = r.get("heldout_extended")
        nom = r.get("heldout_nominal")
        gain = (
            "-"
            if nom is None or nom != nom
            else f"{nom:.3g} -> {'-' if ext is None or ext != ext else f'{ext:.3g}'}"
        )
        lines.append(
            f"| {r['case']} | {r['kind']} | {r['n_storeys']} | {r['sensors']} | {r['record']} | {r['noise']:.3f} | "
            f"{r['hidden']} | {r['named']}{'' if r['hit'] else ' **(miss)**'} | {gain} | {r['seconds']:.0f} | "
            f"{r.get('code') or '-'} |"
        )
    (results / f"{name}.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=66)  # 6 of each of the 11 kinds
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--only", type=int, nargs="+", help="run these cases only (their numbers)")
    ap.add_argument(
        "--duration", type=float, default=DURATION, help="seconds of each record (the draws stay the same)"
    )
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "outputs" / "discrepancy_bench_building")
    ap.add_argument("--results", type=Path, default=ROOT / "experiments" / "results")
    ap.add_argument("--name", default="discrepancy_bench_building")
    ap.add_argument("--aggregate", action="store_true", help="only rewrite the table from the finished cases")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    if a.aggregate:  # each finished case scored again from its diagnosis (the scorer may have changed)
        rows = [_rescored(f) for f in sorted(a.out.glob("case_*/row.json"))]
        write_results(rows, a.results, a.name, a.cases)
        return
    rows: list[dict] = []
    share_cores(a.jobs)
    with ThreadPoolExecutor(a.jobs) as pool:
        cases = a.only or range(a.first, a.cases)
        futures = {pool.submit(run_case, i, a.out, a.duration): i for i in cases}
        for fut in as_completed(futures):
            row = fut.result()
            rows.append(row)
            print(
                f"case {row['case']:3d} {row['kind']:20s} hidden {row['hidden']:35s} named {row['named']:35s} "
                f"{'hit' if row['hit'] else 'MISS'} {row['seconds']:.0f} s ({len(rows)}/{len(futures)})",
                flush=True,
            )
            write_results(rows, a.results, a.name, a.cases)


if __name__ == "__main__":
    main()
