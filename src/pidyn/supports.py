"""What the records say of each support of a bridge model (``RigidDeck``): its stiffness and
damping with their intervals, and, where the data cannot tell two supports apart, that in words
with the correlation that shows it, instead of numbers the data do not determine."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from pidyn.notes import note

log = logging.getLogger(__name__)

#: stiffnesses of two supports this correlated are one combination to the data, not two numbers
CORRELATED = 0.9
#: an interval wider than this factor (upper over lower) does not determine the value
SPAN = 3.0


def support_table(system: Any, final: dict[str, float], refined: Any) -> tuple[list[dict], list[str]]:
    """One row per support (input, position, k, c and their intervals, whether the data determine
    them) and the notes on the supports the data do not tell apart."""
    intervals = dict(getattr(refined, "intervals", None) or {})
    names = list(getattr(refined, "names", None) or [])
    corr = np.asarray(getattr(refined, "correlation", None) or np.eye(len(names)), float)
    rows, notes = [], []
    for j, (inp, pos, support) in enumerate(zip(system.inputs, system.positions, system.supports), start=1):
        k_name = next((t.initial_stiffness_param for t in support if t.initial_stiffness_param), None)
        c_name = next((t.damping_param for t in support if t.damping_param), None)
        row = {"support": j, "input": inp, "position_m": pos}
        for key, name in (("k", k_name), ("c", c_name)):
            ci = intervals.get(name) if name else None
            ci = ci.get("ci95") if isinstance(ci, dict) else ci  # the refinement's {value, std, ci95}
            row[key] = None if name is None else float(final[name])
            row[f"{key}_ci95"] = ci
            row[f"{key}_determined"] = _determined(ci)
        rows.append(row)
    k_names = [
        next((t.initial_stiffness_param for t in s if t.initial_stiffness_param), None)
        for s in system.supports
    ]
    for a in range(len(k_names)):
        for b in range(a + 1, len(k_names)):
            if k_names[a] in names and k_names[b] in names:
                r = float(corr[names.index(k_names[a]), names.index(k_names[b])])
                if abs(r) >= CORRELATED:
                    notes.append(
                        note(
                            "supports_not_distinguished",
                            f"the records do not tell support {a + 1} ({system.inputs[a]}) from support {b + 1} "
                            f"({system.inputs[b]}): their stiffnesses' estimates correlate {r:+.2f}, so only a "
                            "combination of the two is determined, not each",
                        )
                    )
    for row in rows:
        if row["k"] is not None and not row["k_determined"]:
            rows_ci = row["k_ci95"]
            notes.append(
                note(
                    "support_undetermined",
                    f"support {row['support']} ({row['input']}): its stiffness's 95 % interval "
                    f"{_text(rows_ci)} does not determine it (wider than a factor {SPAN:g}); not reported as its value",
                )
            )
    return rows, notes


def _determined(ci: Any) -> bool:
    if not ci or ci[0] is None or ci[1] is None:
        return False
    lo, hi = float(ci[0]), float(ci[1])
    return lo > 0 and np.isfinite(hi) and hi / lo <= SPAN


def _text(ci: Any) -> str:
    return "unknown" if not ci or ci[0] is None else f"[{float(ci[0]):.4g}, {float(ci[1]):.4g}]"


def support_lines(rows: list[dict]) -> list[str]:
    """The supports as a markdown table: a value the data do not determine is not printed."""
    out = [
        "| support | input | at (m) | k (s^-2) | k 95 % | c (s^-1) | c 95 % |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        k = f"{r['k']:.4g}" if r["k_determined"] else "not determined"
        c = f"{r['c']:.4g}" if r["c_determined"] else "not determined"
        out.append(
            f"| {r['support']} | {r['input']} | {r['position_m']:.4g} | {k} | {_text(r['k_ci95'])} | {c} | "
            f"{_text(r['c_ci95'])} |"
        )
    return out
