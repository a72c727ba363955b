"""One step of a building's diagnosis tried: the building with a candidate storey term added,
refined on the fitting part, and accepted only when it predicts the held-out floors better."""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.effects import EFFECTS
from pidyn.discrepancy.loop import Step
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.step_reports import StoreyStep
from pidyn.discrepancy.storey_model import BuildingState, Found, building_with
from pidyn.discrepancy.storey_nominal import heldout_nrmse
from pidyn.discrepancy.storey_ranking import floor_noise, measured_floors, trial_values
from pidyn.refine.stage import refine
from pidyn.simulate import simulate_response
from pidyn.systems.places import storey_param
from pidyn.systems.shear_building import ShearBuilding

log = logging.getLogger(__name__)


def try_extension(
    record: Record,
    nominal_system: ShearBuilding,
    current: BuildingState,
    found: list[Found],
    cand: Found,
    fit: tuple[float, float],
    held: tuple[float, float],
    settings: DiagnosisSettings,
    refine_settings: Any,
) -> Step:
    """The building with ``cand`` added, refined on the fitting part; accepted when it predicts
    the held-out floor accelerations better than the current model by ``storey_min_gain``."""

    # the refinement identifies the shapes the screening fixed from the record (a friction's
    # width read from filtered drifts is biased, and the friction's size follows its width)
    cand = replace(cand, ctx={**cand.ctx, "free_width": True})
    ext, start = building_with(
        nominal_system, trial_values(current.values, cand.storey, cand.row), [*found, cand]
    )
    log.info(
        "storey %d: %s (score %.1f), extending and refining",
        cand.storey,
        cand.effect,
        cand.row.score or 0.0,
    )
    res = refine(
        ext, record, {"screening": start}, refine_settings, t_start=fit[0], t_end=fit[1], prefer="screening"
    )
    values = {**start, **res.params}
    ho = heldout_nrmse(record, ext, values, held)
    before = current.heldout.mean
    bic = fit_bic(record, ext, values, fit, current.noise)
    accepted = bool(np.isfinite(ho.mean) and ho.mean < before * (1.0 - float(settings.storey_min_gain)))
    params, report = _step_report(cand, values, res, bic, before, ho.mean, accepted)
    if accepted and (spread := size_spread(cand, report)) > float(settings.storey_max_rel_std):
        # a size the data do not fix: such an effect stands in for another part of the model (a
        # collapsed linear damper) rather than for something the structure does
        accepted = report.accepted = False
        report.size_rel_std = spread
    log.info(
        "storey %d %s: held-out NRMSE %.4g -> %.4g (%s)",
        cand.storey,
        cand.effect,
        before,
        ho.mean,
        report.outcome(),
    )
    done = Found(cand.effect, cand.storey, params, cand.row, cand.ctx)
    return Step(accepted, BuildingState(ext, values, ho, res, current.noise), done, report)


def size_spread(cand: Found, report: StoreyStep) -> float:
    """The standard deviation of the effect's size (its key parameter) as a share of it, from the
    refinement's interval; 0 where it has none."""
    iv = report.intervals.get(storey_param(EFFECTS[cand.effect].key, cand.storey)) or {}
    rel = iv.get("rel_std_pct")
    return float(rel) / 100.0 if rel is not None and np.isfinite(rel) else 0.0


def _step_report(
    cand: Found, values: dict, res: Any, bic: float, before: float, after: float, accepted: bool
) -> tuple[dict[str, float], StoreyStep]:
    """The effect's own parameters (its names without the storey) and what ``diagnosis.json``
    keeps of the step."""
    names = {
        s.name: storey_param(s.name, cand.storey)
        for s in EFFECTS[cand.effect].term(cand.params, cand.ctx).specs()
    }
    params = {base: float(values[full]) for base, full in names.items() if full in values}
    report = StoreyStep(
        effect=cand.effect,
        storey=cand.storey,
        score=cand.row.score,
        cv_gain=cand.row.cv_gain,
        screening_parameters=cand.params,
        parameters={names[b]: v for b, v in params.items()},
        intervals={full: res.intervals.get(full) for full in names.values() if full in res.intervals},
        source="weak_form",
        fit_bic=bic,
        n_params=len(names),
        heldout_before=before,
        heldout_after=after,
        accepted=accepted,
    )
    return params, report


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
