"""The diagnosis loop: what does the nominal model get wrong, why, and what does fixing it gain?

1. a data-driven start, then the nominal model on the fitting part (``identify``: PIDynNet,
   then optionally an output-error polish);
2. the force it cannot explain, screened against the effect library
   (``pidyn.discrepancy.screening``): a cause, or ``none``; an effect the weak-form screening
   leans to without deciding is fitted by output error and named when the simulated response
   decides for it (``pidyn.discrepancy.confirm``);
3. the held-out check, and where the structure changed when the model fails there
   (``pidyn.discrepancy.changes``);
4. the model extended with the named effect and identified again, screened again, until
   nothing more passes the evidence (a structured remainder no library effect explains gets a
   learned force, ``pidyn.discrepancy.learned_fit``);
5. nominal and extended models simulated over the held-out part and compared.

``identify(node, folder, fit) -> (metrics, system, values)`` identifies the model a config
node describes on the fitting span ``fit`` and writes its run to ``folder``: the task passes
it in, so this package never imports the task layer.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.changes import (
    HELDOUT_BAND,
    SETTLE_PERIODS,
    HeldoutCheck,
    heldout_check,
    locate_step,
    simulation_sensitivity,
)
from pidyn.discrepancy.confirm import Confirmation, confirm, undecided
from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Signals
from pidyn.discrepancy.extend import (  # noqa: F401
    EXTENSION,
    build_system,
    check_fit,
    extension_node,
    release_held,
    system_node,
)
from pidyn.discrepancy.learned_fit import (
    LEARNED,
    learned_row,
    refuse_learned,
    save_unexplained,
    train_learned_force,
)
from pidyn.discrepancy.screening import EXCLUSIVE, Screening, screen
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.verdicts import Verdict, unearned_names
from pidyn.refine.output_error import fit_output_error, output_error_costs
from pidyn.reporting import nrmse
from pidyn.signals import dominant_period
from pidyn.simulate import simulate_response
from pidyn.systems.sdof import SDOFSystem
from pidyn.weak_form import WeakForm, measurement_noise, smooth_signals, velocity_noise

log = logging.getLogger(__name__)

IdentifyFn = Callable[[dict, Path, tuple[float, float]], tuple[dict, SDOFSystem, dict[str, float]]]

#: what each step keeps of the row that named its effect
ROW_EVIDENCE = ("score", "delta_bic", "explained", "cv_gain", "heldout_gain", "force_share", "source")
#: what each step keeps of the next screening's rows: the evidence behind the next name
STEP_EVIDENCE = (
    "effect",
    "score",
    "delta_bic",
    "explained",
    "cv_gain",
    "heldout_gain",
    "force_share",
    "passes",
    "persists",
    "heldout_miss",
    "heldout_small",
    "note",
    "parameters",
    "source",
)


def check_diagnosable(system) -> None:
    """A named refusal for a model the diagnosis cannot extend (before any record is read)."""
    if getattr(system, "modal_coordinates", False):
        raise ValueError(
            f"system '{system.name}': the diagnosis extends force laws in physical coordinates (a single "
            "degree of freedom or a shear building's storeys), and modes have none; diagnose with "
            "system=linear, identify the modes with train.py"
        )


def split_spans(record: Record, fit_share: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Fitting and held-out time spans: the record's own split if it has one, else a share."""
    sp = (record.meta or {}).get("split")
    if sp:
        return (float(sp["fit"][0]), float(sp["fit"][1])), (float(sp["heldout"][0]), float(sp["heldout"][1]))
    if not 0.1 <= fit_share <= 0.95:
        raise ValueError(f"diagnosis.fit_share must lie in [0.1, 0.95], got {fit_share}")
    t0, t1 = float(record.t[0]), float(record.t[-1])
    cut = t0 + fit_share * (t1 - t0)
    return (t0, cut), (cut, t1)


@dataclass
class Case:
    """One diagnosis: the record and its split, the nominal system and its config node, the
    settings, and how a model is identified."""

    record: Record
    base: SDOFSystem
    base_node: dict
    effects: dict
    settings: DiagnosisSettings
    mass: float | None
    fit: tuple[float, float]
    held: tuple[float, float]
    run_dir: Path
    identify: IdentifyFn

    @property
    def mass_known(self) -> bool:
        return self.mass is not None

    @property
    def thresholds(self):
        return self.settings.thresholds

    @property
    def x_raw(self) -> np.ndarray:
        """The displacement: measured, or integrated from accelerometers (``accelerometers.motion_view``)."""
        if self.record.x is not None:
            return self.record.x[:, 0]
        return np.asarray(self.record.meta["motion"]["x"], float)

    @property
    def weak_f(self) -> np.ndarray:
        """The excitation the weak form pairs with ``x_raw``: high-passed alike on an accelerometer record
        (identification and output error take the record's own, unfiltered)."""
        motion = (self.record.meta or {}).get("motion")
        return self.record.f if motion is None else np.asarray(motion["f"], float)

    @property
    def v_raw(self) -> np.ndarray | None:
        if self.record.v is not None:
            return self.record.v[:, 0]
        motion = (self.record.meta or {}).get("motion")
        return None if motion is None else np.asarray(motion["v"], float)

    @property
    def stiff(self) -> str:
        return self.base.stiffness_name

    def mask(self, span: tuple[float, float]) -> np.ndarray:
        return (self.record.t >= span[0]) & (self.record.t <= span[1])

    def signals(self, period: float, k_nom: float, mass: float) -> tuple[Signals, WeakForm]:
        """Smoothed x, x' and the weak form, on the time scale of ``period``."""
        r = self.record
        v_raw = self.v_raw
        xs, vs = smooth_signals(r.t, self.x_raw, v_raw, period)
        return (
            Signals(
                r.t,
                xs,
                vs,
                mass,
                k_nom,
                self.stiff,
                t_fit_end=self.fit[1],
                v_noise=velocity_noise(r.t, self.x_raw, v_raw, period),
            ),
            WeakForm.for_record(r.t, period),
        )

    def screen(
        self,
        system: SDOFSystem,
        values: dict[str, float],
        s: Signals,
        weak: WeakForm,
        effects: dict | None = None,
    ) -> Screening:
        return screen(
            system,
            values,
            s,
            self.weak_f,
            self.x_raw,
            weak,
            self.fit[1],
            self.mass_known,
            effects=self.effects if effects is None else effects,
            thresholds=self.thresholds,
        )

    def free_run(self, system: SDOFSystem, values: dict[str, float], v0: float) -> np.ndarray:
        """The model from the measured initial state over the whole record."""
        return self.free_response(system, values, v0)["x"][:, 0]

    def free_response(self, system: SDOFSystem, values: dict[str, float], v0: float) -> dict[str, np.ndarray]:
        """``free_run``'s x, v and a (relative) over the whole record."""
        y0 = np.zeros(system.n_state)
        y0[0], y0[1] = float(self.x_raw[0]), v0
        return simulate_response(system, values, self.record, int(self.settings.substeps), y0)

    def noise_std(self, measured: np.ndarray, period: float) -> float:
        """The measurement noise of ``measured``: of an accelerometer, what the record says of it (the
        simulated noise level, or the sensor's RMS before the shaking), since a smoother's residual
        reads an acceleration's broadband content as noise; else the smoother's estimate."""
        meta = self.record.meta or {}
        if self.from_accelerometers:
            level = (meta.get("noise_levels") or {}).get("a")
            if level is not None:
                absolute = measured + np.asarray(meta.get("sensor_ground", self.record.f), float)
                return float(level) * float(np.sqrt(np.mean(absolute**2)))
            pre = (meta.get("pre_event_rms") or {}).get("outputs")
            if pre:
                return float(pre[0])
        return measurement_noise(self.record.t, measured, period)

    @property
    def from_accelerometers(self) -> bool:
        """The record's motion was integrated from accelerations (``accelerometers.motion_view``)."""
        return "accelerometers" in (self.record.meta or {})


def prepare(
    record: Record,
    base: SDOFSystem,
    base_node: dict,
    settings: DiagnosisSettings,
    mass: float | None,
    run_dir: Path,
    identify: IdentifyFn,
) -> Case:
    """The settings checked against the library and the nominal system, the fit / held-out split."""
    wanted = list(settings.effects) if settings.effects else list(LIBRARY)
    unknown = set(wanted) - set(EFFECTS)
    if unknown:
        raise ValueError(
            f"diagnosis.effects: unknown effect(s) {sorted(unknown)}; the library has {sorted(EFFECTS)}"
        )
    effects = {n: EFFECTS[n] for n in wanted}
    if not isinstance(base, SDOFSystem):
        raise ValueError(f"diagnosis needs a single-degree-of-freedom nominal system, got '{base.name}'")
    already = {t.name for t in base.terms} & set(effects)
    if already:  # an effect the nominal model already has cannot be what it misses
        log.info("not screening %s: already in the nominal model", sorted(already))
        effects = {n: e for n, e in effects.items() if n not in already}
    if mass is None and record.excitation == "ground":
        raise ValueError(
            "data.mass is null, but a ground-excited record cannot reveal the mass "
            "(m x'' + ... = -m ag is homogeneous in m): give the mass"
        )
    fit, held = split_spans(record, float(settings.fit_share))
    log.info(
        "diagnosing '%s' with nominal '%s': fit %.4g-%.4g s, held out %.4g-%.4g s",
        record.name,
        base.name,
        *fit,
        *held,
    )
    run_dir.mkdir(parents=True, exist_ok=True)
    return Case(record, base, base_node, effects, settings, mass, fit, held, run_dir, identify)


@dataclass
class Nominal:
    node: dict
    system: SDOFSystem
    values: dict[str, float]
    metrics: dict
    polish_note: str | None
    s: Signals
    weak: WeakForm
    period: float


@dataclass
class Outcome:
    """Everything the summary and the figures are made of."""

    nominal: Nominal
    screening: Screening
    check: HeldoutCheck
    change_row: dict | None
    extension: dict
    causes: list[str]
    cause: str | None
    forced: bool
    confirmation: Confirmation | None
    pointwise: dict
    x_nom: np.ndarray
    x_ext: np.ndarray | None
    sims: dict = field(
        default_factory=dict
    )  # nominal / extended: x, v, a over the record (accelerometer records)
    modal: list[dict] | None = None  # the nominal model's modes with 95 % intervals
    running: dict | None = None  # period and damping window by window (accelerometer records)


def run(case: Case) -> Outcome:
    """Steps 1-5 on a prepared case."""
    values0, period = starting_point(case)
    nom = identify_nominal(case, values0, period)
    from pidyn.discrepancy.residual import unexplained_force

    sc = case.screen(nom.system, nom.values, nom.s, nom.weak)
    pointwise = unexplained_force(nom.system, nom.values, case.record.t, case.x_raw, case.weak_f, nom.period)
    forced = case.settings.force_effect
    log.info("screening: %s", ", ".join(f"{r['effect']} {r['score']:.1f}" for r in sc.ranking[:4]))
    # does the nominal model hold on the held-out part? if not, when did the structure change?
    x_nom = case.free_run(nom.system, nom.values, float(nom.s.v[0]))
    check, change_row = check_heldout(case, nom, sc, x_nom, bool(forced))
    running = running_period(case, nom)
    cause, confirmation, change_row = _first_cause(case, nom, sc, check, change_row, forced, running)
    if (
        case.from_accelerometers
    ):  # the period that moves beyond its windows' intervals refutes one linear model
        structured = check.failed or bool(running and running.get("variation", {}).get("varies"))
    else:
        structured = sc.verdict == Verdict.UNEXPLAINED or check.failed
    if cause is None and case.settings.learn_unexplained and not forced and structured:
        cause = LEARNED  # structured, but nothing in the library explains it: learn the force
    row = _cause_row(cause, sc, change_row, confirmation)
    ext = names_earn_or_learn(
        case, nom, sc, extend_until_explained(case, nom, cause, row, bool(forced)), bool(forced)
    )
    causes = ext["causes"] if case.settings.extend else ([] if cause is None else [cause])
    x_ext = (
        case.free_run(ext["system"], ext["values"], float(nom.s.v[0])) if ext["system"] is not None else None
    )
    sims = _acceleration_sims(case, nom, ext) if case.from_accelerometers else {}
    return Outcome(
        nom,
        sc,
        check,
        change_row,
        ext,
        causes,
        cause,
        bool(forced),
        confirmation,
        pointwise,
        x_nom,
        x_ext,
        sims,
        nominal_modes(case, nom),
        running,
    )


def _first_cause(
    case: Case, nom: Nominal, sc, check, change_row: dict | None, forced, running: dict | None = None
) -> tuple[str | None, Any, dict | None]:
    """The cause to extend with first (a located change, a forced effect, the screening's
    choice), the output-error confirmation where the simulated response decides, and the
    located change that survives it. A period that moves through the record (``running``) adds
    the amplitude-dependent structure to the candidates."""
    cause = change_row["effect"] if change_row is not None else (forced or sc.cause)
    confirmation = None
    if case.from_accelerometers and not forced and (change_row is None or not check.failed):
        # integrated accelerations are a poor measurement of the motion: the weak form proposes, output
        # error on the accelerations decides among every effect it could fit, a change it located in time
        # included while the nominal model holds on the held-out part (a 73 % stiffness loss that the
        # weak form found on a Painter Street record fitted to 3 % and predicted no better)
        extra = [] if change_row is None else [_change_candidate(change_row)]
        if running and running.get("variation", {}).get("varies") and not case.settings.effects:
            extra.append(_amplitude_candidate())  # (a user's list of effects screens it where it names it)
        confirmation = confirm_undecided(
            case, nom.system, nom.values, nom.node, sc, nom.s, 1, everything=True, extra=extra
        )
        cause = None if confirmation.row is None else confirmation.row["effect"]
        if change_row is not None and cause != change_row["effect"]:
            log.info("the output error does not confirm the change the weak form located: none is named")
            change_row = None
    elif cause is None and not forced and sc.verdict == Verdict.NONE:
        # an effect the weak form leans towards without deciding: the simulated response decides
        confirmation = confirm_undecided(case, nom.system, nom.values, nom.node, sc, nom.s, 1)
        if confirmation.row is not None:
            cause = confirmation.row["effect"]
    return cause, confirmation, change_row


def _change_candidate(change_row: dict) -> dict:
    """A located change as one candidate of the output-error check: started where the weak form
    put it, its time free (no ``change`` key, so nothing is held), its location kept for the record."""
    return {
        "effect": change_row["effect"],
        "score": change_row["score"],
        "parameters": dict(change_row["parameters"]),
        "nominal_refit": {},
        "located": change_row["change"].to_dict(),
    }


#: the amplitude-dependent structure (``effects.Amplitude``), tried where the period moves
AMPLITUDE = "amplitude_softening"


def _amplitude_candidate() -> dict:
    """The amplitude-dependent structure as a candidate of the output-error check, started at a
    small softening and a time constant of a second (on the 1992 Petrolia records the fits from
    0.5 and 2 s ended together; the weak form does not score it: ``score`` None)."""
    return {
        "effect": AMPLITUDE,
        "score": None,
        "parameters": {"soft": 0.1, "gain": 0.1, "tau": 1.0},
        "nominal_refit": {},
    }


def _cause_row(cause: str | None, sc, change_row: dict | None, confirmation) -> dict | None:
    """The evidence row the extension starts from: the learned force's, the located change's,
    the confirmation's or the screening's."""
    if cause is None:
        return None
    if cause == LEARNED:
        return learned_row(sc.structure)
    if change_row:
        return change_row
    if confirmation and confirmation.row:
        return confirmation.row
    return next(r for r in sc.ranking if r["effect"] == cause)


def _acceleration_sims(case: Case, nom: Nominal, ext: dict) -> dict:
    """The nominal and extended models' responses: the gain is measured on the accelerations, as
    the sensors read them."""
    v0 = float(nom.s.v[0])
    return {
        "nominal": case.free_response(nom.system, nom.values, v0),
        "extended": None if ext["system"] is None else case.free_response(ext["system"], ext["values"], v0),
    }


def running_period(case: Case, nom: Nominal) -> dict | None:
    """On an accelerometer record: the period and damping window by window by output error
    (``pidyn.discrepancy.running``), windows of about twelve periods (at least 2 s) every quarter
    window: the test of a moving period picks windows a full width apart from them, and a coarser
    step leaves a short record fewer to pick (a half-width step left a 20 s Painter Street record
    two with motion, where the quarter-width one found the period moving)."""
    if not case.from_accelerometers:
        return None
    from pidyn.discrepancy.running import period_varies, running_modes

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
    out["variation"] = period_varies(out, width)
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
    from pidyn.refine import RefineSettings, refine
    from pidyn.systems.modal import modes_with_intervals

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
    fitted = ((case.record.meta or {}).get("accelerometers") or {}).get("nominal")
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


def heldout_test(case: Case, nom: Nominal, x_nom: np.ndarray) -> HeldoutCheck:
    """The calibrated held-out test of the nominal model (``pidyn.discrepancy.changes``): on the
    displacement, or on an accelerometer record the acceleration, as the sensors read it."""
    kind = "a" if case.from_accelerometers else "x"
    if case.from_accelerometers:
        meas = case.record.a[:, 0]
        sim = case.free_response(nom.system, nom.values, float(nom.s.v[0]))["a"][:, 0]
    else:
        meas, sim = case.x_raw, x_nom

    def simulate(p: dict[str, float]) -> np.ndarray:  # the forced response, from rest
        return simulate_response(nom.system, {**nom.values, **p}, case.record, int(case.settings.substeps))[
            kind
        ][:, 0]

    # how the prediction moves with the fitted parameters: their uncertainty widens what a correct
    # model may leave on the held-out part (the forced response's sensitivities: a free run's start
    # from a noisy measured state would read as information the record does not hold)
    names = [s.name for s in nom.system.param_specs() if s.trainable and s.name in nom.values]
    check = heldout_check(
        meas,
        sim,
        case.mask(case.fit),
        case.mask(case.held),
        case.noise_std(meas, nom.period),
        level=float(case.settings.changes.heldout_level),
        sensitivity=simulation_sensitivity(simulate, nom.values, names),
        band=(case.record.dt, HELDOUT_BAND / nom.period),
        settle=int(round(SETTLE_PERIODS * nom.period / case.record.dt)),
    )
    return check


def check_heldout(
    case: Case, nom: Nominal, sc: Screening, x_nom: np.ndarray, forced: bool
) -> tuple[HeldoutCheck, dict | None]:
    """The held-out failure check, and where the structure changed when the data say it did
    (a located change moves ``case.fit`` / ``case.held`` to the change point). On an
    accelerometer record the check compares accelerations, as the sensors read them."""
    check = heldout_test(case, nom, x_nom)
    log.info("%s", check.sentence())
    time_effects = {
        n: p_
        for n, p_ in {"stiffness_loss": case.stiff, "damping_change": "c"}.items()
        if n in case.effects and p_ in nom.values
    }
    if forced or not time_effects or not ((check.failed and sc.cause is None) or sc.cause in time_effects):
        return check, None
    change, case.fit, case.held = locate_step(
        nom.system,
        nom.values,
        nom.s,
        case.weak_f,
        case.x_raw,
        nom.weak,
        case.fit,
        case.held,
        case.mass_known,
        {n: p_ for n, p_ in time_effects.items() if sc.cause in (None, n)},
        case.thresholds,
        bool(check.failed and sc.cause is None),
    )
    if change is None:
        return check, None
    log.info("%s", change.sentence())
    return check, {
        "effect": change.effect,
        "parameters": change.effect_parameters(),
        "nominal_refit": {},
        "score": -change.delta_bic,
        "change": change,
    }


def extend_until_explained(
    case: Case, nom: Nominal, cause: str | None, row: dict | None, forced: bool
) -> dict[str, Any]:
    """Extend the model with ``cause``, identify it (PIDynNet, polish), screen the extended
    model against the effects not yet in it, and repeat while one passes the thresholds, up to
    ``diagnosis.max_effects``. Each step's evidence is kept; the last model carries every
    named effect. Step k's run is in ``extended/`` (k = 1) or ``extended_<k>/``."""
    st = case.settings
    out: dict[str, Any] = {
        "system": None,
        "values": None,
        "metrics": None,
        "causes": [],
        "steps": [],
        "note": None,
        "refused": None,
        "learned_fit": None,
    }
    node, values = nom.node, nom.values
    limit = 1 if forced else int(st.max_effects)
    while cause is not None and row is not None and st.extend:
        step = _extension_step(case, nom, node, values, cause, row, out)
        if step is None:  # a learned force that predicts the held-out part worse: not kept
            break
        node, values, system = step
        k = len(out["causes"])
        if k >= limit:
            if not forced:
                log.info("stopping at diagnosis.max_effects=%d effects", limit)
            break
        if cause == LEARNED:
            break  # the learned force takes whatever is left: nothing to screen after it
        present = set(out["causes"]) | {t.name for t in system.terms}
        blocked = set().union(*[g for g in EXCLUSIVE if g & present])
        remaining = {n: e for n, e in case.effects.items() if n not in present | blocked}
        if not remaining:
            break
        cause, row = next_cause(case, system, values, node, remaining, out, nom.s, nom.weak)
        if cause == LEARNED and LEARNED in out["causes"]:
            break
    return out


def names_earn_or_learn(
    case: Case, nom: Nominal, sc: Screening, ext: dict[str, Any], forced: bool
) -> dict[str, Any]:
    """The library names of an extension must earn their place together (``unearned_names``, on
    the held-out errors the diagnosis reports): the members of a pair may help only together (a
    gap alone once predicted 1.82 -> 2.17, gap and friction 0.99). When they do not, the extension
    is not kept (``unearned``, with its steps) and a learned force is tried from the nominal model
    in their place; a forced effect's model is kept, its name still refused."""
    names = [c for c in ext["causes"] if c != LEARNED]
    if not names or ext["system"] is None:
        return ext
    refused = unearned_names(names, heldout_errors(case, nom, ext), case.thresholds)
    if refused is None or forced:
        return {**ext, "unearned": refused}
    log.info("%s", refused["note"])
    learned = case.settings.learn_unexplained and LEARNED not in ext["causes"]
    new = extend_until_explained(
        case, nom, LEARNED if learned else None, learned_row(sc.structure) if learned else None, False
    )
    new["unearned"] = {**refused, "steps": ext["steps"]}
    return new


def heldout_errors(case: Case, nom: Nominal, ext: dict[str, Any]) -> dict[str, float | None]:
    """The nominal and extended models' held-out NRMSE as ``diagnosis.json``'s ``gain`` gives it:
    of the displacement, or of the accelerations as the sensors read them."""
    held = case.mask(case.held)
    sims = _acceleration_sims(case, nom, ext)
    if case.from_accelerometers:
        from pidyn.discrepancy.accelerometers import acceleration_gain

        gain = acceleration_gain(case.record, sims, held)
        return {"nominal": gain["nominal"], "extended": gain["extended"]}
    return {k: None if s is None else nrmse(s["x"][held, 0], case.x_raw[held]) for k, s in sims.items()}


def _extension_step(
    case: Case, nom: Nominal, node: dict, values: dict[str, float], cause: str, row: dict, out: dict[str, Any]
) -> tuple[dict, dict[str, float], SDOFSystem] | None:
    """Step k: the current model extended with ``cause``, identified, polished (and a learned
    force trained on the response); recorded in ``out``. None when a learned force is refused."""
    st, record, s = case.settings, case.record, nom.s
    if row.get("score") is not None and not np.isfinite(row["score"]):
        raise ValueError(f"effect '{cause}' has no physical fit to this record ({row.get('note')})")
    k = len(out["causes"]) + 1
    if cause == LEARNED:  # start the network at the force the current model cannot explain
        path = save_unexplained(
            case.run_dir / f"unexplained_{k}.npz",
            record,
            build_system(node),
            values,
            case.x_raw,
            case.fit,
            f=case.weak_f,
        )
        row = {**row, "parameters": {"init_from": str(path)}}
    ext_node = extension_node(node, values, cause, row, s.context(), k, case.mass_known)
    folder = case.run_dir / ("extended" if k == 1 else f"extended_{k}")
    metrics, system, ext_values = case.identify(ext_node, folder, case.fit)
    trained = cause == LEARNED and st.learned.output_error
    if st.polish:  # a held change time is refined here, from where the search put it; a learned force's
        # model only briefly: its training on the simulated response (the physical parameters with the
        # weights) follows and the held-out part decides (on a Painter Street record 100 evaluations, 110 s,
        # moved the cost by 3e-4)
        budget = int(st.polish_max_nfev) if trained else None
        check = None if cause == LEARNED else check_fit(values, row, k)  # the fit that named the effect
        ext_values, out["note"] = polish(
            case, build_system(release_held(ext_node)), ext_values, budget, check
        )
    if trained:
        ext_values, out["learned_fit"] = train_learned_force(
            record, system, ext_values, s, case.fit, st.learned, folder
        )
    errors = None
    if cause == LEARNED:
        out["refused"], errors = refuse_learned(
            record,
            build_system(node),
            values,
            system,
            ext_values,
            case.x_raw,
            float(s.v[0]),
            case.held,
            int(st.substeps),
            folder,
        )
        if out["refused"] is not None:  # a network that fits the fitting part but predicts worse
            return None
    out["causes"].append(cause)
    out["steps"].append(_step_record(k, cause, folder, system.describe(ext_values), row, errors))
    out.update(system=system, values=ext_values, metrics=metrics)
    log.info("step %d: extended with %s: %s", k, cause, system.describe(ext_values))
    return ext_node, ext_values, system


def _step_record(k: int, cause: str, folder, equation: str, row: dict, errors) -> dict:
    """What ``diagnosis.json`` keeps of extension step ``k``."""
    return {
        "step": k,
        "effect": cause,
        "folder": folder.name,
        "equation": equation,
        "evidence": {
            **{key: row.get(key) for key in ROW_EVIDENCE},
            **({"heldout_nrmse": errors} if cause == LEARNED else {}),
        },
    }


def next_cause(
    case: Case,
    system: SDOFSystem,
    values: dict[str, float],
    node: dict,
    remaining: dict,
    out: dict[str, Any],
    s: Signals,
    weak: WeakForm,
) -> tuple[str | None, dict | None]:
    """Screen the model just extended against the effects not yet in it; what the weak form
    leaves undecided goes to the output-error check, and a structured remainder no library
    effect explains to the learned force. The evidence lands on the last step of ``out``."""
    k = len(out["causes"])
    sc = screen(
        system,
        values,
        s,
        case.weak_f,
        case.x_raw,
        weak,
        case.fit[1],
        case.mass_known,
        remaining,
        case.thresholds,
    )
    step = out["steps"][-1]
    step["next_ranking"] = [{k_: r.get(k_) for k_ in STEP_EVIDENCE if k_ in r} for r in sc.ranking]
    step["next_structure"] = dict(sc.structure)
    step["next_verdict"] = sc.verdict
    log.info(
        "screening the extended model: %s",
        ", ".join(f"{r['effect']} {r['score']:.1f}" for r in sc.ranking[:4] if r.get("score") is not None),
    )
    if case.from_accelerometers:  # output error on the accelerations decides (see ``run``)
        confirmation = confirm_undecided(case, system, values, node, sc, s, k + 1, everything=True)
        step["next_confirmation"] = confirmation.tested
        return (None, None) if confirmation.row is None else (confirmation.row["effect"], confirmation.row)
    if sc.cause is not None:
        return sc.cause, next(r for r in sc.ranking if r["effect"] == sc.cause)
    if sc.verdict == Verdict.NONE:  # the simulated response decides what the weak form leans to
        confirmation = confirm_undecided(case, system, values, node, sc, s, k + 1)
        step["next_confirmation"] = confirmation.tested
        if confirmation.row is not None:
            return confirmation.row["effect"], confirmation.row
    if sc.verdict == Verdict.UNEXPLAINED and LEARNED not in out["causes"] and case.settings.learn_unexplained:
        return LEARNED, learned_row(
            sc.structure
        )  # what remains is structured but no library effect: learn it
    return None, None


def confirm_undecided(
    case: Case,
    system: SDOFSystem,
    values: dict[str, float],
    node: dict,
    sc: Screening,
    s: Signals,
    k: int,
    everything: bool = False,
    extra: list[dict] | None = None,
) -> Confirmation:
    """The output-error check of the effects screening ``sc`` leaves undecided
    (``pidyn.discrepancy.confirm``); ``diagnosis.confirm.max_candidates`` = 0 turns it off.
    ``everything``: every effect the weak form could fit at all (an accelerometer record);
    ``extra``: candidates from elsewhere (a located change), tried after them."""
    st = case.settings
    if everything:
        candidates = [
            r
            for r in sc.ranking
            if r.get("score") is not None and np.isfinite(r["score"]) and not r.get("step_in_time")
        ]
    else:
        candidates = undecided(sc.ranking, case.thresholds, int(st.confirm.max_candidates))
    candidates = candidates + list(extra or [])
    if not candidates:
        return Confirmation()
    node = release_held(node)  # as in the polish: a located change time is refined with the rest
    ctx = s.context()

    def build(row: dict) -> Any:
        return build_system(extension_node(node, values, row["effect"], row, ctx, k, case.mass_known))

    # deciding, not confirming (an accelerometer record): each fit run to its end
    nfev = fit_budget(case) if everything else int(st.polish_max_nfev)
    return confirm(
        case.record,
        build_system(node),
        values,
        candidates,
        build,
        case.fit,
        case.held,
        case.thresholds,
        substeps=int(st.substeps),
        max_nfev=nfev,
        polish_seconds=st.polish_seconds,
        tol=float(st.polish_tol),
    )


def _fmt(values: dict[str, float]) -> str:
    return ", ".join(f"{k}={v:.5g}" for k, v in values.items())
