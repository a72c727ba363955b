"""Figures and the markdown report of a diagnosis."""

from __future__ import annotations

from pathlib import Path

from pidyn.discrepancy.verdicts import Verdict
from pidyn.reporting import plottable


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shade(ax, fit, held) -> None:
    ax.axvspan(*held, color="0.92", zorder=0, label="held out")


def plot_response(
    path: Path, t, x, x_nom, x_ext, fit, held, unit: str = "m", period: float | None = None
) -> None:
    """Measured vs simulated displacement (nominal, extended) and the simulation errors; for a
    record of many periods, a third panel zooms into 30 periods at the start of the held-out part."""
    plt = _plt()
    x_nom = plottable(x_nom)  # a model that blows up is drawn up to the blow-up
    x_ext = None if x_ext is None else plottable(x_ext)
    zoom = period is not None and (t[-1] - t[0]) > 200 * period
    fig, axes = plt.subplots(3 if zoom else 2, 1, figsize=(11, 8 if zoom else 5.5))
    a1, a2 = axes[0], axes[1]
    a2.sharex(a1)
    if zoom:
        a3 = axes[2]
        sel = (t >= held[0]) & (t <= held[0] + 30 * period)
        a3.plot(t[sel], x[sel], color="k", lw=0.8, label="measured")
        a3.plot(t[sel], x_nom[sel], color="tab:red", lw=0.8, label="nominal model")
        if x_ext is not None:
            a3.plot(t[sel], x_ext[sel], color="tab:blue", lw=0.8, ls="--", label="extended model")
        a3.set(xlabel="t [s]", ylabel=f"x [{unit}]", title="zoom: start of the held-out part")
        a3.legend(loc="upper right", fontsize=8, ncol=3)
    _shade(a1, fit, held)
    a1.plot(t, x, color="k", lw=0.6, label="measured")
    a1.plot(t, x_nom, color="tab:red", lw=0.7, label="nominal model")
    if x_ext is not None:
        a1.plot(t, x_ext, color="tab:blue", lw=0.7, ls="--", label="extended model")
    a1.set_ylabel(f"x [{unit}]")
    a1.legend(loc="upper right", fontsize=8, ncol=4)
    _shade(a2, fit, held)
    a2.plot(t, x_nom - x, color="tab:red", lw=0.6, label="nominal - measured")
    if x_ext is not None:
        a2.plot(t, x_ext - x, color="tab:blue", lw=0.6, label="extended - measured")
    a2.set_ylabel(f"error [{unit}]")
    a2.set_xlabel("t [s]")
    a2.legend(loc="upper right", fontsize=8)
    fig.suptitle("What the simulation gets wrong: free simulation from the measured initial state")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_residual(path: Path, t, r_raw, x, v, fit, cause, fitted, units: dict, period: float) -> None:
    """The force the nominal model cannot explain: over time, against x and x', spectrum.

    The residual and x, x' are band-limited alike (``residual.unexplained_force``); one
    natural period at each end, where the spectral derivative rings, is left out."""
    from scipy.signal import welch

    plt = _plt()
    dt = float(t[1] - t[0])
    edge = max(1, int(round(period / dt)))
    if len(r_raw) > 4 * edge:
        inner = slice(edge, len(r_raw) - edge)
        t, r_raw, x, v = t[inner], r_raw[inner], x[inner], v[inner]
        fitted = None if fitted is None else fitted[inner]
    r = r_raw
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    ux, uf = units.get("x", "m"), units.get("u", "N")
    ax[0, 0].plot(t, r, lw=0.4, color="0.2", label="unexplained force")
    if fitted is not None:
        ax[0, 0].plot(t, fitted, lw=0.6, color="tab:blue", label=f"explained by {cause}")
    ax[0, 0].axvline(fit[1], color="k", ls=":", lw=0.8)
    ax[0, 0].set(xlabel="t [s]", ylabel=f"force [{uf}]", title="over time (dotted: end of fitting part)")
    ax[0, 0].legend(fontsize=8)
    step = max(1, len(t) // 20000)
    for a, s, lab in ((ax[0, 1], x, f"x [{ux}]"), (ax[1, 0], v, f"x' [{ux}/s]")):
        a.scatter(s[::step], r[::step], s=1, c=t[::step], cmap="viridis", alpha=0.5, rasterized=True)
        if fitted is not None:
            a.scatter(
                s[::step],
                fitted[::step],
                s=0.5,
                color="tab:red",
                alpha=0.5,
                rasterized=True,
                label=f"explained by {cause}",
            )
            a.legend(fontsize=8, markerscale=8)
        a.set(xlabel=lab, ylabel=f"force [{uf}]", title=f"against {lab.split()[0]} (colour: time)")
    nper = int(min(len(r), 2048))
    f, pr = welch(r_raw - r_raw.mean(), fs=1 / dt, nperseg=nper)
    ax[1, 1].semilogy(f[1:], pr[1:], color="0.3", lw=0.8, label="unexplained force")
    if fitted is not None:
        _, pf = welch(fitted - fitted.mean(), fs=1 / dt, nperseg=nper)
        ax[1, 1].semilogy(f[1:], pf[1:], color="tab:blue", lw=0.8, label=f"explained by {cause}")
    ax[1, 1].set(xlabel="frequency [Hz]", ylabel="PSD", title="spectrum")
    ax[1, 1].legend(fontsize=8)
    fig.suptitle("The force the nominal model cannot explain")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_ranking(path: Path, ranking: list[dict], min_delta_bic: float) -> None:
    plt = _plt()
    rows = [r for r in ranking if r.get("score") is not None]
    fig, ax = plt.subplots(figsize=(7, 0.45 * len(rows) + 1.2))
    names = [r["effect"] for r in rows][::-1]
    scores = [r["score"] for r in rows][::-1]
    colors = ["tab:blue" if r.get("passes") else "0.6" for r in rows][::-1]
    ax.barh(names, scores, color=colors)
    ax.axvline(
        min_delta_bic, color="k", ls=":", lw=0.8, label=f"evidence threshold (-dBIC = {min_delta_bic:g})"
    )
    ax.set_xscale("symlog")
    ax.set_xlabel("score = -dBIC (symlog)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_running_estimate(
    path: Path,
    running: dict,
    nominal: dict,
    fit,
    held,
    change=None,
    stiffness: str | None = None,
    signal: tuple | None = None,
) -> None:
    """The nominal parameters refitted in sliding windows over the record, relative to the
    nominal fit: a change in time shows as a step, located with its interval when found. With
    the ``stiffness`` parameter named, a second panel gives the running natural period
    2 pi sqrt(m / k(t)) (and the damping ratio) beside the motion's envelope (``signal``: t, x),
    so a period that lengthens in the strong motion and recovers in the coda shows as such."""
    import numpy as np

    plt = _plt()
    names = [n for n in running if n != "t" and n in nominal and n != "m"]
    with_period = stiffness is not None and stiffness in running and nominal.get(stiffness, 0) > 0
    fig, axes = plt.subplots(
        2 if with_period else 1, 1, figsize=(10, 6.8 if with_period else 3.8), squeeze=False
    )
    ax = axes[0, 0]
    _shade(ax, fit, held)
    for n in names:
        ax.plot(
            running["t"], np.asarray(running[n]) / nominal[n], marker=".", lw=1, label=f"{n} / nominal {n}"
        )
    ax.axhline(1.0, color="k", lw=0.6)
    if change is not None:
        ax.axvspan(*change.ci95, color="tab:orange", alpha=0.25, label="change, 95 % interval")
        ax.axvline(change.t_change, color="tab:orange", lw=1.2)
        ax.axhline(
            1.0 + change.fraction,
            color="tab:orange",
            lw=0.8,
            ls="--",
            label=f"{change.parameter} after the change ({100 * change.fraction:+.0f} %)",
        )
    ax.set(
        xlabel="t [s] (window centre)",
        ylabel="running estimate / nominal",
        title="Running estimate over the record (sliding weak-form fit)",
    )
    ax.legend(fontsize=8, loc="best")
    if with_period:
        _period_panel(axes[1, 0], running, nominal, fit, held, stiffness, signal)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _period_panel(a2, running: dict, nominal: dict, fit, held, stiffness: str, signal: tuple | None) -> None:
    """The running natural period (and damping ratio) beside the motion's envelope."""
    import numpy as np

    m = float(nominal.get("m", 1.0))
    k = np.asarray(running[stiffness], float)
    period = np.where(k > 0, 2 * np.pi * np.sqrt(m / np.where(k > 0, k, 1.0)), np.nan)
    _shade(a2, fit, held)
    a2.plot(running["t"], period, marker=".", lw=1.2, color="tab:blue", label="running period")
    a2.axhline(
        2 * np.pi * np.sqrt(m / nominal[stiffness]),
        color="tab:blue",
        lw=0.7,
        ls="--",
        label="nominal model's period",
    )
    a2.set(xlabel="t [s] (window centre)", ylabel="period [s]", title="Natural period through the record")
    if signal is not None:
        b = a2.twinx()
        b.plot(signal[0], np.abs(signal[1]), color="0.6", lw=0.5, zorder=0)
        b.set_ylabel("|x| (relative displacement)", color="0.5")
    if "c" in running and nominal.get("c") is not None:
        c = np.asarray(running["c"], float)
        zeta = np.where(k > 0, c / (2 * np.sqrt(m * np.where(k > 0, k, 1.0))), np.nan)
        a2.plot([], [], color="tab:red", marker=".", label="damping ratio (right axis, x100 %)")
        z = a2.twinx()
        z.spines["right"].set_position(("axes", 1.08))
        z.plot(running["t"], 100 * zeta, marker=".", lw=0.8, color="tab:red")
        z.set_ylabel("damping ratio [%]", color="tab:red")
    a2.legend(fontsize=8, loc="upper right")


def plot_learned_force(path: Path, x, v, residual, learned, surface: dict, units: dict) -> None:
    """The learned force beside the force the nominal model could not explain: against x and x'
    (the loops a structural engineer reads), and the learned f(x, x') as a surface."""
    import numpy as np

    plt = _plt()
    ux, uf = units.get("x", "m"), units.get("u", "N")
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    step = max(1, len(x) // 20000)
    for a, sig, lab in ((ax[0], x, f"x [{ux}]"), (ax[1], v, f"x' [{ux}/s]")):
        a.scatter(
            sig[::step],
            residual[::step],
            s=1,
            color="0.6",
            alpha=0.5,
            rasterized=True,
            label="unexplained force",
        )
        a.scatter(
            sig[::step],
            learned[::step],
            s=1,
            color="tab:blue",
            alpha=0.6,
            rasterized=True,
            label="learned force",
        )
        a.set(xlabel=lab, ylabel=f"force [{uf}]")
        a.legend(fontsize=8, markerscale=8)
    cs = ax[2].contourf(surface["x"], surface["v"], surface["f"], levels=20, cmap="RdBu_r")
    ax[2].plot(x[::step], v[::step], color="k", lw=0.2, alpha=0.4)
    ax[2].set(xlabel=f"x [{ux}]", ylabel=f"x' [{ux}/s]", title="learned f(x, x') (line: the record's path)")
    fig.colorbar(cs, ax=ax[2], label=f"force [{uf}]")
    fig.suptitle("Learned force (universal differential equation) against the unexplained force")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    del np


def _num(v) -> str:
    return "-" if v is None else (f"{v:.4g}" if isinstance(v, (int, float)) else str(v))


def write_report(path: Path, d: dict, figures: list[str]) -> None:
    """report.md: the verdict, the steps, the models' held-out errors, the evidence, the ranking."""
    lines = (
        _verdict_lines(d)
        + _accelerometer_lines(d)
        + _steps_lines(d)
        + _model_lines(d)
        + _evidence_lines(d)
        + _confirmation_lines(d)
        + _ranking_lines(d)
        + ["## Figures", ""]
        + [f"![{f}](figures/{f})" for f in figures]
    )
    path.write_text("\n".join(lines) + "\n")


def _verdict_lines(d: dict) -> list[str]:
    """The title and the verdict in words."""
    lines = [f"# Diagnosis of `{d['record']}`", ""]
    if d["verdict"] == Verdict.NONE:
        lines += [
            "**Verdict: none.** No candidate effect explains more of the residual than noise and the "
            "model's own error would (thresholds below). The nominal model is adequate for these data.",
            "",
        ]
    elif d["verdict"] == Verdict.UNEXPLAINED:
        lines += [
            "**Verdict: unexplained.** The nominal model is clearly wrong on these data, but no effect of the "
            "library (nor a change of stiffness or damping in time) explains what it misses. Look at the "
            "residual force below before trusting this model.",
            "",
        ]
    else:
        causes = d.get("causes") or [d["cause"]]
        lines += [
            f"**Verdict: discrepancy. Cause{'s' if len(causes) > 1 else ''}: "
            + ", ".join(f"`{c}`" for c in causes)
            + "**"
            + (" (named by the user, not by the screening)" if d.get("forced") else ""),
            "",
        ]
    return lines


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
    """Nominal and extended equations with their held-out errors, and the split."""
    g = d["gain"]
    lines = [
        "| model | equation | held-out NRMSE of x |",
        "|---|---|---|",
        f"| nominal | `{d['nominal']}` | {_num(g['nominal'])} |",
    ]
    if d.get("extended"):
        lines.append(f"| extended | `{d['extended']}` | {_num(g['extended'])} |")
    if g.get("trivial") is not None:
        lines.append(f"| knowing nothing | the structure {g['trivial_label']} | {_num(g['trivial'])} |")
    if d.get("trivial_note"):
        lines += ["", f"**{d['trivial_note']}**"]
    lines += [
        "",
        f"Fitting part {d['split']['fit'][0]:.4g}-{d['split']['fit'][1]:.4g} s; held-out part "
        f"{d['split']['heldout'][0]:.4g}-{d['split']['heldout'][1]:.4g} s (not used for fitting).",
        "",
    ]
    return lines


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
        from pidyn.discrepancy.heldout_check import HeldoutCheck

        why = HeldoutCheck(**hc).sentence()
        lines += [f"Held-out check: {why}.", ""]
    return lines


def _change_and_truth_lines(d: dict) -> list[str]:
    """A change in time, the effect parameters, and what was hidden in simulated data."""
    lines: list[str] = []
    ch = d.get("change")
    if ch:
        what = "stiffness" if ch["effect"] == "stiffness_loss" else "damping"
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


def plot_running_period(
    path: Path,
    running: dict,
    fit,
    held,
    signal: tuple | None = None,
    nominal_period: float | None = None,
    model: tuple | None = None,
) -> None:
    """Period and damping ratio window by window (output error on the sensors' readings), each with
    its 95 % interval, over the motion's envelope; ``model`` (t, period, zeta): an
    amplitude-dependent model's own, along its simulated response."""
    import numpy as np

    plt = _plt()
    t = np.asarray(running["t"])
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    for ax, key, label, scale in (
        (axes[0], "period", "period [s]", 1.0),
        (axes[1], "damping", "damping ratio [%]", 100.0),
    ):
        _shade(ax, fit, held)
        ax.fill_between(
            t,
            scale * np.asarray(running[f"{key}_lo"]),
            scale * np.asarray(running[f"{key}_hi"]),
            color="tab:blue",
            alpha=0.25,
            label="95 % interval",
        )
        ax.plot(
            t, scale * np.asarray(running[key]), marker=".", color="tab:blue", lw=1.2, label=f"running {key}"
        )
        ax.set_ylabel(label)
        if signal is not None:
            b = ax.twinx()
            b.plot(signal[0], np.abs(signal[1]), color="0.65", lw=0.5, zorder=0)
            b.set_ylabel("|measured| (sensor)", color="0.5")
    if nominal_period is not None:
        axes[0].axhline(nominal_period, color="k", lw=0.7, ls="--", label="one model for the fitting part")
    if model is not None:
        label = "amplitude-dependent model (its own response's envelope)"
        axes[0].plot(model[0], model[1], color="tab:red", lw=1.0, label=label)
        axes[1].plot(model[0], 100.0 * np.asarray(model[2]), color="tab:red", lw=1.0)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[0].set_title("Natural period and damping through the record (windows fitted by output error)")
    axes[1].set_xlabel("t [s] (window centre)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
