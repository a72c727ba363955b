"""The nominal model of a diagnosis: its data-driven start, its identification on the fitting part
(PIDynNet, then the output-error polish), its modes with intervals and its period window by window."""

from __future__ import annotations

import logging

import numpy as np

from pidyn.discrepancy.case import Case, Nominal
from pidyn.discrepancy.extend import system_node
from pidyn.discrepancy.running import period_varies, running_modes
from pidyn.refine import RefineSettings, refine
from pidyn.refine.output_error import fit_output_error, output_error_costs
from pidyn.reporting import nrmse
from pidyn.signals import dominant_period
from pidyn.simulate import simulate_response
from pidyn.systems.modal import modes_with_intervals
from pidyn.systems.sdof import SDOFSystem

log = logging.getLogger(__name__)


def running_period(case: Case, nom: Nominal) -> dict | None:
    """On an accelerometer record: the period and damping window by window by output error
    (``pidyn.discrepancy.running``), windows of about twelve periods (at least 2 s) every quarter
    window: the test of a moving period picks windows a full width apart from them, and a coarser
    step leaves a short record fewer to pick (a half-width step left a 20 s Painter Street record
    two with motion, where the quarter-width one found the period moving)."""
    if not case.from_accelerometers:
        return None

    width = max(12.0 * nom.period, 2.0)
    try:
        out = running_modes(
            case.record,
            nom.system,
            nom.values,
            width=width,
            step=width / 4,
            substeps=int(case.settings.substeps),
        )
    except ValueError as exc:
        log.info("no running period (%s)", exc)
        return None
    out["variation"] = period_varies(out, width, period=nom.period)
    v = out["variation"]
    if v.get("varies"):
        log.info(
            "the period moves through the record beyond its windows' intervals: %.3g s at %.3g s against "
            "%.3g s at %.3g s",
            v["longest"]["period"],
            v["longest"]["t"],
            v["shortest"]["period"],
            v["shortest"]["t"],
        )
    return out


def nominal_modes(case: Case, nom: Nominal) -> list[dict] | None:
    """The nominal model's modes with 95 % intervals: its fitting part refined by multiple shooting
    (from the polished values and the measured or integrated states) for the covariance."""
    try:
        seg = case.record.segment(*case.fit)
        res = refine(
            nom.system, seg, {"nominal": nom.values}, RefineSettings(states="measured", initial_state="free")
        )
        return modes_with_intervals(
            nom.system, {**nom.values, **res.params}, res.names, np.asarray(res.covariance)
        )
    except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
        log.info("no intervals for the nominal model's modes (%s)", exc)
        try:
            return modes_with_intervals(nom.system, nom.values)
        except (ValueError, KeyError):
            return None


def starting_point(case: Case) -> tuple[dict[str, float], float]:
    """A data-driven start for the nominal parameters (weak-form least squares, no effect) and
    the natural period, refined once from the start's own stiffness."""
    period = dominant_period(case.record.t[case.mask(case.fit)], case.x_raw[case.mask(case.fit)])
    values0 = {s.name: s.init for s in case.base.param_specs()}
    if case.mass_known:
        values0["m"] = float(case.mass)
    s, weak = case.signals(period, values0[case.stiff], values0.get("m", 1.0))
    values0.update(case.screen(case.base, values0, s, weak, effects={}).nominal_params)
    if values0.get(case.stiff, 0) > 0 and values0.get("m", 0) > 0:
        period = 2 * np.pi * np.sqrt(values0["m"] / values0[case.stiff])
        s, weak = case.signals(period, values0[case.stiff], values0.get("m", 1.0))
        values0.update(case.screen(case.base, values0, s, weak, effects={}).nominal_params)
    log.info("weak-form starting point: %s (natural period %.4g s)", _fmt(values0), period)
    return _accelerometer_start(case, values0, period)


def _accelerometer_start(
    case: Case, values0: dict[str, float], period: float
) -> tuple[dict[str, float], float]:
    """On an accelerometer record, the weak form's start or the accelerations' own fit (the data
    start and output error that combined the supports), whichever simulates the fitting part's
    accelerations better. The weak form reads an integrated motion, a poor measurement on a stiff
    structure: on a longitudinal Painter Street record it put the period at 0.96 s (negative
    damping) where the accelerations say 0.3 s."""
    view = case.record.meta.accelerometers
    fitted = view.nominal if view is not None else None
    if not fitted:
        return values0, period
    names = {s.name for s in case.base.param_specs()}
    scale = float(case.mass) / float(fitted.get("m", 1.0)) if case.mass_known else 1.0
    other = {**values0, **{k: float(v) * scale for k, v in fitted.items() if k in names and k != "m"}}
    if case.mass_known:
        other["m"] = float(case.mass)
    errors = [_fit_error(case, v) for v in (values0, other)]
    if not errors[1] < errors[0]:
        return values0, period
    log.info(
        "starting point from the accelerations' fit: %s (fitting-part NRMSE of a %.3g against the weak form's %.3g)",
        _fmt(other),
        errors[1],
        errors[0],
    )
    return other, 2 * np.pi * float(np.sqrt(other.get("m", 1.0) / other[case.stiff]))


def _fit_error(case: Case, values: dict[str, float]) -> float:
    """NRMSE of the simulated (relative) acceleration on the fitting part, from rest; inf for a
    start that is not a physical structure or that blows up."""
    if any(values.get(s.name, 1.0) <= 0 for s in case.base.param_specs() if s.transform == "log"):
        return float("inf")
    try:
        a = simulate_response(case.base, values, case.record, int(case.settings.substeps))["a"][:, 0]
    except (ValueError, KeyError):
        return float("inf")
    mask = case.mask(case.fit)
    if not np.all(np.isfinite(a[mask])):
        return float("inf")
    return float(nrmse(a[mask], case.record.a[mask, 0]))


def fit_budget(case: Case) -> int:
    """Output-error evaluations per fit: ``polish_max_nfev``; at least 100 on an accelerometer
    record, where output error decides between the models and every fit must run to its end (a
    Painter Street nominal stopped after 30 left a misfit its own refit cut elevenfold, and every
    library effect looked like a gain)."""
    st = case.settings
    return max(int(st.polish_max_nfev), 100) if case.from_accelerometers else int(st.polish_max_nfev)


def polish(
    case: Case,
    system: SDOFSystem,
    values: dict[str, float],
    max_nfev: int | None = None,
    alternative: dict[str, float] | None = None,
) -> tuple[dict[str, float], str]:
    """Output-error least squares on (part of) the fitting span, from ``values`` (``max_nfev``
    evaluations, default ``fit_budget``), or from ``alternative`` (another estimate of the same
    model) where that simulates the span better: a fit from a worse start can end in a worse
    local minimum, and the fitting part alone decides which start it takes."""
    st, fit = case.settings, case.fit
    seg_end = fit[1] if st.polish_seconds is None else min(fit[1], fit[0] + float(st.polish_seconds))
    seg = case.record.segment(fit[0], seg_end)
    trainable = {s.name for s in system.param_specs() if s.trainable}
    start, how = values, ""
    if alternative is not None:
        other = {**values, **alternative}
        starts = [{k: v for k, v in d.items() if k in trainable} for d in (values, other)]
        costs = output_error_costs(seg, system, starts, int(st.substeps))
        if costs[1] < costs[0]:
            start, how = (
                other,
                f" from the check's fit (cost {costs[1]:.4g} against the network's {costs[0]:.4g})",
            )
    res = fit_output_error(
        seg,
        system,
        init={k: v for k, v in start.items() if k in trainable},
        substeps=int(st.substeps),
        max_nfev=fit_budget(case) if max_nfev is None else int(max_nfev),
        tol=float(st.polish_tol),
    )
    out = dict(start)
    out.update(res.params)
    return out, f"output error on {seg.t[0]:.4g}-{seg.t[-1]:.4g} s{how}: {res.note}, {res.seconds:.1f} s"


def identify_nominal(case: Case, values0: dict[str, float], period: float) -> Nominal:
    """The nominal model on the fitting part: PIDynNet, then the output-error polish."""
    record = case.record
    node = system_node(
        case.base_node,
        {k: v for k, v in values0.items() if v > 0},
        values0["m"] if "m" in values0 else 1.0,
        not case.mass_known,
    )
    if record.excitation != case.base_node.get("excitation", record.excitation):
        node["excitation"] = record.excitation
    metrics, system, values = case.identify(node, case.run_dir / "nominal", case.fit)
    polish_note = None
    if case.settings.polish:
        values, polish_note = polish(case, system, values)
    s, weak = case.signals(period, values[case.stiff], values0.get("m", 1.0))
    s.mass = values["m"]
    return Nominal(node, system, values, metrics, polish_note, s, weak, period)


def _fmt(values: dict[str, float]) -> str:
    return ", ".join(f"{k}={v:.5g}" for k, v in values.items())
