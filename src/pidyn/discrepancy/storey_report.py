"""What a building diagnosis writes: ``diagnosis.json`` (the SDOF diagnosis's fields, with
``storeys`` parallel to ``causes`` and a located change's ``t_change`` at the top level),
``report.md`` and, per storey, the force the model leaves unexplained against drift and drift
velocity (``figures/storey_residuals.png``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.screening_rules import Thresholds
from pidyn.discrepancy.step_reports import StoreyStep
from pidyn.discrepancy.storey_model import BuildingDiagnosis, StoreyView, score_text, storey_system
from pidyn.reporting import pyplot
from pidyn.systems.shear_building import ShearBuilding


def summarize_building(
    record: Record, system: ShearBuilding, d: BuildingDiagnosis, fit, held, thresholds: Thresholds
) -> dict:
    """``diagnosis.json`` of a building."""
    causes = [f.effect for f in d.found]
    params, t_change, t_ci = _accepted_parameters(d.steps)
    ext = None
    if d.extended:
        ext = {"system": d.extended.system, "storey_equations": d.extended.storey_equations}
    return {
        "nominal": {"system": system.name, "storey_equations": system.storey_equations(d.nominal.params)},
        "verdict": d.verdict,
        "cause": causes[0] if causes else None,
        "causes": causes,
        "storeys": [f.storey for f in d.found],
        "t_change": t_change,
        "unexplained_storey": d.unexplained_storey,
        "steps": [s.to_dict() for s in d.steps],
        "heldout_check": {
            "metric": "nrmse_a",
            "fit": d.nominal.fit.to_dict(),
            "heldout": d.nominal.heldout.to_dict(),
            "test": d.nominal.heldout_test,
        },
        "fit_test": d.nominal.fit_test,
        "change": None if t_change is None else {"t_change": t_change, "ci95": t_ci},
        "structure": [dict(sc.structure) for sc in d.screenings],
        "ranking": [_ranking_row(i, sc) for i, sc in enumerate(d.screenings, start=1)],
        "extended": ext,
        "parameters": params,
        "nominal_parameters": d.nominal.params,
        "nominal_intervals": d.nominal.intervals,
        "extended_parameters": d.extended.params if d.extended else None,
        "extended_intervals": d.extended.intervals if d.extended else None,
        "gain": d.gain,
        "learned": d.learned,
        "split": {"fit": list(fit), "heldout": list(held)},
        "record": record.name,
        "measured_floors": d.views[0].measured_floors if d.views else [],
        "highpass_hz": d.corner_hz,
        "noise": record.meta.noise,
        "thresholds": dataclasses.asdict(thresholds),
        "notes": d.notes,
    }


def _accepted_parameters(steps: list[StoreyStep]) -> tuple[dict, float | None, list[float] | None]:
    """The accepted steps' effect parameters and a located change's time with its interval."""
    params: dict = {}
    t_change, t_ci = None, None
    for step in steps:
        if not step.accepted:
            continue
        params.update(step.parameters)
        for name, iv in step.intervals.items():
            if name.startswith("t_d") and iv is not None:
                t_change, t_ci = float(step.parameters[name]), [float(v) for v in iv["ci95"]]
    if t_change is not None:
        params["t_change"], params["t_change_ci95"] = t_change, t_ci
    return params, t_change, t_ci


def _ranking_row(storey: int, sc) -> dict:
    return {
        "storey": storey,
        "verdict": sc.verdict,
        "cause": sc.cause,
        "own_law": sc.nominal_params,
        "rows": [r.to_dict() for r in sc.ranking],
    }


def storey_residual(view: StoreyView, values: dict[str, float], found) -> np.ndarray:
    """The storey force the model leaves unexplained: measured shear minus the storey's law (a
    hysteretic term found there is left in: its z needs the path, drawn as it is)."""
    i = view.storey
    here = [f for f in found if f.storey == i]
    system, sv = storey_system(values[f"c{i}"], values[f"k{i}"], here)
    law = np.zeros_like(view.drift)
    for term in system.terms:
        law = law + np.asarray(
            term.force(view.t, view.drift, view.drift_velocity, None, sv)
            if not term.n_latent
            else np.zeros_like(view.drift),
            float,
        )
    return view.shear - law


def write_building_figures(run_dir: Path, d: BuildingDiagnosis) -> list[str]:
    """Each storey's unexplained force against its drift and drift velocity; the figure's name."""
    plt = pyplot()

    n = len(d.views)
    fig, axes = plt.subplots(n, 2, figsize=(9, 2.6 * n), squeeze=False)
    t = d.views[0].t if d.views else np.zeros(0)
    edge = 0.05 * (t[-1] - t[0]) if len(t) else 0.0
    inner = (t >= t[0] + edge) & (t <= t[-1] - edge) if len(t) else slice(None)  # the filter's ends left out
    for row, view in zip(axes, d.views):
        nominal = storey_residual(view, d.nominal.params, [])
        final = storey_residual(view, d.values, d.found) if d.found else None
        named = [f.effect for f in d.found if f.storey == view.storey]
        signals = (
            (row[0], view.drift, "drift d (m)"),
            (row[1], view.drift_velocity, "drift velocity d' (m/s)"),
        )
        for ax, sig, label in signals:
            ax.plot(sig[inner], nominal[inner], ".", ms=1.5, alpha=0.5, color="0.55", label="nominal model")
            if final is not None:
                ax.plot(sig[inner], final[inner], ".", ms=1.5, alpha=0.6, color="C0", label="extended model")
            ax.set_xlabel(label)
            ax.set_ylabel(f"storey {view.storey} force (N)")
        title = f"storey {view.storey}: unexplained force" + (f" ({', '.join(named)} found)" if named else "")
        row[0].set_title(title, fontsize=9)
        row[0].legend(fontsize=7, markerscale=4, loc="best")
    fig.tight_layout()
    (run_dir / "figures").mkdir(parents=True, exist_ok=True)
    fig.savefig(run_dir / "figures" / "storey_residuals.png", dpi=110)
    plt.close(fig)
    return ["storey_residuals.png"]


def report_lines(d: dict) -> list[str]:
    """``report.md`` of a building after the common head: the storeys, the equations, the steps."""
    lines = [f"Floors measured: {d['measured_floors']}.", ""]
    if d["unexplained_storey"]:
        lines.append(
            f"Storey {d['unexplained_storey']}'s force is structured, and no library effect earns its place there."
        )
    if d["t_change"] is not None:
        lo, hi = d["change"]["ci95"]
        lines.append(f"Change located at t = {d['t_change']:.3f} s (95 % interval {lo:.3f}-{hi:.3f} s).")
    lines += ["", "Nominal model (fitting part):", ""] + [
        f"    {e}" for e in d["nominal"]["storey_equations"]
    ]
    if d["extended"]:
        lines += ["", "Extended model:", ""] + [f"    {e}" for e in d["extended"]["storey_equations"]]
    lines += _fit_test_lines(d.get("fit_test"))
    lines += _storey_table(d)
    learned = d.get("learned")
    if learned:
        lines.append(
            f"\nLearned force f_NN(d, d') in storey {learned['storey']} (storeys tried: {learned['storeys_tried']}, "
            f"the best fit of the fitting part taken): held-out NRMSE {learned['heldout_before']:.4g} -> "
            f"{learned['heldout_after']:.4g}, {'kept' if learned['kept'] else 'not kept (it does not predict better)'}."
        )
    for s in d["steps"]:
        lines.append(
            f"\nStep: {s['effect']} in storey {s['storey']} (score {score_text(s.get('score'))}): held-out NRMSE "
            f"{s['heldout_before']:.4g} -> {s['heldout_after']:.4g}, {StoreyStep.of(s).outcome()}."
        )
    return lines + [""]


def _fit_test_lines(test: dict | None) -> list[str]:
    """The nominal building's fitting part against the sensors' noise, floor by floor."""
    if not test:
        return []

    def cell(ch: str, v: dict) -> str:
        if v["noise"] is None:
            return f"{ch} {v['nrmse']:.3g} / -"
        # no band above the modes: the second difference, an upper bound on the noise
        bound = " (second-difference bound)" if v.get("noise_method") == "second_difference" else ""
        return f"{ch} {v['nrmse']:.3g} / {v['noise']:.3g}{bound}"

    cells = ", ".join(cell(ch, v) for ch, v in test["channels"].items())
    verdict = (
        f"not fitted down to the noise on {test['failed_channels']}"
        if test["failed"]
        else "fitted down to the noise"
    )
    return [
        "",
        f"Fitting part against the sensors' noise (NRMSE / noise, read above the structural band): {cells}; {verdict} "
        f"(fails at {test['rms_ratio']:g} times the noise and {test['min_excess']:g} above it).",
    ]


def _storey_table(d: dict) -> list[str]:
    """report.md's table: per storey the model's c, k, the storey's own, and its screening."""
    lines: list[str] = []
    lines += [
        "",
        "| storey | the model's c, k | c, k from the storey's own shear | screening verdict | top effect | score "
        "| cross-validation gain |",
        "|---|---|---|---|---|---|---|",
    ]
    final = d["extended_parameters"] or d["nominal_parameters"]
    for r in d["ranking"]:
        top = r["rows"][0] if r["rows"] else {}
        score = top.get("score")
        i, own = r["storey"], r.get("own_law") or {}
        model = f"{final.get(f'c{i}', float('nan')):.4g}, {final.get(f'k{i}', float('nan')):.5g}"
        law = f"{own.get('c', float('nan')):.4g}, {own.get('k', float('nan')):.5g}"
        lines.append(
            f"| {i} | {model} | {law} | {r['verdict']} | {top.get('effect', '-')} | "
            f"{'-' if score is None else f'{score:.1f}'} | {top.get('cv_gain', float('nan')):.3f} |"
        )
    lines += [
        "",
        "The storey's own c, k: its law refitted to the shear its floors' accelerations give (the weak form, "
        "fitting part), without the other storeys; where it differs from the model's, the record places the "
        "stiffness or damping in another storey than the model does.",
    ]
    return lines
