"""A learned storey force: what the building diagnosis adds when something is missing and no
library effect earns its place (``unexplained``).

A small network f(d, d') on one storey's drift and drift velocity (``LearnedForce`` inside the
shear building's equations), trained with the building's physical parameters on the simulated
floor accelerations of the fitting part (``pidyn.discrepancy.learned_fit``). The storey is the
one the screening found structured, else the storeys the score test on the floor accelerations
puts first (``storey_ranking.storey_order``) are each trained briefly and the first is taken
unless another's trained model fits the fitting part clearly better (``learned.choice_margin``):
the held-out part decides nothing but whether the learned force is kept, which it is only when
it predicts the held-out floor accelerations better than the model it extends (as the
single-degree-of-freedom diagnosis keeps its learned force).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pidyn.discrepancy.learned_fit import fit_learned_force
from pidyn.discrepancy.storey_model import BuildingState
from pidyn.simulate import simulate_response
from pidyn.systems.shear_building import ShearBuilding
from pidyn.systems.terms import LearnedForce

log = logging.getLogger(__name__)


def with_learned_force(
    system: ShearBuilding, values: dict[str, float], storey: int, drift: np.ndarray, velocity: np.ndarray
) -> ShearBuilding:
    """The linear building at ``values`` with a learned force on ``storey``'s drift, its scales
    the nominal model's drift and drift velocity there (it starts as the nominal model)."""
    k = float(values[f"k{storey}"])
    d_scale = max(float(np.std(drift)), 1e-12)
    term = LearnedForce(x_scale=d_scale, v_scale=max(float(np.std(velocity)), 1e-12), f_scale=k * d_scale)
    return system.linear_at(values, {storey: [term]}, f"{system.name}+learned_force@{storey}")


def _own(ext: ShearBuilding, values: dict[str, float]) -> dict[str, float]:
    names = {s.name for s in ext.param_specs()}
    return {k: v for k, v in values.items() if k in names}


def _train(ext, start: dict, record, fit, period: float, settings, evaluations: int):
    return fit_learned_force(
        ext,
        start,
        record,
        fit,
        period,
        periods_per_segment=float(settings.periods_per_segment),
        max_evaluations=evaluations,
    )


def _save(folder: Path, ext: ShearBuilding, storey: int, values: dict[str, float]) -> str:
    term = next(t.term for t in ext.storeys[storey - 1] if isinstance(t.term, LearnedForce))
    torch.save(
        {"storey": storey, "values": values, "network": term.net.state_dict()}, folder / "learned_force.pt"
    )
    return "learned_force.pt"


def _chosen(tried: list[tuple], ordered: bool, margin: float) -> tuple:
    """The brief training whose fit fell most; with ``ordered`` storeys (the score test's order),
    the first unless another's fell lower by ``margin`` of its ratio: a brief fit is a noisy
    judge (a trilinear spring in storey 3 of four, the score test's first: 0.822 there, 0.803 in
    storey 4, whose learned force then predicted the held-out floors worse, 0.51 -> 0.78)."""
    best = min(tried, key=lambda r: r[0])
    if not ordered or best is tried[0] or best[0] < (1.0 - margin) * tried[0][0]:
        return best
    return tried[0]


def _train_best(study, system, values, storeys: list[int], drifts, velocities, period: float, ordered: bool):
    """Each of several storeys trained briefly, the chosen one (``_chosen``) trained on to the full
    budget (one storey: trained in full): (storey, system, result, seconds, tried), or None."""
    record, settings = study.record, study.settings.learned
    brief = int(settings.max_evaluations) if len(storeys) == 1 else max(1, int(settings.max_evaluations) // 4)
    tried = []
    for i in storeys:
        ext = with_learned_force(system, values, i, drifts[i - 1], velocities[i - 1])
        res = _train(ext, _own(ext, values), record, study.fit, period, settings, brief)
        if res is not None:
            tried.append((res.loss_after / max(res.loss_before, 1e-300), i, ext, res))
    if not tried:
        return None
    _, chosen, ext, res = _chosen(tried, ordered, float(settings.choice_margin))
    seconds = sum(r.seconds for *_, r in tried)
    if brief < int(settings.max_evaluations):
        more = _train(
            ext, res.values, record, study.fit, period, settings, int(settings.max_evaluations) - brief
        )
        if more is not None:
            res, seconds = more, seconds + more.seconds
    return chosen, ext, res, seconds, tried


def learned_storey_force(
    study: Any,
    current: BuildingState,
    storeys: list[int] | None,
    folder: Path | None,
    period: float,
    heldout: Callable,
) -> dict | None:
    """Train a learned force on one of ``storeys`` (None: every storey, the best fit on the
    fitting part taken; several: in the score test's order, ``_chosen``) from the current model,
    in segments of a few ``period`` s (the fundamental's);
    ``heldout(record, system, values, span)`` scores it as the diagnosis scores every model.
    Its held-out gain, and whether it is kept; None when no storey's network can be trained
    (a fitting part shorter than one segment)."""
    record, system, values = study.record, current.system, current.values
    sim = simulate_response(system, values, record)
    drifts, velocities = system._drifts(sim["x"], sim["v"])  # per storey, as the equations take them
    ordered = bool(storeys)
    storeys = list(storeys or range(1, system.n_dof + 1))
    picked = _train_best(study, system, values, storeys, drifts, velocities, period, ordered)
    if picked is None:
        return None
    chosen, ext, res, seconds, tried = picked
    held = heldout(record, ext, res.values, study.held)
    before = current.heldout.mean
    kept = bool(np.isfinite(held.mean) and held.mean < before)
    out = {
        "storey": chosen,
        "storeys_tried": [i for _, i, *_ in tried],
        "fit_loss_ratio": {str(i): r for r, i, *_ in tried},  # after the brief training of each
        "heldout_before": before,
        "heldout_after": held.mean,
        "heldout_per_floor": held.per_floor,
        "kept": kept,
        "note": res.note,
        "seconds": seconds,
        "system": ext,
        "values": res.values,
        "heldout": held,
    }
    if folder is not None:
        out["file"] = _save(folder, ext, chosen, res.values)
    log.info(
        "learned force in storey %d (of %s tried): held-out NRMSE %.4g -> %.4g (%s)",
        chosen,
        out["storeys_tried"],
        before,
        held.mean,
        "kept" if kept else "not kept: it does not predict the held-out part better",
    )
    return out
