"""What a diagnosis writes: ``diagnosis.json``'s content, the figures and ``report.md``."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.discrepancy.accelerometers import acceleration_gain
from pidyn.discrepancy.case import Case, Outcome
from pidyn.discrepancy.changes import running_estimate
from pidyn.discrepancy.effects import EFFECTS, Signals
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.learned_step import LEARNED
from pidyn.discrepancy.report_figures import (
    plot_learned_force,
    plot_ranking,
    plot_residual,
    plot_response,
    plot_running_estimate,
    plot_running_period,
)
from pidyn.discrepancy.result import DiagnosisResult, Finding, HeldoutErrors, trivial_note
from pidyn.discrepancy.screening import weak_system
from pidyn.discrepancy.verdicts import Verdict
from pidyn.notes import note
from pidyn.parallel import map_ordered
from pidyn.reporting import nrmse
from pidyn.signals import band_limited
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.terms import AmplitudeSoftening, latent_path


def conclusion(case: Case, o: Outcome) -> DiagnosisResult:
    """The single degree of freedom's result: the verdict (``unexplained`` when the names did not
    earn their place, see ``_verdict``), the causes kept, the held-out errors, the coded notes."""
    gain = heldout_gain(case, o)
    learned = LEARNED in o.causes
    unearned = o.extension.unearned  # the extension's names did not earn their place: none is kept
    causes = [] if unearned else [c for c in o.causes if c != LEARNED]
    worse = trivial_note(gain)
    verdict = Verdict.UNEXPLAINED if unearned else _verdict(case, o, bool(causes), learned, worse is not None)
    contested = None if unearned else rivals(o)
    # (the result adds the note that it predicts worse than knowing nothing, as for every subject)
    notes = [n for n in ((unearned or {}).get("note"), (contested or {}).get("note")) if n]
    return DiagnosisResult(
        case.record.name,
        "single degree of freedom",
        "",
        verdict,
        [Finding(c) for c in causes],
        HeldoutErrors.of(gain),
        gain,
        notes,
        o.forced,
        o,
    )


def summarize(case: Case, result: DiagnosisResult) -> dict[str, Any]:
    """diagnosis.json beyond the result's head: the evidence, the parameters, the models."""
    o: Outcome = result.detail
    record, nom, ext = case.record, o.nominal, o.extension
    unearned = ext.unearned
    causes = [f.effect for f in result.findings]
    ext_system, ext_values, ext_metrics = ext.system, ext.values, ext.metrics
    effect_params = _effect_parameters(o, nom, ext_system, ext_values)
    hidden = record.meta.hidden_params  # {} for a hidden case that hides nothing
    truth = None if hidden is None else dict(hidden)
    return {
        "nominal": nom.system.describe(nom.values),
        "cause": causes[0] if causes else (None if o.cause == LEARNED or unearned else o.cause),
        "unearned": None if unearned is None else _with_steps(unearned),
        "t_change": effect_params.get("t_change"),
        "steps": [s.to_dict() for s in ext.steps],
        "learned_force": LEARNED in o.causes,
        "structure": {k: v for k, v in o.screening.structure.items()},
        "heldout_check": o.check.__dict__,
        "change": None if o.change_row is None else o.change_row.change.to_dict(),
        "ranking": [r.to_dict() for r in o.screening.ranking],
        "extended": ext_system.describe(ext_values) if ext_system is not None else None,
        "parameters": effect_params,
        "nominal_parameters": nom.values,
        "extended_parameters": ext_values,
        "trivial_note": result.worse_than_trivial,
        "split": {"fit": list(case.fit), "heldout": list(case.held)},
        "record": record.name,
        "noise": record.meta.noise,
        "natural_period": nom.period,
        "thresholds": dataclasses.asdict(case.thresholds),
        "polish": {"nominal": nom.polish_note, "extended": ext.note},
        "learned_fit": ext.learned_fit,
        "pidynnet": {
            "nominal_errors_pct": nom.metrics.get("error_pct"),
            "extended_errors_pct": None if ext_metrics is None else ext_metrics.get("error_pct"),
        },
        "hidden": None if truth is None else {"effect": record.meta.hidden_effect, "parameters": truth},
        "modal": None
        if o.modal is None
        else [{k: v for k, v in m.items() if not k.startswith("mode_shape")} for m in o.modal],
        "running": None if o.running is None else running_summary(o.running, case),
        "accelerometers": None
        if record.meta.accelerometers is None
        else record.meta.accelerometers.to_dict(),
        "confirmation": None if o.confirmation is None else [r.to_dict() for r in o.confirmation.tested],
        "confirmation_nominal": None if o.confirmation is None else o.confirmation.nominal,
        "rivals": None if unearned else rivals(o),
        "learned_force_refused": None if ext.refused is None else ext.refused.to_dict(),
    }


def heldout_gain(case: Case, o: Outcome) -> dict[str, Any]:
    """The nominal and extended models' NRMSE on the held-out part: of the displacement (and
    against the noise-free truth when simulated), of the accelerations for accelerometer records."""
    record, held_mask = case.record, case.mask(case.held)
    gain = {
        "metric": "heldout_nrmse_x",
        "nominal": nrmse(o.x_nom[held_mask], case.x_raw[held_mask]),
        "extended": None if o.x_ext is None else nrmse(o.x_ext[held_mask], case.x_raw[held_mask]),
    }
    if record.clean is not None:
        xc = record.clean.x[:, 0]
        gain["nominal_vs_clean"] = nrmse(o.x_nom[held_mask], xc[held_mask])
        gain["extended_vs_clean"] = None if o.x_ext is None else nrmse(o.x_ext[held_mask], xc[held_mask])
    gain["trivial"], gain["trivial_label"] = (
        nrmse(np.zeros(int(held_mask.sum())), case.x_raw[held_mask]),
        "at rest",
    )
    if case.from_accelerometers:  # the sensors' quantity decides; the displacement's gain is kept beside it
        gain = {**acceleration_gain(record, o.sims, held_mask), "x": gain}
    for key in ("nominal", "extended"):  # beside every held-out score, the prediction that knows nothing
        gain[f"{key}_beats_trivial"] = None if gain.get(key) is None else bool(gain[key] < gain["trivial"])
    return gain


def rivals(o: Outcome) -> dict[str, Any] | None:
    """The effects the output-error check cannot tell from the one it named (within
    ``tie_delta_bic``): the record does not decide between them. None when it does."""
    row = None if o.confirmation is None else o.confirmation.row
    if not row or not row.rivals:
        return None
    named = row.effect
    others = ", ".join(f"{r.effect} ({r.score:.1f})" for r in row.rivals)
    return {
        "named": named,
        "rivals": [r.to_dict() for r in row.rivals],
        "note": note(
            "not_decided",
            f"{named} is named by the output-error check (score {row.score:.1f}), but {others} "
            "simulate the record as well: the record does not decide between them",
        ),
    }


def _effect_parameters(o: Outcome, nom, ext_system, ext_values) -> dict[str, Any]:
    """The extended model's parameters beyond the nominal ones, and a located change's time."""
    effect_params: dict[str, Any] = {}
    if ext_values is not None and ext_system is not None:
        nominal_names = {sp.name for sp in nom.system.param_specs()}
        effect_params = {k: v for k, v in ext_values.items() if k not in nominal_names}
    if o.change_row is not None:
        ch = o.change_row.change
        effect_params["t_change"] = effect_params.get("t_d", ch.t_change)
        effect_params["t_change_ci95"] = list(ch.ci95)
    return effect_params


def _verdict(case: Case, o: Outcome, named: bool, learned: bool, worse: bool = False) -> Verdict:
    """``discrepancy`` with a named cause; ``unexplained`` with a learned force or a structured
    misfit (the held-out check failed, or the weak form's residual, or the running period moved),
    or where the nominal model predicts the held-out part worse than knowing nothing (``worse``:
    it does not hold there, whatever the checks say); else ``none``."""
    sc, check = o.screening, o.check
    varies = bool(((o.running or {}).get("variation") or {}).get("varies"))
    structured = (
        (check.failed or varies)
        if case.from_accelerometers
        else (check.failed or sc.verdict == Verdict.UNEXPLAINED)
    )
    if named or (o.cause is not None and o.cause != LEARNED):
        return Verdict.DISCREPANCY
    return Verdict.UNEXPLAINED if learned or structured or worse else Verdict.NONE


def _with_steps(unearned: dict) -> dict:
    """An unearned extension's account with its steps in their JSON form."""
    return {
        **unearned,
        **({"steps": [s.to_dict() for s in unearned["steps"]]} if "steps" in unearned else {}),
    }


def write_figures(case: Case, o: Outcome, d: dict) -> list[str]:
    """The figures of the run folder, drawn side by side on the machine's cores
    (``pidyn.parallel``; the slowest first); their file names."""
    fig = case.run_dir / "figures"
    fig.mkdir(exist_ok=True)
    draws = [
        lambda: _residual_figure(case, o, d["cause"], fig),
        lambda: _running_period_figure(case, o, fig),
        lambda: _running_estimate_figure(case, o, fig),
        lambda: _response_figure(case, o, fig),
        lambda: plot_ranking(fig / "ranking.png", o.screening.ranking, case.thresholds.min_delta_bic),
    ]
    ext = o.extension
    if d["learned_force"] and ext.system is not None and ext.system.n_latent == 0:
        draws.append(lambda: _learned_figure(case, o, fig))
    map_ordered(_draw, draws)
    return [p.name for p in sorted(fig.glob("*.png"))]


def _draw(draw) -> None:
    """One figure drawn (what it returns stays in the process that drew it)."""
    draw()


def _response_figure(case: Case, o: Outcome, fig: Path) -> None:
    units = case.record.meta.units or {}
    plot_response(
        fig / "simulation_vs_measured.png",
        case.record.t,
        case.x_raw,
        o.x_nom,
        o.x_ext,
        case.fit,
        case.held,
        units.get("x", "m"),
        o.nominal.period,
    )


def _residual_figure(case: Case, o: Outcome, cause: str | None, fig: Path) -> None:
    """The force the nominal model leaves, and the named cause's share of it."""
    nom, pw = o.nominal, o.pointwise
    row = _evidence_row(o, cause)
    explained = None if row is None else explained_force(nom.system, nom.values, row, nom.s, pw)
    units = case.record.meta.units or {}
    plot_residual(
        fig / "residual.png",
        case.record.t,
        pw["r"],
        pw["x"],
        pw["v"],
        case.fit,
        cause,
        explained,
        units,
        nom.period,
    )


def _learned_figure(case: Case, o: Outcome, fig: Path) -> None:
    nom, ext = o.nominal, o.extension
    units = case.record.meta.units or {}
    plot_learned(
        fig / "learned_force.png",
        case.record.t,
        nom.system,
        nom.values,
        ext.system,
        ext.values,
        o.pointwise,
        units,
    )


def _running_estimate_figure(case: Case, o: Outcome, fig: Path) -> None:
    """The weak form's running estimate over the record."""
    record, nom = case.record, o.nominal
    names, A0, y = weak_system(
        nom.system, nom.values, nom.s, case.weak_f, case.x_raw, nom.weak, case.mass_known
    )
    running = running_estimate(
        names, A0, y, nom.weak.centers, max(4 * nom.period, 3 * nom.weak.dt * (2 * nom.weak.half + 1))
    )
    plot_running_estimate(
        fig / "running_estimate.png",
        running,
        nom.values,
        case.fit,
        case.held,
        None if o.change_row is None else o.change_row.change,
        stiffness=case.stiff,
        signal=(record.t, case.x_raw),
    )


def _running_period_figure(case: Case, o: Outcome, fig: Path) -> None:
    """An accelerometer record's running period, with the amplitude model's own path."""
    if o.running is None:
        return
    record = case.record
    ground = record.meta.sensor_ground
    meas = record.a[:, 0] + (0.0 if ground is None else np.asarray(ground))
    plot_running_period(
        fig / "running_period.png",
        o.running,
        case.fit,
        case.held,
        signal=(record.t, meas),
        nominal_period=(o.modal or [{}])[0].get("period_s"),
        model=amplitude_path(case, o),
    )


def plot_learned(
    path: Path,
    t: np.ndarray,
    nominal: SDOFSystem,
    nominal_values: dict[str, float],
    ext: SDOFSystem,
    ext_values: dict[str, float],
    pw: dict[str, np.ndarray],
    units: dict,
) -> None:
    """The extended model's restoring force minus the nominal one (the learned force plus the
    shift of the nominal parameters that came with it) on the residual's band-limited signals."""
    x, v = pw["x"], pw["v"]  # on the record's samples: a time-dependent term (a change) evaluates right
    dev = ext.restoring_force(t, x, v, None, ext_values) - nominal.restoring_force(
        t, x, v, None, nominal_values
    )
    gx = np.linspace(x.min(), x.max(), 60)
    gv = np.linspace(v.min(), v.max(), 60)
    X, V = np.meshgrid(gx, gv)
    t_end = float(t[-1])  # the surface: the model as it stands at the end of the record
    F = ext.restoring_force(t_end, X, V, None, ext_values) - nominal.restoring_force(
        t_end, X, V, None, nominal_values
    )
    edge = max(1, len(x) // 50)
    inner = slice(edge, len(x) - edge)  # the band-limited ends ring
    plot_learned_force(path, x[inner], v[inner], pw["r"][inner], dev[inner], {"x": X, "v": V, "f": F}, units)


def amplitude_path(case: Case, o: Outcome) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """An amplitude-dependent extension's own period and damping ratio through the record (t,
    period, zeta): the equivalent-linear structure at the envelope its simulated response
    carries (the free run the gain was measured on), beside the windows' fits. None without
    such a term."""
    system, values = o.extension.system, o.extension.values
    term = next((t for t in getattr(system, "terms", []) if isinstance(t, AmplitudeSoftening)), None)
    if term is None:
        return None
    run = (o.sims or {}).get("extended") or case.free_response(system, values, float(o.nominal.s.v[0]))
    e = run["z"][:, list(system.latent_names).index(term.name)]
    k, c = term.at_envelope(values, e)
    m = float(values.get("m", 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        return case.record.t, 2 * np.pi * np.sqrt(m / k), c / (2 * np.sqrt(k * m))


def _evidence_row(o: Outcome, cause: str | None) -> Evidence | None:
    """The fit that named ``cause``: the located change, the screening's row, or the output-error
    check's (an effect the weak form does not screen, the amplitude-dependent structure)."""
    if cause is None:
        return None
    if o.change_row:
        return o.change_row
    row = next((r for r in o.screening.ranking if r.effect == cause), None)
    checked = getattr(o.confirmation, "row", None)
    if row is None and checked and checked.effect == cause:
        return checked
    return row


def explained_force(
    nominal: SDOFSystem, values: dict[str, float], row: Evidence, s: Signals, pw: dict[str, np.ndarray]
) -> np.ndarray:
    """What the screening's fit says the residual is: the effect's force plus the change it
    brings to the nominal parameters (which had absorbed part of the effect), on the same
    band-limited signals as the residual."""
    p = {**values, **row.nominal_refit, **row.parameters}
    term = EFFECTS[row.effect].term(row.parameters, s.context())
    x, v = pw["x"], pw["v"]
    z = latent_path(term, s.t, x, None, p) if term.n_latent else None
    change = nominal.restoring_force(s.t, x, v, None, values) - nominal.restoring_force(s.t, x, v, None, p)
    inertia = (p["m"] - values["m"]) * pw["a"]  # nonzero only when the mass is identified
    total = term.force(s.t, x, v, z, p) - change + inertia
    return band_limited(total, float(s.t[1] - s.t[0]), float(pw["f_cut"]))[0]  # the residual's band


def running_summary(running: dict, case: Case) -> dict:
    """The running period and damping in numbers: every window, and the extremes beside the
    quietest and the strongest windows (what the figure shows, for a table)."""
    t = np.asarray(running["t"])
    ok = np.isfinite(np.asarray(running["period"]))
    rows = {
        k: [None if not np.isfinite(v) else float(v) for v in np.asarray(running[k])]
        for k in running
        if k != "variation"
    }
    out: dict = {"windows": rows, "variation": running.get("variation")}
    if ok.sum() >= 2:
        peak = np.asarray(running["peak"])
        strong, quiet = (
            int(np.nanargmax(np.where(ok, peak, -np.inf))),
            int(np.nanargmin(np.where(ok, peak, np.inf))),
        )
        longest = int(np.nanargmax(np.where(ok, running["period"], -np.inf)))
        out.update(
            {
                "period_strongest_window": float(running["period"][strong]),
                "t_strongest_window": float(t[strong]),
                "period_quietest_window": float(running["period"][quiet]),
                "t_quietest_window": float(t[quiet]),
                "period_longest": float(running["period"][longest]),
                "t_period_longest": float(t[longest]),
                "period_last_window": float(np.asarray(running["period"])[ok][-1]),
                "damping_strongest_window": float(running["damping"][strong]),
                "damping_last_window": float(np.asarray(running["damping"])[ok][-1]),
            }
        )
    return out
