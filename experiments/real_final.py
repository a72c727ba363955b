"""The Painter Street study's final models: every event and direction diagnosed, and what the
diagnosis ends with (its nominal model, or the extension it keeps) against the identification and
mdof's SRIM on the same held-out part.

The diagnosis keeps an extension only when it predicts the held-out part better than its nominal
model, so its final error has looked at that part once (a choice between two models); the nominal
model's error has not. Both are reported."""

from __future__ import annotations

from collections.abc import Callable

from pidyn.bench.tables import cell


def final_error(diag: dict) -> float | None:
    """The held-out NRMSE of the model the diagnosis ends with."""
    g = diag.get("gain") or {}
    kept = diag.get("verdict") != "none" and g.get("extended") is not None
    return g.get("extended") if kept else g.get("nominal")


def final_rows(ident: list[dict], diag: list[dict]) -> list[dict]:
    """One row per event and direction that both sweeps finished."""
    # a model the record rejects is identified too: its diagnosis says what it misses
    by_key = {(r["event"], r["direction"]): r for r in ident if r["status"].startswith("ok")}
    out = []
    for d in diag:
        r = by_key.get((d["event"], d.get("direction")))
        if r is None or d["status"] != "ok":
            continue
        out.append(
            {
                "event": d["event"],
                "direction": d["direction"],
                "role": d["role"],
                "pga_g": r.get("pga_g"),
                "identified": r.get("heldout_nrmse_a"),
                "nominal": (d.get("gain") or {}).get("nominal"),
                "final": final_error(d),
                "srim": r.get("srim_heldout_nrmse_a"),
                "verdict": d["verdict"]
                + (f" ({', '.join(d['causes'])})" if d.get("causes") else "")
                + (" + learned force" if d.get("learned") else ""),
                "wall_s": d.get("wall_s"),
            }
        )
    return out


def _at_most(a: float | None, b: float | None) -> bool | None:
    return None if a is None or b is None else bool(a <= b)


def final_lines(ident: list[dict], diag: list[dict], tag: Callable[[dict], str]) -> list[str]:
    """The section: per event and direction, the held-out NRMSE of the identification, the
    diagnosis' nominal and final models and SRIM; a summary per direction and role."""
    rows = final_rows(ident, diag)
    if not rows:
        return []
    n_ident = sum(r["status"].startswith("ok") for r in ident)
    lines = [
        "## The final model on every event",
        "",
        f"{len(rows)} of the {n_ident} identified events and directions have a finished diagnosis in this study "
        "(`python diagnose.py experiment=painter_street_diagnose data=csmip`, the sweep over all events and both "
        "directions; an interrupted sweep resumes with `--resume`). The diagnosis fits its nominal "
        "model by output error to the fitting part's accelerations from the data's start and from a peer's "
        "(SRIM's or OKID-ERA's order-2 model mapped onto it, the one that simulates that part better) and "
        "keeps the lower fitted cost, then refits it by PIDynNet and output error, and ends with it or with "
        "the extension it keeps. It keeps an extension only when that predicts the held-out part "
        "better, so the final column has looked at the held-out part once; the nominal column has not. "
        "SRIM: mdof's, on the same channels and span (from the identification table).",
        "",
        "| event | direction | PGA (g) | verdict | held-out NRMSE: identification / diagnosis nominal / final / "
        "SRIM | final <= SRIM | s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=lambda r: (r["direction"], r.get("pga_g") or 0)):
        beats = _at_most(r["final"], r["srim"])
        lines.append(
            f"| {r['event']}{tag(r)} | {r['direction']} | {cell(r['pga_g'])} | {r['verdict']} | "
            f"{cell(r['identified'])} / {cell(r['nominal'])} / {cell(r['final'])} / {cell(r['srim'])} | "
            f"{'-' if beats is None else ('yes' if beats else '**no**')} | {cell(r['wall_s'], '.0f')} |"
        )
    lines.append("")
    for direction in ("transverse", "longitudinal"):
        for role, label in (("untouched", "kept out of all tuning"), ("tuning", "used in tuning")):
            part = [
                r for r in rows if r["direction"] == direction and r["role"] == role and r["srim"] is not None
            ]
            if not part:
                continue
            n_final = sum(bool(_at_most(r["final"], r["srim"])) for r in part)
            n_nom = sum(bool(_at_most(r["nominal"], r["srim"])) for r in part)
            n_id = sum(bool(_at_most(r["identified"], r["srim"])) for r in part)
            lines.append(
                f"- {direction}, events {label} ({len(part)} with a stable SRIM model): at or below SRIM's "
                f"held-out NRMSE, the final model on {n_final}, the diagnosis' nominal model on {n_nom}, "
                f"the identification on {n_id}."
            )
    slow = max((r["wall_s"] or 0) for r in rows)
    lines += [f"- At most {slow:.0f} s a diagnosis.", ""]
    return lines
