"""What a deck's diagnosis writes beyond the common head: ``diagnosis.json``'s deck fields, the
report's sections (each support's law with its interval, which supports the data tell apart, the
candidates' scores, the steps) and the held-out deck channels, measured against both models
(``figures/deck_channels.png``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pidyn.discrepancy.deck_model import DeckDiagnosis, channels, simulated_channels
from pidyn.notes import note
from pidyn.reporting import pyplot
from pidyn.supports import support_lines


def deck_notes(study, d: DeckDiagnosis) -> list[str]:
    """The coded notes: supports the data do not tell apart (their springs, ``pidyn.supports``, or
    where an effect sits), and a failed fit with nothing named."""
    out = list(d.nominal["supports"][1])
    for a in d.alike:
        j, k = a["supports"]
        out.append(
            note(
                "effect_support_not_distinguished",
                f"{a['effect']} at support {j} or at support {k}: the deck channels change alike for either "
                f"(correlation {a['correlation']:.3f}); the data name the effect, not which of the two supports",
            )
        )
    rigid = d.nominal["rigid_test"]
    if not rigid["rigid"]:
        worst = max(rigid["failed_channels"], key=lambda n: rigid["off_share"][n])
        out.append(
            note(
                "deck_not_rigid",
                f"the deck channels do not move as a deck rigid in plan: {100 * rigid['off_share'][worst]:.0f} % of "
                f"channel {worst} (RMS) is off the best rigid motion of the deck, beyond its noise; the deck bends or "
                "twists in plan, and an effect named at a support may stand for that as much as for the support",
            )
        )
    if not d.found and d.nominal["fit_test"]["failed"]:
        out.append(
            note(
                "fit_fails",
                "nothing named, but the nominal deck does not fit its fitting part down to the sensors' noise "
                f"(channels {', '.join(d.nominal['fit_test']['failed_channels'])}); no effect of the library at "
                "any support predicts the held-out part better",
            )
        )
    return out


def deck_summary(study, d: DeckDiagnosis) -> dict[str, Any]:
    """``diagnosis.json``'s deck fields."""
    system = study.system
    return {
        "nominal": {
            "system": system.name,
            "support_equations": system.support_equations(d.nominal["params"]),
        },
        "extended": None
        if not d.found
        else {
            "system": d.final.system.name,
            "support_equations": d.final.system.support_equations(d.final.values),
        },
        "verdict": d.verdict,
        "cause": d.found[0].effect if d.found else None,
        "change": None,  # a support's change in time is one of its effects (stiffness_loss, damping_change)
        "supports": [f.support for f in d.found],
        "nominal_parameters": d.nominal["params"],
        "nominal_intervals": d.nominal["intervals"],
        "extended_parameters": d.final.values if d.found else None,
        "extended_intervals": d.final.result.intervals if d.found and d.final.result is not None else None,
        "support_table": d.nominal["supports"][0],
        "alike": d.alike,
        "fit_test": d.nominal["fit_test"],
        "rigid_test": d.nominal["rigid_test"],
        "heldout_check": {"metric": "nrmse_a", "fit": d.nominal["fit"], "heldout": d.nominal["heldout"]},
        "ranking": d.ranking,
        "steps": d.steps,
        "split": {"fit": list(study.fit), "heldout": list(study.held)},
        "channels": channels(study.record)[2],
        "layout": {
            "length_m": system.length,
            "supports": dict(zip(system.inputs, system.positions)),
            "sensors": system.sensors,
        },
    }


def deck_sections(summary: dict[str, Any]) -> list[str]:
    """The report's deck sections, after the common head."""
    lines = ["## The supports", ""]
    lines += [f"- nominal: {e}" for e in summary["nominal"]["support_equations"]]
    if summary["extended"]:
        lines += [f"- extended: {e}" for e in summary["extended"]["support_equations"]]
    lines += [
        "",
        "The nominal deck's supports (per kg of deck; a value the data do not determine is not printed):",
        "",
    ]
    lines += support_lines(summary["support_table"])
    lines += ["", "## Which support misses what", ""]
    lines += [
        "Each effect at each support, scored by the share of the fitting part's misfit it would remove:",
        "",
    ]
    lines += ["| effect | support | share of the misfit |", "|---|---|---|"]
    lines += [f"| {r['effect']} | {r['support']} | {r['share']:.3g} |" for r in summary["ranking"][:8]]
    lines += ["", "| tried | held-out NRMSE before | after | outcome |", "|---|---|---|---|"]
    lines += [
        f"| {s['effect']} at support {s['support']} | {s['heldout_before']:.4g} | {s['heldout_after']:.4g} | {s['outcome']} |"
        for s in summary["steps"]
    ]
    named = [s for s in summary["steps"] if s["accepted"]]
    if named:
        lines += ["", "| named effect's parameter | value | 95 % interval |", "|---|---|---|"]
        for step in named:
            for name, value in step["parameters"].items():
                ci = (step["intervals"].get(name) or {}).get("ci95")
                lines.append(f"| {name} ({step['effect']}) | {value:.4g} | {_ci(ci)} |")
    rt = summary["rigid_test"]
    lines += [
        "",
        "The deck channels against the best rigid motion of the deck (before any model): "
        + ", ".join(f"{n} {100 * v:.0f} % off" for n, v in rt["off_share"].items())
        + (
            " (within their noise)."
            if rt["rigid"]
            else f"; beyond their noise on {', '.join(rt['failed_channels'])}."
        ),
    ]
    ft = summary["fit_test"]
    lines += [
        "",
        f"Fit test of the nominal deck (fitting part, against each channel's noise): {'failed' if ft['failed'] else 'passed'}.",
        "",
    ]
    return lines


def write_deck_figures(run_dir: Path, study, d: DeckDiagnosis) -> list[str]:
    """The held-out deck channels: measured, the nominal deck's and the extended deck's."""
    plt = pyplot()
    record = study.record
    meas, _, names = channels(record)
    m = (record.t >= study.held[0]) & (record.t <= study.held[1])
    nominal = simulated_channels(d.nominal_state.system, [d.nominal_state.values], record)[0]
    final = simulated_channels(d.final.system, [d.final.values], record)[0] if d.found else None
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.2 * len(names)), sharex=True, squeeze=False)
    for i, (ax, name) in enumerate(zip(axes[:, 0], names)):
        ax.plot(record.t[m], meas[m, i], color="k", lw=0.8, label="measured")
        ax.plot(record.t[m], nominal[m, i], color="0.55", lw=0.8, label="nominal deck")
        if final is not None:
            ax.plot(record.t[m], final[m, i], color="C0", lw=0.8, label="extended deck")
        ax.set_ylabel(f"{name} (abs.)")
    axes[0, 0].set_title("held-out deck channels, simulated from rest", fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("t (s)")
    fig.tight_layout()
    (run_dir / "figures").mkdir(parents=True, exist_ok=True)
    fig.savefig(run_dir / "figures" / "deck_channels.png", dpi=110)
    plt.close(fig)
    return ["deck_channels.png"] if np.isfinite(nominal).any() else []


def _ci(ci) -> str:
    return "-" if not ci or ci[0] is None else f"{float(ci[0]):.4g} to {float(ci[1]):.4g}"
