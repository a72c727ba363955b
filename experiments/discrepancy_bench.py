"""Hit rate of the diagnosis over a seeded sweep of hidden effects (``make discrepancy-bench``).

Case i hides kind ``KINDS[i % len(KINDS)]`` in a linear structure under a record, magnitude
and noise level (uniform in 0-5 %) drawn from seed 1000 + i, and runs the full diagnosis
(``diagnose.py``) in its own process. The kinds: nothing; each library effect; a softening
cubic and a negative k2 (signed effects); a stiffness loss and a damping change after the
split (changes in time the fitting part does not see); pairs of effects; effects outside the
library (a trilinear spring, Stribeck friction). Finished cases are skipped on a rerun
(resumable), and the committed table's finished cases (stamped with their code commit) are
kept, so a study grows over several sessions; the table is rewritten after every case.
Writes ``experiments/results/discrepancy_bench.{md,csv,json}``: per kind the hit rate, the
false ``discrepancy`` rate on clean data, the held-out gain, parameter errors and seconds per
diagnosis.

    python experiments/discrepancy_bench.py --cases 180 --jobs 2
    python experiments/discrepancy_bench.py --cases 18 --kinds pair:gap_contact+coulomb_friction
    python experiments/discrepancy_bench.py --full --cases 6 --name diagnosis_time_40s \
        --kinds none hysteresis ... data.source.duration=40 data.source.fit_end=26
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

from pidyn.cores import share_cores  # noqa: E402
from pidyn.discrepancy.effects import EFFECTS, LIBRARY  # noqa: E402
from pidyn.discrepancy.hidden import EQUIVALENT  # noqa: E402
from pidyn.errors import error_pct  # noqa: E402
from pidyn.runs import provenance  # noqa: E402

NAMES = ["none", *sorted(LIBRARY)]
#: the benchmark's PIDynNet schedule, stated in every row's table; diagnose's default since db7a6c1
FAST = [
    "model.schedule.pretrain_iters=300",
    "model.schedule.pretrain_iters_window=300",
    "model.schedule.max_iters=500",
]


@dataclass
class Kind:
    """One kind of case: what is hidden (the data source's overrides) and what counts as found."""

    label: str
    effect: str  # data.source.effect
    expect: set[str] = field(default_factory=set)  # the causes to name (empty: none)
    overrides: list[str] = field(default_factory=list)
    outside: bool = False  # 'unexplained' or an equivalent name counts
    change_after_split: bool = False

    def args(self, i: int) -> list[str]:
        out = [f"data.source.effect={self.effect}", *self.overrides]
        if self.change_after_split:  # after the split at 16 s, before 22 s, drawn by the case
            t_d = 17.0 + 5.0 * ((i * 0.6180339887) % 1.0)
            out.append(f"+data.source.params={{t_d: {t_d:.3f}}}")
        return out

    def score(self, d: dict) -> bool:
        causes = set(d.get("causes") or ([d["cause"]] if d.get("cause") else []))
        if self.outside:
            return (
                d["verdict"] in ("unexplained", "discrepancy")
                and causes <= EQUIVALENT[self.effect]
                and d["verdict"] != "none"
            )
        if not self.expect:
            return d["verdict"] == "none"
        return causes == self.expect


KINDS = (
    [Kind("none", "none")]
    + [Kind(n, n, {n}) for n in sorted(LIBRARY)]
    + [
        Kind("softening_cubic", "cubic_stiffness", {"cubic_stiffness"}, ["data.source.sign=-1"]),
        Kind("negative_k2", "quadratic_stiffness", {"quadratic_stiffness"}, ["data.source.sign=-1"]),
        Kind("stiffness_loss_after_split", "stiffness_loss", {"stiffness_loss"}, change_after_split=True),
        Kind("damping_change_after_split", "damping_change", {"damping_change"}, change_after_split=True),
    ]
    + [
        Kind(f"pair:{a}+{b}", f"{a}+{b}", {a, b})
        for a, b in (
            ("quadratic_stiffness", "quadratic_damping"),
            ("gap_contact", "coulomb_friction"),
            ("cubic_stiffness", "coulomb_friction"),
        )
    ]
    + [Kind(f"outside:{n}", n, set(), outside=True) for n in EQUIVALENT]
)
BY_LABEL = {k.label: k for k in KINDS}


def run_case(i: int, out: Path, extra: list[str], kinds: list[Kind]) -> dict:
    kind = kinds[i % len(kinds)]
    folder = out / f"case_{i:03d}_{kind.label.replace(':', '_').replace('+', '_')}"
    result = folder / "diagnosis.json"
    if not result.exists():
        cmd = [
            sys.executable,
            str(ROOT / "diagnose.py"),
            *kind.args(i),
            f"data_seed={1000 + i}",
            "noise=null",
            "logger=none",
            "trainer.enable_progress_bar=false",
            "num_threads=1",
            f"hydra.run.dir={folder}",
            *extra,
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
        if proc.returncode != 0 or not result.exists():
            return {"case": i, "hidden": kind.label, "error": (proc.stderr or proc.stdout)[-800:]}
    d = json.loads(result.read_text())
    hidden = d["hidden"] or {}
    causes = d.get("causes") or ([d["cause"]] if d.get("cause") else [])
    row = {
        "case": i,
        "hidden": kind.label,
        "found": "+".join(causes) or d["verdict"],
        "verdict": d["verdict"],
        "hit": kind.score(d),
        "record": d["record"],
        "noise": d.get("noise"),
        "seconds": d["wall_seconds"],
        "nrmse_nominal": d["gain"]["nominal"],
        "nrmse_extended": d["gain"]["extended"],
        "top_score": d["ranking"][0]["score"],
    }
    if len(kind.expect) == 1 and kind.score(d):
        (effect,) = kind.expect
        key = EFFECTS[effect].key
        truth = (hidden.get("parameters") or {}).get(key)
        est = d["parameters"].get(key)
        if truth and est is not None:
            row["param"] = key
            row["param_error_pct"] = error_pct(est, truth)
    if kind.change_after_split and d.get("change"):
        t_true = (hidden.get("parameters") or {}).get("t_d")
        lo, hi = d["change"]["t_change_ci95"]
        row["t_change_covered"] = bool(t_true is not None and lo <= t_true <= hi)
    return row


def summarise(df: pd.DataFrame) -> dict:
    ok = df[df.get("error").isna()] if "error" in df else df
    eff = ok[ok.hidden != "none"]
    clean = ok[ok.hidden == "none"]
    ratio = (eff.nrmse_extended / eff.nrmse_nominal).dropna()
    return {
        "cases": int(len(df)),
        "failed_runs": int(len(df) - len(ok)),
        "hit_rate": float(ok.hit.mean()),
        "hit_rate_effects": float(eff.hit.mean()) if len(eff) else None,
        "missed_effects_rate": float((eff.verdict == "none").mean()) if len(eff) else None,
        "false_discrepancy_rate": float((clean.verdict != "none").mean()) if len(clean) else None,
        "median_heldout_nrmse_ratio_extended_over_nominal": float(ratio.median()) if len(ratio) else None,
        "median_param_error_pct": float(ok["param_error_pct"].median()) if "param_error_pct" in ok else None,
        "median_seconds_per_diagnosis": float(ok.seconds.median()),
        "max_seconds_per_diagnosis": float(ok.seconds.max()),
    }


def code_commit() -> str:
    """The checkout's commit (with ``+dirty`` for uncommitted changes), stamped on every row."""
    return provenance.code_commit(ROOT)


def committed_rows(path: Path, kinds: list[Kind]) -> dict[int, dict]:
    """Finished cases of the committed table that still describe case i (same hidden kind, a
    code commit stamped, no error): a study grows over several sessions without re-running them."""
    if not path.exists():
        return {}
    df = pd.read_csv(path, dtype={"commit": str})  # a short hash like 61e7462 is no number
    if "commit" not in df:
        return {}
    out = {}
    for r in df.to_dict("records"):
        i = int(r["case"])
        if isinstance(r.get("error"), str) or r["hidden"] != kinds[i % len(kinds)].label:
            continue
        out[i] = {k: v for k, v in r.items() if not (isinstance(v, float) and np.isnan(v))}
    return out


def write_results(
    rows: list[dict],
    planned: int,
    schedule: str,
    results: Path,
    stem: str = "discrepancy_bench",
    command: str | None = None,
    split: tuple[float, float] = (16.0, 25.0),
) -> list[str]:
    """The table over the cases finished so far (rewritten after every case, so an interrupted
    study loses nothing and says how far it got)."""
    df = pd.DataFrame(rows).sort_values("case")
    summary = summarise(df)
    summary["cases_planned"] = planned
    summary["schedule"] = schedule
    summary["total_case_seconds"] = (
        float(df["seconds"].sum()) if "seconds" in df else None
    )  # 2 cases at a time
    summary["code_commits"] = (
        " ".join(sorted(set(df["commit"].dropna().astype(str)))) if "commit" in df else ""
    )
    per = per_kind(df)
    results.mkdir(parents=True, exist_ok=True)
    df.to_csv(results / f"{stem}.csv", index=False)
    (results / f"{stem}.json").write_text(
        json.dumps(
            {"summary": summary, "per_effect": per.reset_index().to_dict("records")}, indent=2, default=float
        )
    )
    lines = _markdown(df, per, summary, planned, command, split)
    (results / f"{stem}.md").write_text("\n".join(lines) + "\n")
    return lines


def per_kind(df: pd.DataFrame) -> pd.DataFrame:
    """Per hidden kind: cases, top-1 hit rate, median parameter error, held-out NRMSE ratio, time."""
    rows_per = []
    for name, g in df.groupby("hidden", sort=False):
        errs = g["param_error_pct"] if "param_error_pct" in g else pd.Series(dtype=float)
        rows_per.append(
            {
                "hidden": name,
                "cases": len(g),
                "top1": float(g.hit.fillna(False).astype(bool).mean()),
                "median_param_error_pct": float(errs.median()) if errs.notna().any() else np.nan,
                "median_nrmse_ratio": float((g.nrmse_extended / g.nrmse_nominal).median())
                if name != "none"
                else np.nan,
                "max_seconds": float(g.seconds.max()) if "seconds" in g else np.nan,
            }
        )
    per = pd.DataFrame(rows_per)
    order = {k.label: n for n, k in enumerate(KINDS)}
    per = per.sort_values("hidden", key=lambda c: c.map(lambda v: order.get(v, len(order)))).set_index(
        "hidden"
    )
    return per


def _markdown(
    df: pd.DataFrame, per: pd.DataFrame, summary: dict, planned: int, command: str | None, split: tuple
) -> list[str]:
    """The table's markdown: what was run, the summary, per kind, the misses."""
    done = (
        "" if len(df) >= planned else f" ({len(df)} of the {planned} planned cases finished; the rest resume)"
    )
    lines = [
        "# Diagnosis benchmark: hidden effects",
        "",
        f"{summary['cases']} seeded cases{done} (linear SDOF m=1, c=0.5, k=15; nothing, one library effect "
        "(either sign where the sign is a finding), a change after the split, a pair, or an effect outside the "
        "library hidden; a change before the split drawn where the structure moves, after 20-70 % (stiffness) or "
        "20-60 % (damping) of the stepping signal's energy in the fitting part; "
        "shipped records scaled to PGA 3 m/s^2; noise uniform 0-5 %; "
        f"fit 0-{split[0]:g} s, held out {split[0]:g}-{split[1]:g} s). PIDynNet schedule: {summary['schedule']}.",
        "",
        f"Command: `{command or f'python experiments/discrepancy_bench.py --cases {planned} --jobs 2'}`"
        f"{'' if command else ' (`make discrepancy-bench`)'}; "
        f"code {summary['code_commits'] or 'unknown'}.",
        "",
        "| metric | value |",
        "|---|---|",
    ]
    lines += [f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in summary.items()]
    lines += [
        "",
        "Hit: the hidden effect(s) named and nothing else; `none` on clean data; for effects outside the "
        "library `unexplained` or a physically equivalent name ("
        + ", ".join(f"{k}: {sorted(v)}" for k, v in EQUIVALENT.items())
        + ").",
        "",
        "| hidden | cases | hit rate | median parameter error % | median NRMSE ratio ext/nom | max seconds |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in per.iterrows():
        lines.append(
            f"| {name} | {int(r.cases)} | {r.top1:.2f} | {r.median_param_error_pct:.3g} | "
            f"{r.median_nrmse_ratio:.3g} | {r.max_seconds:.0f} |"
        )
    misses = df[~df.hit.fillna(False).astype(bool)] if "hit" in df else df
    if len(misses):
        lines += [
            "",
            "Misses: " + "; ".join(f"case {r.case} {r.hidden} -> {r.found}" for r in misses.itertuples()),
        ]
    return lines


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=180)  # 10 of each of the 18 kinds
    ap.add_argument(
        "--first",
        type=int,
        default=0,
        help="first case (with --name: a study of cases FIRST..CASES-1, seeds the benchmark does not use)",
    )
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "outputs" / "discrepancy_bench")
    ap.add_argument(
        "--full",
        action="store_true",
        help="no schedule overrides: diagnose's default (the same as FAST since db7a6c1)",
    )
    ap.add_argument("--results", type=Path, default=ROOT / "experiments" / "results")
    ap.add_argument("--kinds", nargs="*", default=None, help=f"a subset of the kinds: {', '.join(BY_LABEL)}")
    ap.add_argument("--rerun", action="store_true", help="ignore the committed table's finished cases")
    ap.add_argument(
        "--name",
        default=None,
        help="write the table as experiments/results/NAME.{md,csv,json} (a study of its own, e.g. the "
        "default schedule on 40 s records; with --kinds too)",
    )
    return ap


def _checked_args(ap: argparse.ArgumentParser) -> tuple[argparse.Namespace, list[str]]:
    """The options, checked, and the config overrides given after them (``key=value``)."""
    args, extra = ap.parse_known_args()
    if args.kinds:  # key=value after --kinds are config overrides, not kinds
        extra += [k for k in args.kinds if "=" in k]
        args.kinds = [k for k in args.kinds if "=" not in k] or None
    unknown = set(args.kinds or []) - set(BY_LABEL)
    if unknown:
        ap.error(f"unknown kind(s) {sorted(unknown)}; choose from {', '.join(BY_LABEL)}")
    if args.first and not args.name:
        ap.error(
            "--first needs --name: cases from FIRST on are a study of their own, not the benchmark's table"
        )
    if not 0 <= args.first < args.cases:
        ap.error(f"--first {args.first} must lie in 0..{args.cases - 1} (--cases {args.cases})")
    return args, extra


def main() -> None:
    ap = _parser()
    args, extra = _checked_args(ap)
    kinds = [BY_LABEL[k] for k in args.kinds] if args.kinds else KINDS
    schedule = "default" if args.full else "short: " + " ".join(FAST)
    given = dict(e.split("=", 1) for e in extra if "=" in e)  # the record's split, as the table states it
    split = (float(given.get("data.source.fit_end", 16.0)), float(given.get("data.source.duration", 25.0)))
    extra = ([] if args.full else FAST) + extra
    args.out.mkdir(parents=True, exist_ok=True)
    name = args.name or "discrepancy_bench"
    # a subset run writes the benchmark's own table nowhere; a named study writes its own
    where = args.results if (args.name or not args.kinds) else args.out / "subset"
    command = (
        None
        if name == "discrepancy_bench" and not args.kinds
        else "python " + " ".join(["experiments/discrepancy_bench.py", *sys.argv[1:]])
    )
    kept = (
        {} if args.rerun or (args.kinds and not args.name) else committed_rows(where / f"{name}.csv", kinds)
    )
    kept = {i: r for i, r in kept.items() if args.first <= i < args.cases}
    rows = list(kept.values())
    todo = [i for i in range(args.first, args.cases) if i not in kept]
    if kept:
        print(f"{len(kept)} case(s) kept from the committed table; {len(todo)} to run", flush=True)
    commit = code_commit()
    lines: list[str] = []
    share_cores(args.jobs)
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futs = {pool.submit(run_case, i, args.out, extra, kinds): i for i in todo}
        for n, fut in enumerate(as_completed(futs), 1):
            r = {**fut.result(), "commit": commit}
            rows.append(r)
            status = r.get("error") and "FAILED" or f"found {r['found']} ({r['seconds']:.0f} s)"
            print(f"[{n}/{len(todo)}] case {r['case']} hidden {r['hidden']}: {status}", flush=True)
            lines = write_results(rows, args.cases - args.first, schedule, where, name, command, split)
    if rows and not lines:
        lines = write_results(rows, args.cases - args.first, schedule, where, name, command, split)
    print(f"table: {where / (name + '.md')}")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
