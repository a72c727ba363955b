"""The diagnosis of a shear building, storey by storey: which storey, what effect, since when.

Floor accelerometers measure each storey's shear force without any model: with the floor
masses known, the shear carried by storey i is ``V_i = -sum_{j >= i} m_j a_j`` (absolute
accelerations), and the storey's restoring force must equal it, ``F_i(d_i, d_i') = V_i``,
whatever the other storeys do. So each storey is screened on its own, as a single degree of
freedom whose load is its measured shear:

1. the nominal (linear) building is identified on the fitting part (the start from the data,
   then the refinement: intervals for every parameter);
2. floors without a sensor take the nominal model's simulated acceleration (their share of the
   shear above a storey is what the model says it is);
3. each storey's drift and drift velocity are integrated from the floors' relative
   accelerations (spectral, high-passed with the shear alike, so a linear storey law holds
   exactly for the filtered signals) and its shear force is screened against the effect
   library in the weak form (``screening.screen`` with a unit "mass" whose inertia term is
   the drift's own acceleration: what remains is ``F_i = V_i``);
4. the strongest passing (effect, storey) extends the building by that storey term, the
   extended model is refined on the fitting part, and it is named only when it predicts the
   held-out floor accelerations better than the model it extends;
5. the extended model's storeys are screened again (the found term in its storey's nominal
   law), until nothing more passes or ``max_effects`` are named.

A storey whose force is clearly structured (a generic f(d, d') explains it in
cross-validation) while no library effect both passes and earns its held-out gain gives
``unexplained``, naming the storey; nothing structured gives ``none``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.case import split_spans
from pidyn.discrepancy.effects import EFFECTS, Signals
from pidyn.discrepancy.fit_test import fit_test
from pidyn.discrepancy.screening import Screening, screen
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.storey_learned import learned_storey_force
from pidyn.discrepancy.storey_nominal import fundamental_hz, heldout_nrmse, nominal_fit
from pidyn.discrepancy.storey_ranking import (
    floor_noise,
    measured_floors,
    rank_candidates,
    spring_shares,
    storey_order,
)
from pidyn.discrepancy.verdicts import Verdict
from pidyn.notes import note
from pidyn.params import positive
from pidyn.signals import integrate
from pidyn.simulate import simulate_response
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.shear_building import ShearBuilding, storey_param
from pidyn.systems.terms import LinearStiffness, ViscousDamping
from pidyn.weak_form import WeakForm, smooth_signals, velocity_noise

log = logging.getLogger(__name__)

#: the drifts are integrated above this share of the fundamental frequency. Twice-integrated
#: accelerometer noise grows as 1/f^3 below the corner, and a drift is a small difference of two
#: floors' motions. Measured on a 3-storey building under El Centro (2 % noise): a cubic spring
#: in storey 3 (a quarter of the storey force) scored -1.0 at 0.2 f1, 27 at 0.3, 53 at 0.4 and 72
#: at 0.5; a stop and a stiffness loss rose alike (52 -> 146, 79 -> 157); two clean buildings
#: stayed below 0.3 at every corner. At 0.1 f1 a clean building read as hysteretic everywhere
CORNER_SHARE = 0.5
#: the weak form's windows span this share of the fundamental period: a storey's drift carries
#: the higher modes too, and a stop that engages briefly is seen in short windows (the gap of
#: that building scored 13 at one period, 36-55 at half of it)
WINDOW_SHARE = 0.5


@dataclass
class StoreyView:
    """One storey seen as a single degree of freedom loaded by its measured shear."""

    storey: int
    t: np.ndarray
    drift: np.ndarray  # integrated, high-passed (m)
    drift_velocity: np.ndarray
    excitation: np.ndarray  # the weak form's f: -(shear + drift acceleration), filtered alike
    shear: np.ndarray  # the storey's shear force from the floor accelerations, filtered (N)
    measured_floors: list[int]


@dataclass
class Found:
    """An effect named in a storey: its term's parameters in the storey's SDOF names."""

    effect: str
    storey: int
    params: dict[str, float]
    row: dict
    ctx: dict


@dataclass
class BuildingDiagnosis:
    verdict: Verdict
    found: list[Found]
    nominal: dict
    extended: dict | None
    steps: list[dict]
    gain: dict
    unexplained_storey: int | None
    views: list[StoreyView]
    screenings: list[Screening]
    values: dict[str, float]
    corner_hz: float
    seconds: float
    notes: list[str] = field(default_factory=list)
    learned: dict | None = None  # the learned storey force of an unexplained verdict (storey_learned)


def floor_accelerations(
    record: Record, system: ShearBuilding, values: dict[str, float]
) -> tuple[np.ndarray, list[int]]:
    """Every floor's relative acceleration (N, n): measured where a sensor is, the model's elsewhere."""
    if record.a is None:
        raise ValueError(f"record '{record.name}': the building diagnosis needs floor accelerations (a1..aN)")
    a = np.array(record.a, float)
    measured = [j + 1 for j in range(a.shape[1]) if not np.isnan(a[:, j]).all()]
    if not measured:
        raise ValueError(f"record '{record.name}': no floor carries an accelerometer")
    missing = [j for j in range(a.shape[1]) if np.isnan(a[:, j]).all()]
    if missing:
        sim = simulate_response(system, values, record)["a"]
        for j in missing:
            a[:, j] = sim[:, j]
    return a, measured


def storey_views(
    record: Record, system: ShearBuilding, values: dict[str, float], corner: float
) -> list[StoreyView]:
    """Each storey's drift, drift velocity and shear (see the module's docstring)."""
    a, measured = floor_accelerations(record, system, values)
    ag = np.asarray(record.f, float)
    masses = np.array([values[f"m{j + 1}"] for j in range(system.n_dof)])
    absolute = a + ag[:, None]
    dt = record.dt
    views = []
    for i in range(system.n_dof):
        below = a[:, i - 1] if i > 0 else np.zeros(len(ag))
        dd = a[:, i] - below  # the drift's acceleration
        shear = -(absolute[:, i:] * masses[i:]).sum(1)
        d, v = (integrate(dd, dt, k, corner) for k in (2, 1))
        shear_f, dd_f = integrate(shear, dt, 0, corner), integrate(dd, dt, 0, corner)
        views.append(StoreyView(i + 1, record.t, d, v, -(shear_f + dd_f), shear_f, measured))
    return views


def storey_system(c: float, k: float, found: list[Found]) -> tuple[SDOFSystem, dict[str, float]]:
    """The storey's law as a unit-mass oscillator (``m d'' + c d' + k d (+ found terms) = -m f``)."""
    c, k = positive(c), positive(k)
    terms = [ViscousDamping(c), LinearStiffness(k)]
    values = {"m": 1.0, "c": c, "k": k}
    for f in found:
        terms.append(EFFECTS[f.effect].term(f.params, f.ctx))
        values.update({s.name: float(f.params.get(s.name, s.init)) for s in terms[-1].specs()})
    return SDOFSystem(terms, mass=1.0, name="storey"), values


def storey_signals(view: StoreyView, k: float, period: float, fit_end: float) -> tuple[Signals, WeakForm]:
    xs, vs = smooth_signals(view.t, view.drift, view.drift_velocity, period)
    noise = velocity_noise(view.t, view.drift, view.drift_velocity, period)
    return Signals(view.t, xs, vs, 1.0, k, "k", t_fit_end=fit_end, v_noise=noise), WeakForm.for_record(
        view.t, period
    )


def screen_storeys(
    views: list[StoreyView],
    values: dict[str, float],
    found: list[Found],
    period: float,
    fit_end: float,
    settings: DiagnosisSettings,
) -> list[Screening]:
    """Every storey's shear screened against the library (found terms in their storey's law)."""
    out = []
    for view in views:
        i = view.storey
        c, k = values[f"c{i}"], values[f"k{i}"]
        here = [f for f in found if f.storey == i]
        system, sv = storey_system(c, k, here)
        s, weak = storey_signals(view, k, period, fit_end)
        effects = {
            n: e
            for n, e in EFFECTS.items()
            if (n in settings.effects if settings.effects else e.library)
            and n not in {f.effect for f in here}
        }
        sc = screen(
            system,
            sv,
            s,
            view.excitation,
            view.drift,
            weak,
            fit_end,
            True,
            effects=effects,
            thresholds=settings.thresholds,
        )
        spring_shares(sc)
        out.append(sc)
    return out


#: a storey's damper below this share of the largest has collapsed; an extension starts it again
#: at ``RESTART`` of the median of the others
COLLAPSED, RESTART = 1e-6, 0.1


def building_with(
    system: ShearBuilding, values: dict[str, float], found: list[Found]
) -> tuple[ShearBuilding, dict[str, float]]:
    """The building with the found terms in their storeys, started at ``values`` and their estimates."""
    terms: dict[int, list] = {}
    start = dict(values)
    dampers = [f"c{i + 1}" for i in range(system.n_dof) if f"c{i + 1}" in start]
    largest = max((start[c] for c in dampers), default=0.0)
    # the median of those that have not collapsed (three of four had, on benchmark case 18)
    typical = float(np.median([start[c] for c in dampers if start[c] >= COLLAPSED * largest] or [0.0]))
    for c in dampers:
        # a damper the nominal fit ran to zero cannot come back in log space (its gradient is
        # proportional to it): a friction in storey 3 left c2 at 1e-12, and the extension then
        # drew a damper into storey 2 to put it back
        if start[c] < COLLAPSED * typical:
            start[c] = RESTART * typical
    for f in found:
        ctx = {**f.ctx, "stiffness": f"k{f.storey}", "damping": f"c{f.storey}"}
        term = EFFECTS[f.effect].term(f.params, ctx)
        terms.setdefault(f.storey, []).append(term)
        for s in term.specs():
            start[storey_param(s.name, f.storey)] = float(s.init)
    ext = system.linear_at(
        start, terms, f"{system.name}+" + "+".join(f"{f.effect}@{f.storey}" for f in found)
    )
    names = {s.name for s in ext.param_specs()}
    return ext, {k: v for k, v in start.items() if k in names}


def best_row(screenings: list[Screening]) -> tuple[int, dict] | None:
    """The (storey, row) of the strongest named cause over every storey: each storey's screening
    decides whether it names one (its evidence, pair and tie rules), the scores between storeys."""
    best = None
    for i, sc in enumerate(screenings, start=1):
        if sc.verdict != Verdict.DISCREPANCY or sc.cause is None:
            continue
        row = next(r for r in sc.ranking if r["effect"] == sc.cause)
        if best is None or (row["score"] or 0.0) > (best[1]["score"] or 0.0):
            best = (i, row)
    return best


def better(a: dict, b: dict, settings: DiagnosisSettings) -> bool:
    """Whether extension ``a`` beats ``b`` on the fitting part: a lower BIC by at least
    ``tie_delta_bic`` ("strong"), or, closer than that, fewer parameters (then the lower BIC).
    A stop fitted to a cubic spring in storey 3 came within 2.1 BIC units of the spring (and
    predicted the held-out part a little worse): two parameters where one does."""
    gap = b["fit_bic"] - a["fit_bic"]
    if abs(gap) >= float(settings.thresholds.tie_delta_bic):
        return gap > 0
    if a["n_params"] != b["n_params"]:
        return a["n_params"] < b["n_params"]
    return gap > 0


def leaning_rows(screenings: list[Screening], settings: DiagnosisSettings) -> list[tuple[int, dict]]:
    """(storey, row) of the effects the weak form leans to without deciding (0 < score <
    ``min_delta_bic``, no rule against them), strongest first, at most ``confirm.max_candidates``."""
    th = settings.thresholds
    rows = [
        (i, r)
        for i, sc in enumerate(screenings, start=1)
        for r in sc.ranking
        if r.get("score") is not None
        and 0.0 < r["score"] < th.min_delta_bic
        and r.get("persists", True)
        and not r.get("heldout_miss")
    ]
    rows.sort(key=lambda ir: -ir[1]["score"])
    return rows[: int(settings.confirm.max_candidates)]


def misfit_rows(
    study: Study,
    current: dict,
    found: list[Found],
    views: list[StoreyView],
    screenings: list[Screening],
    leaning: list[tuple[int, dict]],
    min_share: float = 0.0,
) -> list[tuple[int, dict]]:
    """For a model that fails the fit test: every storey's effects (the leaning ones, already
    tried, left out) ranked by the score test on the simulated floor accelerations
    (``storey_ranking``), the best ``confirm.misfit_candidates``. The weak form on
    twice-integrated drifts loses effects the floors still show (a friction in a top storey
    scored -2.3 there), so its own scores are no order for them. After a named effect only the
    other storeys' effects, and none when the best removes less than ``min_share`` of the
    squared residual (linearised)."""
    named = {f.storey for f in found}
    rows = [
        (i, r)
        for i, sc in enumerate(screenings, start=1)
        for r in sc.ranking
        if i not in named and not any(j == i and q is r for j, q in leaning)
    ]
    ranked = [c for c in rank_candidates(study, current, found, views, rows) if c.chi2 > 0]
    if ranked and ranked[0].share < min_share:
        log.info(
            "score test: the best candidate (%s in storey %d) removes %.0f%% of the squared residual, below "
            "%.0f%%: no effect searched beside the named ones",
            ranked[0].row["effect"],
            ranked[0].storey,
            100 * ranked[0].share,
            100 * min_share,
        )
        return []
    for c in ranked[:6]:
        log.info(
            "score test: %s in storey %d removes %.0f (%.0f%% of the squared residual), linearised",
            c.row["effect"],
            c.storey,
            c.chi2,
            100 * c.share,
        )
    return [(c.storey, c.row) for c in ranked[: int(study.settings.confirm.misfit_candidates)]]


def excess2(test: dict) -> float:
    """The fit test's squared excess over the noise, summed over the floors."""
    return float(sum(v["excess"] ** 2 for v in test["channels"].values()))


def confirm_leaning(
    study: Study,
    current: dict,
    found: list[Found],
    views: list[StoreyView],
    rows: list[tuple[int, dict]],
    misfit: dict | None = None,
) -> dict | None:
    """The output-error check of ``rows`` (storey, weak-form row): each effect's extension refined
    on the fitting part and named when its free simulation beats the current model's by
    ``min_delta_bic`` (BIC, in the nominal fit's noise units) and it predicts the held-out floor
    accelerations better. Twice-integrated drifts are noisy regressors, and a weak form on them
    loses power that the simulated floor accelerations keep. ``misfit``: the current model's
    failed fit test, when ``rows`` are tried for it alone (``misfit_rows``); such an effect must
    also remove ``confirm.misfit_share`` of the fitting part's excess over the noise (a
    hysteretic top storey drew a quadratic damper in storey 1 that removed a tenth). The
    strongest such effect is returned, or None."""
    record, fit, settings = study.record, study.fit, study.settings
    base = fit_bic(record, current["system"], current["values"], fit, current["noise"])
    best = None
    for storey, row in rows:
        sig, _ = storey_signals(views[storey - 1], current["values"][f"k{storey}"], study.period, fit[1])
        cand = Found(row["effect"], storey, dict(row["parameters"]), row, sig.context())
        trial = study.extend(current, found, cand)
        gain = base - trial["report"]["fit_bic"]
        trial["report"].update(source="output_error", delta_bic_fit=gain)
        ok = gain >= float(settings.thresholds.min_delta_bic) and trial["accepted"]
        if misfit is not None:
            explained = 1.0 - excess2(study.fit_check(trial["current"])) / max(excess2(misfit), 1e-300)
            trial["report"].update(source="fit_test", misfit_explained=explained)
            ok = ok and explained >= float(settings.confirm.misfit_share)
        log.info(
            "output-error check of %s in storey %d (weak-form score %s): BIC gain %.1f on the fitting part%s",
            cand.effect,
            storey,
            score_text(row.get("score")),
            gain,
            "" if misfit is None else f", {trial['report']['misfit_explained']:.0%} of the misfit explained",
        )
        if ok and (best is None or gain > best["report"]["delta_bic_fit"]):
            best = trial
        if (
            ok
            and misfit is not None
            and trial["report"]["misfit_explained"] >= float(settings.confirm.misfit_done)
        ):
            break  # the rows come best first (the score test): what is left is too little for another
    return best


def close_rivals(screening: Screening, row: dict, settings: DiagnosisSettings) -> list[dict]:
    """The named row and every other passing effect of its storey less than ``min_delta_bic``
    below it in the weak form: the weak form does not decide between them (a stop and a cubic
    spring on a building scored 53 and 60), the output error on the fitting part does."""
    margin = float(settings.thresholds.min_delta_bic)
    out = [row]
    for r in screening.ranking:
        if r is row or not r.get("passes") or r.get("step_in_time") != row.get("step_in_time"):
            continue
        if (r["score"] or -np.inf) >= (row["score"] or 0.0) - margin:
            out.append(r)
    return out


def fit_bic(
    record: Record, system: ShearBuilding, values: dict[str, float], span: tuple[float, float], noise: dict
) -> float:
    """BIC of a model's free simulation on ``span``: every measured floor's acceleration
    residual in units of that floor's noise (the nominal refinement's), and its parameter count."""
    sim = simulate_response(system, values, record)["a"]
    mask = (record.t >= span[0]) & (record.t <= span[1])
    floors = measured_floors(record)
    r = (sim[mask][:, floors] - record.a[mask][:, floors]) / floor_noise(record, noise, mask)
    chi2, n = float(np.sum(r**2)), int(mask.sum()) * len(floors)
    k = sum(1 for s in system.param_specs() if s.trainable)
    return chi2 + k * float(np.log(max(n, 1))) if np.isfinite(chi2) else float("inf")


def structured_storey(screenings: list[Screening], settings: DiagnosisSettings) -> int | None:
    """The storey whose remaining force a generic f(d, d') explains best, if clearly structured."""
    gains = [(sc.structure.get("cv_gain") or 0.0, i) for i, sc in enumerate(screenings, start=1)]
    gain, storey = max(gains)
    return storey if gain >= settings.thresholds.min_structure_gain else None


@dataclass
class Study:
    """What every step of one building diagnosis shares."""

    record: Record
    system: ShearBuilding  # the nominal (linear) building
    settings: DiagnosisSettings
    refine_settings: Any
    fit: tuple[float, float]
    held: tuple[float, float]
    period: float = 0.0  # the weak form's window
    corner: float = 0.0  # the drifts' high-pass (Hz)
    #: the score test's simulations per model (``storey_ranking``): the learned force's storey
    #: order reuses those of the search that failed before it
    scores: dict = field(default_factory=dict)
    #: the fit test per model: the search, the first name's challenge and the verdict ask it of
    #: the same model
    fits: dict = field(default_factory=dict)

    def screen(self, current: dict, found: list[Found]) -> tuple[list[StoreyView], list[Screening]]:
        views = storey_views(self.record, current["system"], current["values"], self.corner)
        return views, screen_storeys(views, current["values"], found, self.period, self.fit[1], self.settings)

    def fit_check(self, current: dict) -> dict:
        system = current["system"]
        model = (tuple(t.name for t in system.terms), repr(sorted(current["values"].items())))
        if model not in self.fits:
            self.fits[model] = building_fit_test(
                self.record, system, current["values"], self.fit, self.settings
            )
        return self.fits[model]

    def extend(self, current: dict, found: list[Found], cand: Found) -> dict:
        from pidyn.discrepancy.storey_steps import try_extension  # (it builds on this module)

        return try_extension(
            self.record,
            self.system,
            current,
            found,
            cand,
            self.fit,
            self.held,
            self.settings,
            self.refine_settings,
        )


def diagnose_building(
    record: Record,
    system: ShearBuilding,
    settings: DiagnosisSettings,
    refine_settings: Any,
    start: dict | None = None,
    run_dir: Path | None = None,
) -> BuildingDiagnosis:
    """The loop of the module's docstring; ``system``: the nominal (linear) building; ``start``:
    its starting values (default: read from the data); ``run_dir``: where a learned storey
    force's weights go."""
    from pidyn.discrepancy.storey_steps import building_gain, next_step, refusal_notes

    t_wall = time.perf_counter()
    fit, held = split_spans(record, float(settings.fit_share))
    log.info("building diagnosis of '%s': fit %.4g-%.4g s, held out %.4g-%.4g s", record.name, *fit, *held)
    study = Study(record, system, settings, refine_settings, fit, held)
    nominal, current = nominal_state(study, start)
    found: list[Found] = []
    steps: list[dict] = []
    refused = None
    while len(found) < int(settings.max_effects) and settings.extend:
        views, screenings = study.screen(current, found)
        step = next_step(study, current, found, views, screenings)
        if step is None:
            break
        steps.append(step["report"])
        if not step["accepted"]:
            refused = step["report"]
            break
        found.append(step["found"])
        current = step["current"]
    views, screenings = study.screen(current, found)
    verdict, unexplained, notes, test = building_verdict(study, current, found, screenings)
    nominal["heldout_test"] = test
    notes = refusal_notes(refused) + notes
    learned = None
    if verdict == Verdict.UNEXPLAINED and settings.learn_unexplained:
        current, learned = _learned(study, current, found, (views, screenings), unexplained, run_dir)
    extended = _extended(current, found, bool(learned and learned["kept"]))
    return BuildingDiagnosis(
        verdict,
        found,
        nominal,
        extended,
        steps,
        building_gain(nominal, current, extended is not None),
        unexplained,
        views,
        screenings,
        current["values"],
        study.corner,
        time.perf_counter() - t_wall,
        notes,
        None
        if learned is None
        else {k: v for k, v in learned.items() if k not in ("system", "values", "heldout")},
    )


def _learned(
    study: Study,
    current: dict,
    found: list[Found],
    screened: tuple[list[StoreyView], list[Screening]],
    storey: int | None,
    run_dir: Path | None,
) -> tuple[dict, dict | None]:
    """The current model with a learned storey force when it is kept (``storey_learned``), and the
    report. Its storey: the structured one, else the ``learned.storeys`` the score test puts first."""
    period = 1.0 / fundamental_hz(current["system"], current["values"])
    storeys = [storey] if storey else None
    if storey is None and current["system"].n_dof > int(study.settings.learned.storeys):
        views, screenings = screened
        rows = [(i, r) for i, sc in enumerate(screenings, start=1) for r in sc.ranking]
        order = storey_order(study, current, found, views, rows)
        log.info("score test: the storeys in the order their candidates explain the misfit: %s", order)
        storeys = order[: int(study.settings.learned.storeys)] or None
    learned = learned_storey_force(study, current, storeys, run_dir, period, heldout_nrmse)
    if learned is not None and learned["kept"]:  # its storey: learned["storey"]
        current = {**current, "system": learned["system"], "values": learned["values"]}
        current["heldout"] = learned["heldout"]
    return current, learned


def _extended(current: dict, found: list[Found], learned_kept: bool) -> dict | None:
    """The extended model's entry: the named effects', or a kept learned force's."""
    if not found and not learned_kept:
        return None
    return {
        "system": current["system"].name,
        "params": current["values"],
        "intervals": current["result"].intervals if found else {},
        "storey_equations": current["system"].storey_equations(current["values"]),
    }


def building_verdict(
    study: Study, current: dict, found: list[Found], screenings: list[Screening]
) -> tuple[Verdict, int | None, list[str], dict | None]:
    """``discrepancy`` with a named effect; ``unexplained`` when a storey's force is structured
    and nothing earned its place, or when the nominal building fails the held-out test (with the
    storey, or None, and a note); else ``none``. With the held-out test's result when it ran."""
    settings = study.settings
    verdict, unexplained, notes, check = Verdict.NONE, None, [], None
    if found:
        verdict = Verdict.DISCREPANCY
    elif (structured := structured_storey(screenings, settings)) is not None:
        # a storey's force is clearly structured (a generic f(d, d') explains it in cross-validation)
        # and no library effect earned its place: a refused name is no evidence of nothing missing
        verdict = Verdict.UNEXPLAINED
        unexplained = structured
    else:
        # nothing named, nothing structured in the weak form: does the nominal building still predict
        # the floors' held-out accelerations as a correct model would? A model that fails there is
        # wrong, though the screening cannot say how
        check = building_heldout_test(study, current)
        check["fit_test"] = misfit = study.fit_check(current)
        if check["failed"]:
            verdict = Verdict.UNEXPLAINED
            notes.append(
                note(
                    "heldout_fails",
                    f"no library effect is named and no storey's force is structured in the weak form, but the "
                    f"nominal building fails the held-out test on floor(s) {check['failed_floors']} (least p "
                    f"{check['p_min']:.2g} against {check['level']:.2g} per floor): it is wrong, and the screening "
                    "cannot say how",
                )
            )
        elif misfit["failed"]:
            verdict = Verdict.UNEXPLAINED
            worst = misfit["channels"][misfit["worst"]]
            notes.append(
                note(
                    "fit_fails",
                    f"no library effect is named and the held-out test passes, but the nominal building does not fit "
                    f"its own fitting part down to the sensors' noise (floor(s) {misfit['failed_channels']}; "
                    f"{misfit['worst']}: NRMSE {worst['nrmse']:.3g} against noise {worst['noise']:.3g}, read above "
                    "the structural band): it is as wrong on both parts, so something is missing, or the nominal "
                    "fit ended in a poor local optimum",
                )
            )
    return verdict, unexplained, notes, check


def building_heldout_test(study: Study, current: dict) -> dict:
    """The calibrated held-out test (``pidyn.discrepancy.changes.heldout_check``) on every measured
    floor's relative acceleration, simulated from rest, with the sensitivities to the building's
    trainable parameters; a floor fails below the test's level shared among the floors
    (Bonferroni)."""
    from pidyn.discrepancy.changes import HELDOUT_BAND, SETTLE_PERIODS, heldout_check, simulation_sensitivity

    record, system, values = study.record, current["system"], current["values"]
    floors = measured_floors(record)
    names = [s.name for s in system.param_specs() if s.trainable and s.name in values]

    def simulate(p: dict[str, float]) -> np.ndarray:
        return simulate_response(system, {**values, **p}, record)["a"][:, floors].reshape(-1)

    n = len(record.t)
    jac = simulation_sensitivity(simulate, values, names).reshape(n, len(floors), len(names))
    sim = simulate(values).reshape(n, len(floors))
    f1 = fundamental_hz(system, values)
    fit = (record.t >= study.fit[0]) & (record.t <= study.fit[1])
    held = (record.t > study.fit[1]) & (record.t <= study.held[1])
    level = float(study.settings.changes.heldout_level) / max(len(floors), 1)
    p_values = {}
    for i, j in enumerate(floors):
        check = heldout_check(
            record.a[:, j],
            sim[:, i],
            fit,
            held,
            0.0,
            level=level,
            sensitivity=jac[:, i, :],
            band=(record.dt, HELDOUT_BAND * f1),
            settle=int(round(SETTLE_PERIODS / f1 / record.dt)),
        )
        p_values[f"a{j + 1}"] = check.p_value
    failed = [k for k, p in p_values.items() if p is not None and p < level]
    p_min = min((p for p in p_values.values() if p is not None), default=1.0)
    log.info("held-out test of the nominal building: least p %.3g against %.3g per floor", p_min, level)
    return {
        "p_values": p_values,
        "level": level,
        "p_min": p_min,
        "failed_floors": failed,
        "failed": bool(failed),
    }


def building_fit_test(
    record: Record, system: ShearBuilding, values: dict[str, float], span: tuple[float, float], settings
) -> dict:
    """The fit test (``pidyn.discrepancy.fit_test``) of every measured floor's absolute
    acceleration on ``span``, simulated from rest; the noise read above the model's modes."""
    from pidyn.systems.modal import linear_matrices, modal_properties

    sim = simulate_response(system, values, record)["a"]
    ag = np.asarray(record.f, float)
    mask = (record.t >= span[0]) & (record.t <= span[1])
    floors = measured_floors(record)
    meas = {f"a{j + 1}": record.a[mask, j] + ag[mask] for j in floors}
    pred = {f"a{j + 1}": sim[mask, j] + ag[mask] for j in floors}
    f_top = float(max(modal_properties(*linear_matrices(system, values))["frequency_hz"]))
    th = settings.fit_test
    return fit_test(
        meas,
        pred,
        {k: float(np.std(v)) for k, v in meas.items()},
        record.dt,
        f_top,
        float(th.rms_ratio),
        float(th.min_excess),
    )


def nominal_state(study: Study, start: dict | None) -> tuple[dict, dict]:
    """The nominal model (refined, its held-out and fitting-part errors) and the time scales it
    sets (``study.period``, ``study.corner``); the loop's first current model."""
    record, system = study.record, study.system
    values, res = nominal_fit(record, system, study.fit, study.refine_settings, start)
    nominal = {
        "params": values,
        "intervals": res.intervals,
        "heldout": heldout_nrmse(record, system, values, study.held),
        "fit": heldout_nrmse(record, system, values, study.fit),
        "fit_test": building_fit_test(record, system, values, study.fit, study.settings),
    }
    if study.refine_settings.initial_state == "auto" and res.rest_test.get("at_rest"):
        # the nominal building accepted rest: every extension starts from rest too, instead of
        # testing it again (a refinement more each: 27 of 175 s of a two-effect diagnosis)
        study.refine_settings = replace(study.refine_settings, initial_state="rest")
    f1 = fundamental_hz(system, values)
    study.period = WINDOW_SHARE / f1
    study.corner = max(CORNER_SHARE * f1, 2.0 / float(record.t[-1] - record.t[0]))
    current = {
        "system": system,
        "values": values,
        "heldout": nominal["heldout"],
        "result": res,
        "noise": res.noise_std,
    }
    return nominal, current


def score_text(score: float | None) -> str:
    """A weak-form score for people; None where the weak form found no physical fit."""
    return "none (no physical fit)" if score is None else f"{score:.1f}"
