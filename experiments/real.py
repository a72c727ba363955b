"""The Painter Street study (CSMIP station CE89324): every shipped event identified, transverse
and longitudinal, as one Hydra multirun; every event diagnosed in both directions as another (the
final model of each against SRIM, and the strong events' running period); the tables and figures
in experiments/results/real/.

    python experiments/real.py                       # make real (about 18 min on two cores: identification 6, one input 2, diagnosis 10)
    python experiments/real.py --aggregate outputs/real/<stamp>   # the tables again from finished runs
    python experiments/real.py --events riodell82 petrolia_25apr1992 --skip-diagnosis
    python experiments/real.py --resume outputs/real/<stamp>    # finish an interrupted study
    python experiments/real.py --resume outputs/real/<stamp> --two-modes   # add every event with two modes

The multiruns use the joblib launcher (two jobs here); on a cluster, add
``--launcher submitit_slurm_cpu``. With ``--resume`` a run folder that holds its results is not run
again (``skip_done``; delete it to redo it), so an interrupted study goes on where it stopped.
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import shutil
import sys
import time
from pathlib import Path

import numpy as np
from real_final import final_lines
from real_modes import two_modes_lines

from pidyn.assessment import reported_damping
from pidyn.bench.launch import run_logged
from pidyn.bench.tables import cell, load_json, sweep_runs

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"
RECORDS = ROOT / "data" / "painter_street"
#: events looked at while the methods were set up (the data's start, the model with several
#: supports, the peers' settings, the accelerometer diagnosis): reported apart from the others
TUNING = {
    "RioDell_14Sep2012_71842255",
    "bayview_11oct2013_72086051",
    "petrolia_25apr1992",
    "riodell82",
    "petroliaaftershock1_26apr1992",
    "nc73821046",
    "nc73201181",
    "nc73943846",
    "nc73666231",
    "capemendocinoaftershock_21nov1986",
    "eureka_24aug1983",
}
WEAK_G = 0.1  # weak events: peak ground acceleration below this (g)


def events() -> list[str]:
    return sorted(p.name[: -len("_ce89324p.zip")] for p in (RECORDS / "records").glob("*_ce89324p.zip"))


def catalogue() -> dict[str, dict]:
    """The station's event catalogue (events.csv) by archive name."""
    with (RECORDS / "events.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    names = {e.lower(): e for e in events()}
    return {names[r["cesmd_id"].lower()]: r for r in rows if r["cesmd_id"].lower() in names}


def run_sweeps(
    base: Path, chosen: list[str], jobs: int, launcher: str, diagnose: bool, two_modes: bool = False
) -> None:
    sweep = ",".join(chosen)
    todo = [
        ("identify", "train.py", "painter_street", [f"data.event={sweep}"]),
        # the reduced choice, measured: the bent's base alone as the ground of the whole deck
        (
            "one_input",
            "train.py",
            "painter_street",
            [f"data.event={sweep}", "data.direction=transverse", "data.inputs=[3]", "data.outputs=[7]"],
        ),
    ]
    if (
        two_modes
    ):  # the same events with a second mode, started where each event's single mode ended (--two-modes)
        todo.append(
            (
                "two_modes",
                "train.py",
                "painter_street",
                [
                    f"data.event={sweep}",
                    "system=modes",
                    "baselines.run=[transfer_function,srim]",  # SRIM's order-4 model is one more start
                    f"model.start='{base / 'identify'}/*_data.direction=${{data.direction}},data.event=${{data.event}}'",
                ],
            )
        )
    if diagnose:  # every event in both directions: the final model of each (the strong ones' table too)
        todo.append(
            (
                "diagnose",
                "diagnose.py",
                "painter_street_diagnose",
                ["data=csmip", f"data.event={sweep}", "data.direction=transverse,longitudinal"],
            )
        )
    for name, script, experiment, extra in todo:
        cmd = [
            sys.executable,
            script,
            f"experiment={experiment}",
            f"hydra.sweep.dir={base / name}",
            f"hydra.launcher.n_jobs={jobs}",
            "skip_done=true",
            *extra,
        ]
        run_logged(cmd, name, ROOT, launcher)


#: the events whose transverse diagnosis is shown with its running period
#: (conf/experiment/painter_street_diagnose.yaml's own sweep): the strong ones and two weak ones
DIAGNOSED = (
    "petrolia_25apr1992",
    "petroliaaftershock1_26apr1992",
    "petroliaaftershock2_26apr1992",
    "riodell82",
    "RioDell_14Sep2012_71842255",
    "nc73667866",
)


def identification_rows(folder: Path) -> list[dict]:
    cat = catalogue()
    rows = []
    for cfg, run in sweep_runs(folder):
        event, direction = cfg["data"]["event"], cfg["data"]["direction"]
        row = {
            "event": event,
            "direction": direction,
            "run": run,
            "role": "tuning" if event in TUNING else "untouched",
            "date": cat.get(event, {}).get("time_utc", "")[:10],
            "magnitude": cat.get(event, {}).get("magnitude"),
            "pga_catalogue_g": float(cat.get(event, {}).get("pga_str_g") or "nan"),
        }
        failed, metrics = load_json(run / "failed.json"), load_json(run / "metrics.json")
        if failed or not metrics or not (run / "complete.json").is_file():  # finished runs only
            row["status"] = "failed: " + (failed["message"] if failed else "no results (interrupted?)")
            rows.append(row)
            continue
        meta, mode = metrics.get("record_meta") or {}, (metrics.get("modal") or [{}])[0]
        held = metrics.get("heldout") or {}
        adequate = metrics.get("adequate", True)
        if not adequate:  # a rejected model's period and damping are the fit's, not the bridge's
            mode = {}
        row.update(
            {
                "status": "ok" if adequate else "ok (model not adequate: no period or damping)",
                "adequate": adequate,
                "trivial_heldout_nrmse_a": _mean_or_none(held.get("trivial_nrmse")),
                "beats_trivial": held.get("beats_trivial"),
                "pga_g": meta.get("pga", float("nan")) / 9.80665,
                "inputs": meta.get("input_channels"),
                "outputs": meta.get("output_channels"),
                "notes": "; ".join(meta.get("notes") or []),
                "period_s": mode.get("period_s"),
                "period_ci95": mode.get("period_ci95"),
                "period_profile_ci95": mode.get("period_profile_ci95"),
                "damping": reported_damping(mode)[0],
                "damping_ci95": reported_damping(mode)[1],
                "damping_note": mode.get("not_a_property"),
                "heldout_nrmse_a": held.get("mean_nrmse_a"),
                "fit_nrmse_a": held.get("fit_mean_nrmse_a"),
                "wall_s": metrics.get("wall_seconds"),
                "equation": None,
            }
        )
        base = load_json(run / "baselines.json") or {"baselines": []}
        for b in base["baselines"]:
            modes = b.get("modes") or []
            key = b["method"]
            row[f"{key}_period_s"] = modes[0]["period_s"] if modes else None
            row[f"{key}_period_ci95"] = modes[0].get("period_ci95") if modes else None
            row[f"{key}_damping"] = modes[0]["damping_ratio"] if modes else None
            if key in ("srim", "okid_era"):
                row[f"{key}_heldout_nrmse_a"] = b.get("heldout_nrmse_a")
                row[f"{key}_order"] = b.get("order")
                row[f"{key}_note"] = b.get("note", "")
        rows.append(row)
    return with_event_pga(rows)


def _mean_or_none(scores: dict | None) -> float | None:
    vals = [v for k, v in (scores or {}).items() if k.startswith("a")]
    return float(np.mean(vals)) if vals else None


def with_event_pga(rows: list[dict]) -> list[dict]:
    """Each row with ``event_pga_g``: the largest peak input acceleration of its event over the
    directions identified (the event's PGA at the station's ground channels)."""
    peak: dict[str, float] = {}
    for r in rows:
        if r.get("status") == "ok" and np.isfinite(r.get("pga_g", np.nan)):
            peak[r["event"]] = max(peak.get(r["event"], 0.0), r["pga_g"])
    return [{**r, "event_pga_g": peak[r["event"]]} if r["event"] in peak else r for r in rows]


def peer_span(row: dict) -> tuple[float, float] | None:
    """The span of the peers' periods (the transfer function's with its interval)."""
    vals = []
    for key in ("srim", "okid_era", "transfer_function"):
        p = row.get(f"{key}_period_s")
        if p is None:
            continue
        vals.append(p)
        ci = row.get(f"{key}_period_ci95") or [None, None]
        vals += [v for v in ci if v is not None]
    return (min(vals), max(vals)) if vals else None


def judge(row: dict) -> dict:
    """The issue's two lines per event: inside the peers' span (weak events), held-out against SRIM.
    ``inside_peers`` where the direction's own PGA is below 0.1 g; ``weak_event`` says whether the
    event's (the larger of its two directions') is too: a skewed deck's longitudinal response under
    a transverse shaking of 0.14 g is not a weak event's."""
    out = {}
    span = peer_span(row)
    ci = row.get("period_ci95") or [None, None]
    if span and None not in ci and row.get("pga_g", 1) < WEAK_G:
        out["inside_peers"] = bool(ci[0] <= span[1] and ci[1] >= span[0])
        out["weak_event"] = bool(row.get("event_pga_g", row["pga_g"]) < WEAK_G)
        prof = row.get("period_profile_ci95")
        if prof:  # the profile's set; an end it leaves open (None) runs past the scanned factor of two
            lo, hi = (-np.inf if prof[0] is None else prof[0]), (np.inf if prof[1] is None else prof[1])
            out["profile_inside_peers"] = bool(lo <= span[1] and hi >= span[0])
    srim = row.get("srim_heldout_nrmse_a")
    if srim is not None and row.get("heldout_nrmse_a") is not None:
        out["beats_srim"] = bool(row["heldout_nrmse_a"] <= srim)
    return out


def identification_table(rows: list[dict], direction: str) -> list[str]:
    lines = [
        f"### {direction.capitalize()}",
        "",
        "| event | date | PGA (g) | inputs -> output | T (s), 95 % | profile 95 % | damping (%), 95 % | "
        "transfer fn T | SRIM T | OKID-ERA T | held-out NRMSE: ours / SRIM / OKID-ERA | s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted((r for r in rows if r["direction"] == direction), key=lambda r: r.get("pga_g") or 0):
        tag = " *(t)*" if r["role"] == "tuning" else ""
        if not r["status"].startswith("ok"):
            lines.append(f"| {r['event']}{tag} | {r['date']} | - | - | {r['status']} | | | | | | | |")
            continue
        if r["status"] != "ok":  # a model the record rejects: its scores, no period or damping
            lines.append(_rejected_row(r, tag))
            continue
        ci, zc = r["period_ci95"], r["damping_ci95"]
        j = judge(r)
        inside = "" if "inside_peers" not in j else (" (in)" if j["inside_peers"] else " (**out**)")
        inside += "" if j.get("weak_event", True) else f" (event {cell(r['event_pga_g'])} g)"
        beats = "" if "beats_srim" not in j else ("" if j["beats_srim"] else " **(SRIM better)**")
        lines.append(
            f"| {r['event']}{tag} | {r['date']} | {cell(r['pga_g'])} | {r['inputs']} -> {r['outputs']} | "
            f"{cell(r['period_s'])} [{cell(ci[0])}, {cell(ci[1])}]{inside} | {_profile_cell(r, j)} | "
            f"{_damping_cell(r['damping'], zc, r.get('damping_note'))} | {cell(r.get('transfer_function_period_s'))} | "
            f"{cell(r.get('srim_period_s'))} | {cell(r.get('okid_era_period_s'))} | {cell(r['heldout_nrmse_a'])} / "
            f"{cell(r.get('srim_heldout_nrmse_a'))} / {cell(r.get('okid_era_heldout_nrmse_a'))}{beats} | {cell(r['wall_s'], '.0f')} |"
        )
    return lines + [""]


def _rejected_row(r: dict, tag: str) -> str:
    """An identification table's row for a model the record rejects: its and the peers' scores only."""
    return (
        f"| {r['event']}{tag} | {r['date']} | {cell(r['pga_g'])} | {r['inputs']} -> {r['outputs']} | "
        f"not adequate | | | {cell(r.get('transfer_function_period_s'))} | {cell(r.get('srim_period_s'))} | "
        f"{cell(r.get('okid_era_period_s'))} | {cell(r['heldout_nrmse_a'])} / {cell(r.get('srim_heldout_nrmse_a'))} "
        f"/ {cell(r.get('okid_era_heldout_nrmse_a'))} | {cell(r['wall_s'], '.0f')} |"
    )


def _damping_cell(zeta: float | None, ci: list | None, why: str | None) -> str:
    """A damping ratio with its interval (%), or why it is not the structure's (``pidyn.assessment``)."""
    if zeta is None:
        return f"not a property ({why})" if why else "not a property"
    return f"{cell(100 * zeta, '.1f')} [{cell(100 * ci[0], '.1f')}, {cell(100 * ci[1], '.1f')}]"


def _profile_cell(row: dict, j: dict) -> str:
    """The period's profile-likelihood set, open ends as "..."; (in) / (**out**) for a weak event."""
    prof = row.get("period_profile_ci95")
    if not prof:
        return "-"
    lo, hi = ("..." if v is None else cell(v) for v in prof)
    mark = "" if "profile_inside_peers" not in j else (" (in)" if j["profile_inside_peers"] else " (**out**)")
    return f"[{lo}, {hi}]{mark}"


def summary_lines(rows: list[dict]) -> list[str]:
    out = []
    for role in ("untouched", "tuning"):
        for direction in ("transverse", "longitudinal"):
            sel = [
                r for r in rows if r["role"] == role and r["direction"] == direction and r["status"] == "ok"
            ]
            if not sel:
                continue
            js = [judge(r) for r in sel]
            inside = [j["inside_peers"] for j in js if j.get("weak_event")]
            own = [j["inside_peers"] for j in js if "inside_peers" in j]
            prof = [
                j["profile_inside_peers"] for j in js if j.get("weak_event") and "profile_inside_peers" in j
            ]
            beats = [j["beats_srim"] for j in js if "beats_srim" in j]
            wall = max(r["wall_s"] or 0 for r in sel)
            out.append(
                f"- {direction}, events {'kept out of all tuning' if role == 'untouched' else 'used in tuning'} "
                f"({len(sel)} with an adequate model): period inside the peers' span on {sum(inside)} of {len(inside)} weak events "
                f"({sum(own)} of {len(own)} counting the direction's own PGA; by the profile interval "
                f"{sum(prof)} of {len(prof)}); "
                f"held-out NRMSE at or below SRIM's on {sum(beats)} of {len(beats)} events where SRIM gives a "
                f"stable model; at most {wall:.0f} s an event."
            )
    rejected = [r for r in rows if r["status"].startswith("ok (")]
    if rejected:
        out.append(
            f"- models the record rejects ({len(rejected)} event-directions: no period or damping reported, "
            "their held-out scores in the tables): "
            + ", ".join(
                f"{r['event']} ({r['direction']})" for r in sorted(rejected, key=lambda r: r["event"])
            )
        )
    failed = sorted({r["event"] for r in rows if r["status"] != "ok" and r not in rejected})
    for e in failed:
        msg = next(r["status"] for r in rows if r["event"] == e and r["status"] != "ok" and r not in rejected)
        out.append(f"- {e}: {msg}")
    return out + [""]


def reduced_choice_lines(rows: list[dict], one: list[dict]) -> list[str]:
    """Three supports against the bent's base alone (transverse, the same output and span)."""
    full = {r["event"]: r for r in rows if r["direction"] == "transverse" and r["status"] == "ok"}
    pairs = [(full[r["event"]], r) for r in one if r["status"] == "ok" and r["event"] in full]
    if not pairs:
        return []
    lines = [
        "## Three supports against one",
        "",
        "The same transverse model with the bent's base (channel 3) as the only ground, against the three "
        "supports of the table above: what the reduced choice costs on the held-out part.",
        "",
        "| event | PGA (g) | held-out NRMSE: 3 supports / 1 | period (s): 3 supports / 1 |",
        "|---|---|---|---|",
    ]
    for f, o in sorted(pairs, key=lambda p: p[0]["pga_g"]):
        lines.append(
            f"| {f['event']} | {cell(f['pga_g'])} | {cell(f['heldout_nrmse_a'])} / {cell(o['heldout_nrmse_a'])} | "
            f"{cell(f['period_s'])} / {cell(o['period_s'])} |"
        )
    gain = [
        o["heldout_nrmse_a"] - f["heldout_nrmse_a"]
        for f, o in pairs
        if f["heldout_nrmse_a"] is not None and o["heldout_nrmse_a"] is not None
    ]
    if gain:
        lines += [
            "",
            f"Median held-out NRMSE with one input minus with three: {np.median(gain):+.3f} over {len(gain)} "
            f"events (three better on {sum(g > 0 for g in gain)}).",
        ]
    skipped = sorted(r["event"] for r in one if r["status"] != "ok")
    if skipped:
        lines.append(f"Not run with one input (channel 3 missing): {', '.join(skipped)}.")
    return lines + [""]


def period_figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    for col, direction in enumerate(("transverse", "longitudinal")):
        sel = [r for r in rows if r["direction"] == direction and r["status"] == "ok"]
        for role, marker in (("untouched", "o"), ("tuning", "s")):
            pts = [r for r in sel if r["role"] == role]
            if not pts:
                continue
            x = np.array([r["pga_g"] for r in pts])
            for row_i, (key, ci_key, scale, label) in enumerate(
                (
                    ("period_s", "period_ci95", 1.0, "period [s]"),
                    ("damping", "damping_ci95", 100.0, "damping [%]"),
                )
            ):
                # a damping that is not the structure's (over 30 %, or an interval over a factor 3) is left out
                y = scale * np.array([np.nan if r[key] is None else r[key] for r in pts], float)
                ci = [r[ci_key] or [None, None] for r in pts]
                lo = scale * np.array([np.nan if c[0] is None else c[0] for c in ci], float)
                hi = scale * np.array([np.nan if c[1] is None else c[1] for c in ci], float)
                ax = axes[row_i, col]
                ax.errorbar(
                    x,
                    y,
                    yerr=[np.nan_to_num(y - lo), np.nan_to_num(hi - y)],
                    fmt=marker,
                    ms=5,
                    capsize=2,
                    label=f"pidyn, events {'kept out of tuning' if role == 'untouched' else 'used in tuning'}",
                )
                if key == "period_s":
                    srim = np.array([r.get("srim_period_s") or np.nan for r in pts], float)
                    tf = np.array([r.get("transfer_function_period_s") or np.nan for r in pts], float)
                    ax.plot(
                        x, srim, "x", color="0.4", ms=5, label="SRIM (mdof)" if role == "untouched" else None
                    )
                    ax.plot(
                        x,
                        tf,
                        "+",
                        color="tab:red",
                        ms=6,
                        label="transfer function" if role == "untouched" else None,
                    )
                ax.set_xscale("log")
                ax.set_ylabel(label)
        axes[0, col].set_title(f"{direction}: period and damping against the event's PGA")
        axes[1, col].set_xlabel("peak ground acceleration at the supports (g)")
        axes[0, col].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def diagnosis_rows(folder: Path) -> list[dict]:
    rows = []
    cat = catalogue()
    for cfg, run in sweep_runs(folder):
        event = cfg["data"]["event"]
        d = load_json(run / "diagnosis.json")
        direction = cfg["data"].get("direction", "transverse")
        failed = load_json(run / "failed.json")
        row = {
            "event": event,
            "direction": direction,
            "role": "tuning" if event in TUNING else "untouched",
            "pga_catalogue_g": float(cat.get(event, {}).get("pga_str_g") or "nan"),
            "run": run,
        }
        if failed or d is None:
            row["status"] = "failed: " + (failed["message"] if failed else "no results")
            rows.append(row)
            continue
        run_info = d.get("running") or {}
        var = run_info.get("variation") or {}
        tested = d.get("confirmation") or []
        best_ho = max(
            (t for t in tested if t.get("heldout_gain") is not None),
            key=lambda t: t["heldout_gain"],
            default=None,
        )
        row.update(
            {
                "status": "ok",
                "verdict": d["verdict"],
                "causes": d["causes"],
                "learned": d["learned_force"],
                "gain": d["gain"],
                "modal": (d.get("modal") or [{}])[0],
                "varies": var.get("varies"),
                "longest": var.get("longest"),
                "shortest": var.get("shortest"),
                "best_candidate_heldout": None
                if best_ho is None
                else (best_ho["effect"], best_ho["heldout_gain"]),
                "wall_s": d.get("wall_seconds"),
                "rivals": [r["effect"] for r in (d.get("rivals") or {}).get("rivals", [])],
            }
        )
        rows.append(row)
    return rows


def diagnosis_table(rows: list[dict], pga: dict[str, float]) -> list[str]:
    """``pga``: each event's peak input acceleration (g) as the identification table reads it."""
    lines = [
        "| event | PGA (g) | verdict | period through the record (95 %) | held-out NRMSE of a: nominal -> "
        "extended | best library effect on the held-out part | s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=lambda r: -(pga.get(r["event"]) or 0)):
        tag = " *(t)*" if r["role"] == "tuning" else ""
        if r["status"] != "ok":
            lines.append(f"| {r['event']}{tag} | {cell(pga.get(r['event']))} | {r['status']} | | | | |")
            continue
        verdict = r["verdict"] + (f" ({', '.join(r['causes'])})" if r["causes"] else "")
        verdict += f", not told from {', '.join(r['rivals'])}" if r.get("rivals") else ""
        verdict += " + learned force" if r["learned"] else ""
        lo, hi = r.get("longest"), r.get("shortest")
        moves = (
            "-"
            if not lo
            else (
                f"{lo['period']:.3f} ({lo['ci95'][0]:.3f}-{lo['ci95'][1]:.3f}) at {lo['t']:.0f} s, "
                f"{hi['period']:.3f} ({hi['ci95'][0]:.3f}-{hi['ci95'][1]:.3f}) at {hi['t']:.0f} s"
                + (": **moves**" if r["varies"] else ": one period")
            )
        )
        g = r["gain"]
        best = r["best_candidate_heldout"]
        lines.append(
            f"| {r['event']}{tag} | {cell(pga.get(r['event']))} | {verdict} | {moves} | {cell(g.get('nominal'))} -> "
            f"{cell(g.get('extended'))} | {'-' if not best else f'{best[0]} ({best[1]:+.2f})'} | "
            f"{cell(r['wall_s'], '.0f')} |"
        )
    return lines + [""]


def _transverse_pga(rows: list[dict]) -> dict[str, float]:
    """Each identified event's transverse peak input (g): the diagnosis tables' PGA column."""
    return {
        r["event"]: r["pga_g"]
        for r in rows
        if r["direction"] == "transverse" and r["status"].startswith("ok")
    }


def aggregate(base: Path) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "figures").mkdir(exist_ok=True)
    rows = identification_rows(base / "identify")
    if not rows:
        raise SystemExit(f"{base / 'identify'}: no run folders to aggregate (the sweep did not run?)")
    write_csv(rows, RESULTS / "painter_street.csv")
    if rows:
        period_figure(rows, RESULTS / "figures" / "period_vs_pga.png")
    lines = [
        "# Painter Street Overpass (CSMIP CE89324): every shipped event",
        "",
        f"Produced by `python experiments/real.py` (`make real`) on {platform.machine()}, two jobs at a time, "
        f"{time.strftime('%Y-%m-%d')}. Model: one degree of freedom on three supports (transverse: inputs 3, 17, "
        "20 -> output 7; longitudinal: 15, 1, 18 -> 11), each support with its influence, its dashpot and what the "
        "sensor reads of it directly; identified by PIDynNet and the refinement on the first 65 % of the shaking "
        "(from a start read from the record, or from a peer's order-2 model mapped onto it when that "
        "simulates the fitting part better), the last 35 % held out. Peers on the same channels and span: "
        "the transfer function's fundamental (H1 from the mean input, with its interval), mdof's SRIM and "
        "OKID-ERA (the order with the lowest fitting-part error among those that do not diverge from rest).",
        "",
        "Events marked *(t)* were looked at while the methods were set up; the others were kept out of all "
        "tuning. (in) / (**out**): the period's interval inside the peers' span (weak events: PGA below 0.1 g; "
        "a direction whose own PGA is below it in an event whose other direction's is not is marked with the "
        "event's PGA and counted apart in the summary).",
        "",
        "## Summary",
        "",
        *summary_lines(rows),
        "## Identification",
        "",
        *identification_table(rows, "transverse"),
        *identification_table(rows, "longitudinal"),
        "![period against PGA](figures/period_vs_pga.png)",
        "",
    ]
    lines += srim_better_lines(rows, base / "identify")
    one = identification_rows(base / "one_input") if (base / "one_input").exists() else []
    lines += reduced_choice_lines(rows, one) or kept_section(
        "## Three supports against one", "## Two modes against one", "one_input"
    )
    two = identification_rows(base / "two_modes") if (base / "two_modes").exists() else []
    lines += two_modes_lines(rows, two, judge) or kept_section(
        "## Two modes against one", "## Diagnosis of the strong events", "two_modes"
    )
    pga = _transverse_pga(rows)
    diag = diagnosis_rows(base / "diagnose") if (base / "diagnose").exists() else []
    lines += _diagnosis_lines(diag, pga)
    lines += final_lines(rows, diag, lambda r: " *(t)*" if r["role"] == "tuning" else "")
    lines += [
        "## Buildings on a shake table, measured by wearable IMUs",
        "",
        "`python experiments/shake_table.py` (the second half of `make real`): [shake_table.md](shake_table.md).",
        "",
    ]
    (RESULTS / "README.md").write_text("\n".join(lines))
    print(f"wrote {RESULTS / 'README.md'}")


def kept_section(start: str, end: str, folder: str) -> list[str]:
    """The committed README's section from the line ``start`` up to ``end``, said to be kept, for a
    study without that sweep's ``folder`` (a sweep not run again keeps its published table rather
    than dropping it); empty where the README has no such section."""
    path = RESULTS / "README.md"
    readme = path.read_text().split("\n") if path.exists() else []
    heads = [i for i, line in enumerate(readme) if line.startswith(start)]
    if not heads:
        return []
    i = heads[0]
    j = next((k for k in range(i + 1, len(readme)) if readme[k].startswith(end)), len(readme))
    body = [line for line in readme[i + 1 : j] if not line.startswith("*Kept from an earlier study")]
    note = (
        f"*Kept from an earlier study: this one has no `{folder}` sweep. Its columns for the single "
        "model are that study's, not the identification table's above.*"
    )
    return [readme[i], "", note, *body]


def srim_better_lines(rows: list[dict], folder: Path) -> list[str]:
    """Where SRIM predicts the held-out part better: the same model fitted by output error to the
    held-out part itself (from the identified values), against the fitting part's. A held-out part
    whose own period and damping differ from the fitting part's says the structure changed between
    the two (the amplitude falls in the coda), which no single linear model of the fitting part
    follows; SRIM's chosen order says where a second mode enters."""
    worse = {(r["event"], r["direction"]) for r in rows if judge(r).get("beats_srim") is False}
    if not worse:
        return []
    out = [
        "## Where SRIM predicts the held-out part better",
        "",
        "The same model fitted by output error to the held-out part itself, from the identified values: its "
        "own period and damping, and the NRMSE it reaches there, simulated from rest at the part's start "
        "(about the best this model class does on that part).",
        "",
        "| event | direction | T, ζ fitted part | T, ζ held-out part's own | held-out NRMSE: ours / SRIM / "
        "own fit | SRIM's order |",
        "|---|---|---|---|---|---|",
    ]
    by_key = {(r["event"], r["direction"]): r for r in rows}
    for cfg, run in sweep_runs(folder):
        d = cfg["data"]
        key = (d["event"], d["direction"])
        if key not in worse:
            continue
        ident, own, own_nrmse = _held_out_own_fit(cfg, load_json(run / "metrics.json") or {})
        r = by_key[key]

        def tz(p: dict) -> str:
            return f"{2 * np.pi / np.sqrt(p['k']):.3f} s, {100 * p['c'] / (2 * np.sqrt(p['k'])):.1f} %"

        out.append(
            f"| {d['event']} | {d['direction']} | {tz(ident)} | {tz(own)} | {cell(r['heldout_nrmse_a'])} / "
            f"{cell(r.get('srim_heldout_nrmse_a'))} / {cell(own_nrmse)} | {r.get('srim_order')} |"
        )
    return out + [""]


def _held_out_own_fit(cfg: dict, metrics: dict) -> tuple[dict, dict, float]:
    """The identified values, the same model fitted by output error to the held-out part itself
    (from them), and its NRMSE there simulated from rest at the part's start. The record and the
    model are the run's own, built from its saved config as the train task builds them."""
    import hydra
    from omegaconf import OmegaConf

    from pidyn.refine.output_error import fit_output_error
    from pidyn.reporting import nrmse
    from pidyn.runs.build import build_record
    from pidyn.simulate import simulate_response

    node = OmegaConf.create(cfg)
    node.data.records = str(RECORDS / "records")  # the run's relative path, from wherever this runs
    rec = build_record(node, hydra.utils.instantiate(node.system))
    system = hydra.utils.instantiate(node.system, inputs=rec.inputs)
    ident = {
        **{s.name: s.init for s in system.param_specs()},
        **{k: float(v) for k, v in metrics["params"].items()},
    }
    held = rec.segment(rec.meta.split.fit[1], float(rec.t[-1]))
    own = {**ident, **fit_output_error(held, system, init=ident, max_nfev=100).params}
    own_nrmse = nrmse(simulate_response(system, own, held)["a"][:, 0], held.a[:, 0])
    return ident, own, own_nrmse


def _diagnosis_lines(rows: list[dict], pga: dict[str, float]) -> list[str]:
    """The strong events' diagnosis table and their running-period figures (copied beside it)."""
    diag = [r for r in rows if r["event"] in DIAGNOSED and r["direction"] == "transverse"]
    if not diag:
        return []
    lines: list[str] = []
    lines += [
        "## Diagnosis of the strong events (transverse)",
        "",
        "`python diagnose.py experiment=painter_street_diagnose`: the accelerations decide (output error "
        "of every library effect), the period and damping are fitted window by window; a period that moves "
        "beyond its windows' intervals refutes one linear model. There the amplitude-dependent structure "
        "(`amplitude_softening`: a stiffness and a damping that follow a latent envelope of the response, "
        "with its time constant) is one more candidate of the check, named like the library's effects when "
        "it passes it and earns its place on the held-out part; the figures draw its own period along its "
        "simulated response in red. Where nothing is named the verdict is `unexplained`, a learned force "
        "tried and kept only when it predicts the held-out part better.",
        "",
        *diagnosis_table(diag, pga),
    ]
    for r in diag:
        fig = Path(r["run"]) / "figures" / "running_period.png"
        if fig.exists():
            shutil.copy(fig, RESULTS / "figures" / f"running_period_{r['event']}.png")
            lines.append(f"![{r['event']}](figures/running_period_{r['event']}.png)")
    lines.append("")
    return lines + _amplitude_figures(rows, diag)


def _amplitude_figures(rows: list[dict], shown: list[dict]) -> list[str]:
    """The running period of every other event-direction where the amplitude-dependent structure
    was named: its own period beside the windows' (red)."""
    named = [
        r
        for r in rows
        if r["status"] == "ok" and "amplitude_softening" in (r.get("causes") or []) and r not in shown
    ]
    if not named:
        return []
    lines = ["The other event-directions where the amplitude-dependent structure is named:", ""]
    for r in named:
        fig = Path(r["run"]) / "figures" / "running_period.png"
        if fig.exists():
            name = f"running_period_{r['event']}_{r['direction']}.png"
            shutil.copy(fig, RESULTS / "figures" / name)
            lines.append(f"![{r['event']} {r['direction']}](figures/{name})")
    return lines + [""]


def write_csv(rows: list[dict], path: Path) -> None:
    """One row per event and direction; lists and dicts as JSON."""
    with path.open("w", newline="") as fh:
        keys = sorted({k for r in rows for k in r} - {"run"})  # the run folder is this machine's
        w = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: json.dumps(v) if isinstance(v, (list, dict)) else v for k, v in r.items()})


def read_csv(path: Path) -> list[dict]:
    """``write_csv``'s rows back: JSON where a cell parses as JSON, text otherwise, None for empty."""

    def cell(v: str):
        if v == "":
            return None
        try:
            return json.loads(v)
        except json.JSONDecodeError:
            return v

    with path.open(newline="") as fh:
        return [{k: cell(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def aggregate_diagnosis(folder: Path) -> None:
    """The diagnosis' sections of the README again from a new diagnosis sweep, beside the committed
    identification (``painter_street.csv``): what it writes between the strong events' diagnosis
    and the shake-table section is replaced, the rest kept."""
    rows = read_csv(RESULTS / "painter_street.csv")
    diag = diagnosis_rows(folder)
    if not diag:
        raise SystemExit(f"{folder}: no diagnosis run folders to aggregate")
    pga = _transverse_pga(rows)
    new = _diagnosis_lines(diag, pga) + final_lines(
        rows, diag, lambda r: " *(t)*" if r["role"] == "tuning" else ""
    )
    readme = (RESULTS / "README.md").read_text().split("\n")
    start = next(i for i, line in enumerate(readme) if line.startswith("## Diagnosis of the strong events"))
    end = next(i for i, line in enumerate(readme) if line.startswith("## Buildings on a shake table"))
    (RESULTS / "README.md").write_text("\n".join(readme[:start] + new + readme[end:]))
    print(f"wrote the diagnosis' sections of {RESULTS / 'README.md'} from {folder}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--aggregate", type=Path, help="only aggregate this study folder (outputs/real/<stamp>)")
    ap.add_argument("--events", nargs="*", help="a subset of the shipped events (archive names)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--launcher", default="joblib", help="joblib, or submitit_slurm_cpu on a cluster")
    ap.add_argument("--skip-diagnosis", action="store_true")
    ap.add_argument(
        "--two-modes",
        action="store_true",
        help="also every event with two modes (about 45 min more on 2 cores)",
    )
    ap.add_argument("--resume", type=Path, help="an interrupted study's folder: its finished runs are kept")
    ap.add_argument(
        "--diagnosis",
        type=Path,
        help="only the diagnosis' sections again, from this diagnosis sweep and the committed identification",
    )
    a = ap.parse_args()
    if a.diagnosis:
        aggregate_diagnosis(a.diagnosis)
        return
    if a.aggregate:
        aggregate(a.aggregate)
        return
    chosen = a.events or events()
    unknown = sorted(set(chosen) - set(events()))
    if unknown:
        raise SystemExit(f"unknown event(s) {unknown}; shipped: {', '.join(events())}")
    base = a.resume or ROOT / "outputs" / "real" / time.strftime("%Y-%m-%d_%H-%M-%S")
    run_sweeps(base, chosen, a.jobs, a.launcher, not a.skip_diagnosis, a.two_modes)
    aggregate(base)


if __name__ == "__main__":
    main()
