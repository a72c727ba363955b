"""The steps of a storey-by-storey diagnosis: the next (effect, storey) to try, the extended
building refined and judged on the held-out floors, and what each step reports."""

from __future__ import annotations

import logging

import numpy as np

from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.loop import Step
from pidyn.discrepancy.screening import Screening
from pidyn.discrepancy.step_reports import StoreyStep
from pidyn.discrepancy.storey_choice import (
    Study,
    best_row,
    better,
    close_rivals,
    confirm_leaning,
    excess2,
    leaning_rows,
    misfit_rows,
)
from pidyn.discrepancy.storey_extension import fit_bic
from pidyn.discrepancy.storey_model import (
    BuildingState,
    Found,
    NominalBuilding,
    StoreyView,
    score_text,
    storey_signals,
)
from pidyn.notes import note

log = logging.getLogger(__name__)


def next_step(
    study: Study,
    current: BuildingState,
    found: list[Found],
    views: list[StoreyView],
    screenings: list[Screening],
) -> Step | None:
    """The next extension: the strongest named cause (and its close rivals, the fitting part's
    output error choosing), or, where the weak form names nothing, a leaning effect the output
    error confirms; then, with the weak form's name refused (or none given), for a building that
    fails the fit test, the score test's best (effect, storey) pairs (``misfit_rows``; after a
    named effect, in the other storeys and only when the best is strong), a confirmed leaning
    effect kept only if it gains more BIC than they do. None when there is nothing to try; a
    refused step when all were refused."""
    pick = best_row(screenings)
    if pick is None:  # the weak form names nothing: the effects it leans to are fitted by output error
        tried = leaning_rows(screenings, study.settings)
        step = confirm_leaning(study, current, found, views, tried)
    else:
        tried = [(pick[0], r) for r in close_rivals(screenings[pick[0] - 1], pick[1], study.settings)]
        step = named_step(study, current, found, views, tried)
    after = float(study.settings.confirm.after_named_share)
    if step is not None and step.accepted and pick is not None and not found:
        if not weak_first_name(study, current, step):
            return step
    elif (step is not None and step.accepted and (pick is not None or found)) or (found and after <= 0):
        return step
    # a leaning effect the output error confirmed competes with the fit test's candidates: a weak
    # score with a real BIC gain can stand in for another effect of the same storey
    misfit = study.fit_check(current)
    if not misfit["failed"]:
        return step
    # the model misses something the weak form does not see, or names wrongly (an unmeasured floor
    # hides the drifts it reads)
    worst = misfit["channels"][misfit["worst"]]
    log.info(
        "the current model fails the fit test (%s: NRMSE %.3g against noise %.3g): trying the effects the "
        "score test on the floor accelerations ranks first, by output error",
        misfit["worst"],
        worst["nrmse"],
        worst["noise"] or 0.0,
    )
    # after a named effect, the remaining misfit is mostly that effect's own law imperfectly
    # fitted, which no other library effect removes: only another storey's effect that the score
    # test finds strong is tried
    rows = misfit_rows(study, current, found, views, screenings, tried, after if found else 0.0)
    other = confirm_leaning(study, current, found, views, rows, misfit)
    if other is None or (step is not None and step.accepted and _gain(step) >= _gain(other)):
        return step
    return other


def weak_first_name(study: Study, current: BuildingState, step: Step) -> bool:
    """Whether the weak form's first name leaves most of the model's misfit: the building
    fails the fit test before it, and the name removes less than ``confirm.misfit_share`` of
    the fitting part's excess over the noise. Then the score test's candidates, every storey's,
    compete with it by their BIC gain. A quadratic spring in storey 3 was named a cubic spring
    there: 21 % of the excess removed (held-out NRMSE 0.42 -> 0.40), where the quadratic
    spring, which the score test ranks first in that storey, removes all of it (0.42 -> 0.044)."""
    misfit = study.fit_check(current)
    if not misfit["failed"]:
        return False
    explained = 1.0 - excess2(study.fit_check(step.current)) / max(excess2(misfit), 1e-300)
    base = fit_bic(study.record, current.system, current.values, study.fit, current.noise)
    step.report.delta_bic_fit, step.report.misfit_explained = base - step.report.fit_bic, explained
    weak = explained < float(study.settings.confirm.misfit_share)
    if weak:
        log.info(
            "storey %d %s removes %.0f%% of the fitting part's excess over the noise: the score test's "
            "candidates compete with it",
            step.report.storey,
            step.report.effect,
            100 * explained,
        )
    return weak


def _gain(step: Step) -> float:
    return float(step.report.delta_bic_fit or -np.inf)


def named_step(
    study: Study,
    current: BuildingState,
    found: list[Found],
    views: list[StoreyView],
    rivals: list[tuple[int, Evidence]],
) -> Step:
    """The weak form's named cause and its close rivals in the same storey, each extended and
    refined; the fitting part's output error chooses (``better``)."""
    storey = rivals[0][0]
    sig, _ = storey_signals(views[storey - 1], current.values[f"k{storey}"], study.period, study.fit[1])
    step = None
    for _, rival in rivals:
        cand = Found(rival.effect, storey, dict(rival.parameters), rival, sig.context())
        trial = study.extend(current, found, cand)
        if step is not None:
            log.info(
                "storey %d: %s (fitting-part BIC %.1f) against %s (%.1f)",
                storey,
                cand.effect,
                trial.report.fit_bic,
                step.report.effect,
                step.report.fit_bic,
            )
            trial.report.rival, step.report.rival = step.report.versus(), trial.report.versus()
        if step is None or better(trial.report, step.report, study.settings):
            step = trial
    return step


def building_gain(nominal: NominalBuilding, current: BuildingState, extended: bool) -> dict:
    """``gain`` of ``diagnosis.json``: the held-out NRMSE of the floor accelerations."""
    trivial = nominal.heldout.trivial
    out = {
        "metric": "heldout_nrmse_a",
        "nominal": nominal.heldout.mean,
        "extended": current.heldout.mean if extended else None,
        "per_floor": {
            "nominal": nominal.heldout.per_floor,
            "extended": current.heldout.per_floor if extended else None,
            "trivial": nominal.heldout.trivial_per_floor,
        },
        "trivial": trivial,
        "trivial_label": "moving with the ground",
    }
    for key in ("nominal", "extended"):  # beside every held-out score, the prediction that knows nothing
        out[f"{key}_beats_trivial"] = (
            None if out[key] is None or trivial is None else bool(out[key] < trivial)
        )
    return out


def refusal_notes(refused: StoreyStep | None) -> list[str]:
    if refused is None:
        return []
    if refused.size_rel_std is not None:
        return [
            note(
                "refused_undetermined",
                f"{refused.effect} in storey {refused.storey} predicted the held-out floor accelerations "
                f"better ({refused.heldout_before:.4g} -> {refused.heldout_after:.4g}) but its size is not "
                f"determined (std {100 * refused.size_rel_std:.0f} % of it): not named",
            )
        ]
    return [
        note(
            "refused_no_heldout_gain",
            f"{refused.effect} in storey {refused.storey} passed the screening (score {score_text(refused.score)}) "
            f"but did not predict the held-out floor accelerations better ({refused.heldout_before:.4g} -> "
            f"{refused.heldout_after:.4g}): not named",
        )
    ]
