"""The Painter Street study's second sweep: the same events with two modes on the supports
(``system=modes``), each started where its single mode ended (and from SRIM's order-4 model);
whether the second mode is kept is decided on the fitting part alone (``pidyn.model_choice``)."""

from __future__ import annotations

from pathlib import Path

from pidyn.bench.tables import cell, load_json
from pidyn.model_choice import nested_test


def _refined(run: Path) -> dict:
    """The refinement's parameter names and its residuals' lag-1 correlation."""
    ref = load_json(run / "refinement.json") or {}
    rest = ref.get("rest_test") or {}
    return {"names": ref.get("names") or [], "lag1": rest.get("residual_lag1_correlation")}


def choice(one: dict, two: dict) -> dict | None:
    """The test of two modes against one for an event (both rows ok), from their run folders."""
    a, b = _refined(one["run"]), _refined(two["run"])
    metrics = load_json(two["run"] / "metrics.json") or {}
    held, dt = metrics.get("heldout") or {}, (metrics.get("record_meta") or {}).get("dt")
    span = held.get("fit_span")
    extra = len(b["names"]) - len(a["names"])
    if None in (one.get("fit_nrmse_a"), two.get("fit_nrmse_a"), b["lag1"], dt, span) or extra <= 0:
        return None
    n = int(round((span[1] - span[0]) / dt)) + 1
    return nested_test(one["fit_nrmse_a"], two["fit_nrmse_a"], n, extra, b["lag1"])


def second_mode(run: Path) -> dict:
    modes = (load_json(run / "metrics.json") or {}).get("modal") or []
    return modes[1] if len(modes) > 1 else {}


def two_modes_lines(rows: list[dict], two: list[dict], judge) -> list[str]:
    """The section: per event, one mode against two on the fitting and held-out parts, the test,
    and the chosen model's held-out error against SRIM's."""
    ones = {(r["event"], r["direction"]): r for r in rows if r["status"] == "ok"}
    pairs = [
        (ones[(r["event"], r["direction"])], r)
        for r in two
        if r["status"] == "ok" and (r["event"], r["direction"]) in ones
    ]
    if not pairs:
        return []
    lines = [
        "## Two modes against one",
        "",
        "The same events with two modes driven by the three supports (`system=modes`, the class of SRIM's "
        "order-4 models; `python experiments/real.py --two-modes`), started where the single mode ended and "
        "from SRIM's order-4 model mapped onto it. "
        "The second mode is kept only when it earns its parameters on the fitting part: a likelihood-ratio "
        "test of the two fits, divided for correlated residuals, at 1 % (`pidyn.model_choice`). The held-out "
        "columns were not used for any choice.",
        "",
        "| event | direction | PGA (g) | fit NRMSE: 1 / 2 modes | held-out: 1 / 2 modes / SRIM | modes 1, 2: T (s), ζ (%) | "
        "test / 1 % threshold | kept | s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    tally: dict[tuple[str, str], list[tuple[bool, bool, bool, bool]]] = {}
    for one, two_row in sorted(pairs, key=lambda p: (p[0]["direction"], p[0].get("pga_g") or 0)):
        test = choice(one, two_row)
        kept = bool(test and test["richer"])
        m2 = second_mode(two_row["run"])
        tag = " *(t)*" if one["role"] == "tuning" else ""
        srim = one.get("srim_heldout_nrmse_a")
        lines.append(
            f"| {one['event']}{tag} | {one['direction']} | {cell(one.get('pga_g'))} | {cell(one['fit_nrmse_a'])} / "
            f"{cell(two_row['fit_nrmse_a'])} | {cell(one['heldout_nrmse_a'])} / {cell(two_row['heldout_nrmse_a'])} / "
            f"{cell(srim)} | {cell(two_row['period_s'])}, {cell(100 * (two_row['damping'] or 0), '.1f')}; "
            f"{cell(m2.get('period_s'))}, {cell(100 * m2['damping_ratio'] if m2 else None, '.1f')} | "
            + (f"{test['statistic']:.1f} / {test['threshold']:.1f}" if test else "-")
            + f" | {'2 modes' if kept else '1 mode'} | {cell(two_row.get('wall_s'), '.0f')} |"
        )
        chosen = two_row if kept else one
        if srim is not None and chosen["heldout_nrmse_a"] is not None:
            tally.setdefault((one["role"], one["direction"]), []).append(
                (
                    kept,
                    chosen["heldout_nrmse_a"] <= srim,
                    bool(judge(one).get("beats_srim")),
                    two_row["heldout_nrmse_a"] < one["heldout_nrmse_a"],
                )
            )
    lines += ["", *_tally_lines(tally), *_undamped_lines(pairs), ""]
    return lines


def _undamped_lines(pairs: list[tuple[dict, dict]]) -> list[str]:
    """How the two-mode fits whose mode ends (nearly) undamped predict the held-out part."""
    light = []
    for one, two in pairs:
        zetas = [two.get("damping"), second_mode(two["run"]).get("damping_ratio")]
        if any(z is not None and z < 0.01 for z in zetas) and None not in (
            one["heldout_nrmse_a"],
            two["heldout_nrmse_a"],
        ):
            light.append(two["heldout_nrmse_a"] > one["heldout_nrmse_a"])
    if not light:
        return []
    return [
        f"- A mode with less than 1 % damping in {len(light)} of the two-mode fits: there the second mode "
        f"predicts the held-out part worse than one mode on {sum(light)} (an oscillator that the fitting part "
        "does not damp keeps ringing in the quieter coda)."
    ]


def _tally_lines(tally: dict) -> list[str]:
    out = []
    for (role, direction), items in sorted(tally.items(), key=lambda kv: (kv[0][0] != "untouched", kv[0][1])):
        kept = sum(k for k, *_ in items)
        out.append(
            f"- {direction}, events {'kept out of all tuning' if role == 'untouched' else 'used in tuning'} "
            f"({len(items)} with a stable SRIM model): the second mode kept on {kept}; the chosen model at or "
            f"below SRIM's held-out NRMSE on {sum(c for _, c, _, _ in items)} (one mode alone: "
            f"{sum(o for _, _, o, _ in items)}); two modes predict the held-out part better than one on "
            f"{sum(t for *_, t in items)} (not used for the choice)."
        )
    return out
