"""The markdown report of a diagnosis (its figures: ``report_figures``)."""

from __future__ import annotations

from pidyn.discrepancy.effects import get_effect
from pidyn.discrepancy.heldout_check import HeldoutCheck


def _num(v) -> str:
    return "-" if v is None else (f"{v:.4g}" if isinstance(v, (int, float)) else str(v))


def report_sections(d: dict) -> list[str]:
    """report.md after the common head: the steps, the equations, the evidence, the ranking."""
    return (
        _accelerometer_lines(d)
        + _steps_lines(d)
        + _model_lines(d)
        + _evidence_lines(d)
        + _confirmation_lines(d)
        + _ranking_lines(d)
    )


def _accelerometer_lines(d: dict) -> list[str]:
    """An accelerometer record: how its motion was read, what the running period says, and which
    candidates the accelerations decide between and which they cannot."""
    acc = d.get("accelerometers")
    if not acc:
        return []
    lines = [
        "## From accelerometers",
        "",
        f"The relative motion is the measured acceleration minus what the sensor reads of the supports "
        f"({acc.get('note')}); the weak-form screening below ran on it integrated (high-passed at "
        f"{acc.get('highpass_hz', 0):.3g} Hz) and only proposes: each candidate was fitted by output error "
        f"to the accelerations, and that fit decides.",
        "",
    ]
    run = d.get("running") or {}
    var = run.get("variation") or {}
    if var.get("varies"):
        lo, hi = var["longest"], var["shortest"]
        lines += [
            f"**The period is not one.** It is {lo['period']:.3f} s (95 % {lo['ci95'][0]:.3f}-{lo['ci95'][1]:.3f}) "
            f"in the window at {lo['t']:.1f} s and {hi['period']:.3f} s ({hi['ci95'][0]:.3f}-{hi['ci95'][1]:.3f}) "
            f"in the one at {hi['t']:.1f} s, windows that share no sample: no one linear, time-invariant model "
            "holds through the record.",
            "",
        ]
    if "period_longest" in run:
        lines += [
            f"Window by window (figure `running_period.png`) the period is {run['period_strongest_window']:.3f} s "
            f"in the strongest window (t = {run['t_strongest_window']:.1f} s), longest {run['period_longest']:.3f} s "
            f"(t = {run['t_period_longest']:.1f} s), {run['period_quietest_window']:.3f} s in the quietest and "
            f"{run['period_last_window']:.3f} s in the last; the damping ratio "
            f"{100 * run['damping_strongest_window']:.0f} % in the strongest window and "
            f"{100 * run['damping_last_window']:.0f} % in the last.",
            "",
        ]
    lines += decision_lines(
        d.get("confirmation") or [], (d.get("thresholds") or {}).get("tie_delta_bic", 6.0)
    )
    return lines


def decision_lines(tested: list[dict], tie: float) -> list[str]:
    """Which candidates the output-error fits decide for, which they cannot tell apart, which none."""
    rows = [r for r in tested if r.get("score") is not None]
    if not rows:
        return []
    best = max(rows, key=lambda r: r["score"])
    passing = [r["effect"] for r in rows if r.get("passes")]
    close = [r["effect"] for r in rows if r is not best and best["score"] - r["score"] < tie]
    helps = [
        f"{r['effect']} ({r['heldout_gain']:+.2f})"
        for r in rows
        if r.get("heldout_gain") is not None and r["heldout_gain"] > 0.02
    ]
    out = []
    if passing:
        out.append(
            f"The accelerations decide for `{best['effect']}` (BIC {best['delta_bic']:.1f} against the nominal "
            f"model"
            + (f"; `{'`, `'.join(close)}` within {tie:g} of it: not told apart" if close else "")
            + ")."
        )
    else:
        out.append(
            "No candidate passes the evidence threshold on the fitting part: the data do not decide for any "
            f"(best `{best['effect']}`, BIC {best['delta_bic']:.1f})."
        )
    if helps:
        out.append("Held-out gain of each candidate fitted alone: " + ", ".join(helps) + ".")
    return out + [""]


def _steps_lines(d: dict) -> list[str]:
    """Each extension step with its evidence (when there was more than one)."""
    lines: list[str] = []
    if len(d.get("steps") or []) > 1 or any(st.get("next_ranking") for st in d.get("steps") or []):
        lines += [
            "## Steps: extend, screen the extended model again",
            "",
            "| step | effect added | score (-dBIC) | CV gain | model after the step | next candidate |",
            "|---|---|---|---|---|---|",
        ]
        steps = d["steps"]
        for i, st in enumerate(steps):
            ev = st["evidence"]
            ranking = st.get("next_ranking") or [{}]
            named = steps[i + 1]["effect"] if i + 1 < len(steps) else None  # a tie-break may name the second
            nxt = next((r for r in ranking if r.get("effect") == named), ranking[0])
            by_oe = (
                i + 1 < len(steps) and (steps[i + 1].get("evidence") or {}).get("source") == "output_error"
            )
            nxt_s = (
                "-"
                if not nxt
                else (
                    f"{nxt.get('effect')} {_num(nxt.get('score'))} "
                    f"({'named by the output-error check' if by_oe else 'passes' if nxt.get('passes') else 'below the thresholds: stop'})"
                )
            )
            lines.append(
                f"| {st['step']} | {st['effect']} | {_num(ev.get('score'))} | {_num(ev.get('cv_gain'))} | "
                f"`{st['equation']}` | {nxt_s} |"
            )
        lines.append("")
    return lines


def _model_lines(d: dict) -> list[str]:
    """The nominal and extended equations."""
    lines = ["| model | equation |", "|---|---|", f"| nominal | `{d['nominal']}` |"]
    if d.get("extended"):
        lines.append(f"| extended | `{d['extended']}` |")
    return lines + [""]


def _evidence_lines(d: dict) -> list[str]:
    """The learned force, the held-out check, a change in time, the effect parameters, the truth."""
    return _learned_lines(d) + _check_lines(d) + _change_and_truth_lines(d)


def _learned_lines(d: dict) -> list[str]:
    """The learned force that was added, and how it was trained."""
    lines: list[str] = []
    if d.get("learned_force"):
        st = d.get("structure") or {}
        lines += [
            "A learned force f(x, x') (a small network in the equation of motion, trained in PIDynNet's physics "
            "loss from the force the model could not explain) was added"
            + (
                f"; a generic f(x, x') removes {st['cv_gain']:.2f} of the residual in cross-validation"
                if st.get("cv_gain") is not None
                else ""
            )
            + ". Compare it with the unexplained force in `figures/learned_force.png` before naming a cause.",
            "",
        ]
        lf = d.get("learned_fit")
        if lf:
            lines += [
                "After PIDynNet, the network and the physical parameters were trained further on the simulated "
                "response of the fitting part (a free simulation is what the held-out comparison measures): "
                f"{lf['segments']} segments of {lf['segment_seconds']:.3g} s, {lf['evaluations']} evaluations, "
                f"{lf['seconds']:.1f} s; segment loss {lf['loss_before']:.3g} -> {lf['loss_after']:.3g} "
                "(mean squared error over the response's variance).",
                "",
            ]
    return lines


def _check_lines(d: dict) -> list[str]:
    """A learned force refused, two effects at once, the held-out check."""
    lines: list[str] = []
    refused = d.get("learned_force_refused")
    if refused:
        lines += [
            f"A learned force f(x, x') was tried ({refused['folder']}/) and not kept: {refused['note']}. What "
            "the model misses is structured, but neither the library nor a network of x and x' trained on the "
            "fitting part predicts it; the model below is the one it would have extended.",
            "",
        ]
    pair = (d.get("structure") or {}).get("pair")
    if pair:
        lines += [
            f"Two effects at once: {pair['why']}. {pair['lead']} was named first; the screening of the model "
            "extended with it had to find the other on its own.",
            "",
        ]
    if d.get("unearned"):
        lines += [f"Not named: {d['unearned']['note']}.", ""]
    hc = d.get("heldout_check")
    if hc:
        why = HeldoutCheck(**hc).sentence()
        lines += [f"Held-out check: {why}.", ""]
    return lines


def _change_and_truth_lines(d: dict) -> list[str]:
    """A change in time, the effect parameters, and what was hidden in simulated data."""
    lines: list[str] = []
    ch = d.get("change")
    if ch:
        what = get_effect(ch["effect"]).changes
        lines += [
            "## Change in time",
            "",
            f"The model held until t = {ch['t_change']:.2f} s (95 % interval {ch['t_change_ci95'][0]:.2f}-"
            f"{ch['t_change_ci95'][1]:.2f} s, from the profile of the weak-form residual over the change time); "
            f"then the {what} `{ch['parameter']}` changed by {100 * ch['fraction']:+.1f} % (screening estimate; "
            "the extended model's estimate is below).",
            "",
        ]
    if d.get("parameters"):
        lines += [
            "Estimated effect parameters: "
            + ", ".join(
                f"{k} = {_num(v) if not isinstance(v, list) else '[' + ', '.join(_num(u) for u in v) + ']'}"
                for k, v in d["parameters"].items()
            ),
            "",
        ]
    if d.get("hidden"):
        h = d["hidden"]
        if h.get("effect"):
            lines += [
                f"Hidden in the data (simulated): `{h['effect']}` "
                + ", ".join(f"{k} = {v:.5g}" for k, v in (h["parameters"] or {}).items()),
                "",
            ]
        else:
            lines += ["Hidden in the data (simulated): nothing; the nominal model is the truth.", ""]
    return lines


def _confirmation_lines(d: dict) -> list[str]:
    """The output-error check of the effects a screening leaned to without deciding."""
    checks = [("nominal model", d.get("confirmation"))]
    checks += [
        (f"after step {st['step']} ({st['effect']})", st.get("next_confirmation"))
        for st in d.get("steps") or []
    ]
    checks = [(where, rows) for where, rows in checks if rows]
    if not checks:
        return []
    lines = [
        "## Output-error check",
        "",
        "Effects the weak-form screening leaned to (0 < score < threshold) without deciding (on an accelerometer "
        "record every effect it could fit, and a change it located in time), fitted by output error "
        "with the model and compared on the simulated response: -dBIC over the residual's independent samples, "
        "held-out gain = share of the held-out simulation error removed; of those that pass, the best is named.",
        "",
        "| model | effect | weak-form score | -dBIC (output error) | independent samples | held-out gain | passes | estimate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for where, rows in checks:
        for r in rows:
            est = ", ".join(f"{k}={v:.4g}" for k, v in (r.get("parameters") or {}).items())
            loc = r.get("located")  # a change the weak form located in time: where it put it
            effect = r["effect"] if not loc else f"{r['effect']} (located at {loc['t_change']:.2f} s)"
            lines.append(
                f"| {where} | {effect} | {_num(r.get('weak_form_score'))} | {_num(r.get('score'))} | "
                f"{_num(r.get('independent_samples'))} | {_num(r.get('heldout_gain'))} | "
                f"{'yes' if r.get('passes') else 'no'} | {est or r.get('error', '')} |"
            )
    return lines + [""]


def _ranking_lines(d: dict) -> list[str]:
    """The ranking of the library effects and the thresholds they are held to."""
    lines: list[str] = []
    lines += [
        "## Ranking of the candidate effects",
        "",
        "score = -dBIC (weak-form equation error, fitting part); explained = share of the nominal residual "
        "removed; CV gain = share removed in blocked cross-validation over the fitting part; held-out gain = share "
        "removed on the held-out rows with coefficients from the fitting part.",
        "",
        "| effect | score | explained | CV gain | held-out gain | passes | estimate |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in d["ranking"]:
        est = ", ".join(f"{k}={v:.4g}" for k, v in (r.get("parameters") or {}).items())
        lines.append(
            f"| {r['effect']} | {_num(r.get('score'))} | {_num(r.get('explained'))} | "
            f"{_num(r.get('cv_gain'))} | {_num(r.get('heldout_gain'))} | {'yes' if r.get('passes') else 'no'} | {est or r.get('note', '')} |"
        )
    th = d["thresholds"]
    lines += [
        "",
        f"An effect counts when -dBIC >= {th['min_delta_bic']:g}, CV gain >= "
        f"{th['min_cv_gain']:g} and it removes at least {th['min_force_share']:g} of the force variance.",
        "",
    ]
    return lines
