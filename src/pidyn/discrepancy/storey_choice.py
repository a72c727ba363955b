"""Which storey and effect a building's screenings point to: the best passing row, the leaning
ones, the rows the floors' misfit ranks, and the confirmation of a leaning row by its refit."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.effects import EFFECTS
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.fit_test import fit_test
from pidyn.discrepancy.loop import Step
from pidyn.discrepancy.screening import Screening, screen
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.step_reports import StoreyStep
from pidyn.discrepancy.storey_extension import fit_bic, try_extension
from pidyn.discrepancy.storey_model import (
    BuildingState,
    Found,
    StoreyView,
    score_text,
    storey_signals,
    storey_system,
    storey_views,
)
from pidyn.discrepancy.storey_ranking import (
    measured_floors,
    rank_candidates,
    spring_shares,
)
from pidyn.discrepancy.verdicts import Verdict
from pidyn.simulate import simulate_response
from pidyn.systems.modal import linear_matrices, modal_properties
from pidyn.systems.shear_building import ShearBuilding

log = logging.getLogger(__name__)


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


def best_row(screenings: list[Screening]) -> tuple[int, Evidence] | None:
    """The (storey, row) of the strongest named cause over every storey: each storey's screening
    decides whether it names one (its evidence, pair and tie rules), the scores between storeys."""
    best = None
    for i, sc in enumerate(screenings, start=1):
        if sc.verdict != Verdict.DISCREPANCY or sc.cause is None:
            continue
        row = next(r for r in sc.ranking if r.effect == sc.cause)
        if best is None or (row.score or 0.0) > (best[1].score or 0.0):
            best = (i, row)
    return best


def better(a: StoreyStep, b: StoreyStep, settings: DiagnosisSettings) -> bool:
    """Whether extension ``a`` beats ``b`` on the fitting part: a lower BIC by at least
    ``tie_delta_bic`` ("strong"), or, closer than that, fewer parameters (then the lower BIC).
    A stop fitted to a cubic spring in storey 3 came within 2.1 BIC units of the spring (and
    predicted the held-out part a little worse): two parameters where one does."""
    gap = b.fit_bic - a.fit_bic
    if abs(gap) >= float(settings.thresholds.tie_delta_bic):
        return gap > 0
    if a.n_params != b.n_params:
        return a.n_params < b.n_params
    return gap > 0


def leaning_rows(screenings: list[Screening], settings: DiagnosisSettings) -> list[tuple[int, Evidence]]:
    """(storey, row) of the effects the weak form leans to without deciding (0 < score <
    ``min_delta_bic``, no rule against them), strongest first, at most ``confirm.max_candidates``."""
    th = settings.thresholds
    rows = [
        (i, r)
        for i, sc in enumerate(screenings, start=1)
        for r in sc.ranking
        if r.score is not None
        and 0.0 < r.score < th.min_delta_bic
        and r.persists is not False
        and not r.heldout_miss
    ]
    rows.sort(key=lambda ir: -ir[1].score)
    return rows[: int(settings.confirm.max_candidates)]


def misfit_rows(
    study: Study,
    current: BuildingState,
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
            ranked[0].row.effect,
            ranked[0].storey,
            100 * ranked[0].share,
            100 * min_share,
        )
        return []
    for c in ranked[:6]:
        log.info(
            "score test: %s in storey %d removes %.0f (%.0f%% of the squared residual), linearised",
            c.row.effect,
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
    current: BuildingState,
    found: list[Found],
    views: list[StoreyView],
    rows: list[tuple[int, Evidence]],
    misfit: dict | None = None,
) -> Step | None:
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
    base = fit_bic(record, current.system, current.values, fit, current.noise)
    best = None
    for storey, row in rows:
        sig, _ = storey_signals(views[storey - 1], current.values[f"k{storey}"], study.period, fit[1])
        cand = Found(row.effect, storey, dict(row.parameters), row, sig.context())
        trial = study.extend(current, found, cand)
        gain = base - trial.report.fit_bic
        trial.report.source, trial.report.delta_bic_fit = "output_error", gain
        ok = gain >= float(settings.thresholds.min_delta_bic) and trial.accepted
        if misfit is not None:
            explained = 1.0 - excess2(study.fit_check(trial.current)) / max(excess2(misfit), 1e-300)
            trial.report.source, trial.report.misfit_explained = "fit_test", explained
            ok = ok and explained >= float(settings.confirm.misfit_share)
        log.info(
            "output-error check of %s in storey %d (weak-form score %s): BIC gain %.1f on the fitting part%s",
            cand.effect,
            storey,
            score_text(row.score),
            gain,
            "" if misfit is None else f", {trial.report.misfit_explained:.0%} of the misfit explained",
        )
        if ok and (best is None or gain > best.report.delta_bic_fit):
            best = trial
        if ok and misfit is not None and trial.report.misfit_explained >= float(settings.confirm.misfit_done):
            break  # the rows come best first (the score test): what is left is too little for another
    return best


def close_rivals(screening: Screening, row: Evidence, settings: DiagnosisSettings) -> list[Evidence]:
    """The named row and every other passing effect of its storey less than ``min_delta_bic``
    below it in the weak form: the weak form does not decide between them (a stop and a cubic
    spring on a building scored 53 and 60), the output error on the fitting part does."""
    margin = float(settings.thresholds.min_delta_bic)
    out = [row]
    for r in screening.ranking:
        if r is row or not r.passes or r.step_in_time != row.step_in_time:
            continue
        if (r.score or -np.inf) >= (row.score or 0.0) - margin:
            out.append(r)
    return out


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

    def screen(self, current: BuildingState, found: list[Found]) -> tuple[list[StoreyView], list[Screening]]:
        views = storey_views(self.record, current.system, current.values, self.corner)
        return views, screen_storeys(views, current.values, found, self.period, self.fit[1], self.settings)

    def fit_check(self, current: BuildingState) -> dict:
        system = current.system
        model = (tuple(t.name for t in system.terms), repr(sorted(current.values.items())))
        if model not in self.fits:
            self.fits[model] = building_fit_test(self.record, system, current.values, self.fit, self.settings)
        return self.fits[model]

    def extend(self, current: BuildingState, found: list[Found], cand: Found) -> Step:
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


def building_fit_test(
    record: Record, system: ShearBuilding, values: dict[str, float], span: tuple[float, float], settings
) -> dict:
    """The fit test (``pidyn.discrepancy.fit_test``) of every measured floor's absolute
    acceleration on ``span``, simulated from rest; the noise read above the model's modes."""
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
