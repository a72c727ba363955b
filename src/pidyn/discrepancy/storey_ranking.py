"""Which (effect, storey) a building's failed fit is tried with first: a score test on the
simulated floor accelerations.

The weak form scores a storey's effects on twice-integrated drifts. Where it loses an effect
(a damping change of a lightly damped storey, a friction in a storey with an unmeasured floor
above it), its best-scored rows are no guide, and each output-error fit of a wrong guess costs a
refinement. Here every candidate is simulated once at the weak form's parameters (a step in
time over a grid of its times; where the weak form found no physical fit, at a typical size
against the storey's drift: a friction in storey 4 of four at 4.9 % noise, whose weak-form fit
had the wrong sign beside an inflated damper, was not scored at all): its change of the floor accelerations is the direction it adds
to the current model. With the current model's own parameters profiled out (the projection off
their sensitivities), the share of the fitting part's misfit (in noise units) that one step
along that direction removes is the candidate's score (the residual's noise units are the
nominal refinement's, so the scores compare candidates, not models): the Lagrange-multiplier test of adding
the effect, without fitting it. The candidates are tried by output error in this order.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.effects import EFFECTS
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.score_test import linearised_chi2, profiled_basis
from pidyn.discrepancy.storey_model import BuildingState, Found, building_with, storey_signals
from pidyn.simulate import input_hold, simulate_batch


@dataclass
class Ranked:
    storey: int
    row: Evidence  # the weak form's row, its parameters at the best grid point
    chi2: float  # the misfit (noise units) one linearised step removes
    share: float  # ... as a share of the current model's squared residual there
    direction: np.ndarray  # its change of the floor accelerations, the profiled parameters' part removed


def measured_floors(record: Record) -> list[int]:
    """The floors (0-based columns of ``record.a``) that carry a sensor."""
    return [j for j in range(record.a.shape[1]) if not np.isnan(record.a[:, j]).all()]


def floor_noise(record: Record, noise: dict, mask: np.ndarray) -> np.ndarray:
    """Each measured floor's noise level: the nominal refinement's (floor 1 is its channel "a",
    the others "a2", "a3", ...), or the floor's RMS where it has none."""
    out = []
    for j in measured_floors(record):
        sd = noise.get(f"a{j + 1}", noise.get("a") if j == 0 else None) or np.std(record.a[mask, j])
        out.append(max(float(sd), 1e-300))
    return np.array(out)


def _simulate(system, sets: list[dict[str, float]], record: Record, floors: list[int], mask) -> np.ndarray:
    """The measured floors' relative accelerations on ``mask`` for each parameter set, (P, rows)."""
    names = sorted(set().union(*sets))
    params = {n: np.array([s[n] for s in sets], float) for n in names}
    with np.errstate(all="ignore"):  # a candidate at the weak form's size may blow up: not finite, not ranked
        a = simulate_batch(system, params, record.t, record.f, hold=input_hold(record))["a"]
    a = a.reshape(len(record.t), len(sets), -1)[mask][:, :, floors]  # (rows, P, floors)
    return np.transpose(a, (1, 0, 2)).reshape(len(sets), -1)


def _profiled(system, values: dict[str, float], record, floors, mask, scale) -> np.ndarray:
    """An orthonormal basis of how the floors' accelerations move with the current model's
    trainable parameters (central differences, in noise units)."""
    rows = int(mask.sum()) * len(floors)
    return profiled_basis(
        lambda sets: _simulate(system, sets, record, floors, mask), system, values, rows, scale
    )


def spring_shares(screening) -> None:
    """Marks each row of a storey's screening whose effect is a spring at rest
    (``Effect.spring_at_rest``) with ``spring_share``: the storey spring its weak-form fit kept
    beside the effect, as a share of the storey's own law's. On the current model's whole spring
    a trial is as much stiffer at once (a hysteresis in storey 5 of five: a negative step at
    every loop shape)."""
    own = float(screening.nominal_params.get("k", 0.0))
    for row in screening.ranking:
        refit = float(row.nominal_refit.get("k", 0.0))
        if getattr(EFFECTS.get(row.effect), "spring_at_rest", False) and own > 0 and refit > 0:
            row.spring_share = float(np.clip(refit / own, 0.05, 1.0))


def trial_values(values: dict[str, float], storey: int, row: Evidence) -> dict[str, float]:
    """The current model's values with the storey's spring taken down to the row's
    ``spring_share`` (``spring_shares``): where a trial of the row's effect starts."""
    share = row.spring_share
    if not share:
        return values
    return {**values, f"k{storey}": float(values[f"k{storey}"]) * float(share)}


def _trials(row: Evidence, span: tuple[float, float], drift_peak: float, k: float) -> list[dict]:
    """The starts of a row's trial, as its effect asks (``Effect.storey_trials``: a step in time
    at every time of a grid, a stop at every gap of its grid)."""
    return EFFECTS[row.effect].storey_trials(dict(row.parameters), span, drift_peak, k)


def rank_candidates(
    study, current: BuildingState, found: list, views: list, rows: list[tuple[int, Evidence]]
) -> list[Ranked]:
    """``rows`` (storey, weak-form row) scored and sorted, best first (the module's docstring)."""
    ranked, _ = _scored(study, current, found, views, rows)
    return ranked


def storey_order(
    study, current: BuildingState, found: list, views: list, rows: list[tuple[int, Evidence]]
) -> list[int]:
    """The storeys, the one whose candidates together remove most of the fitting part's misfit
    first: the projection of the residual on the span of all its candidates' directions (a
    force outside the library is in no single one of them, but its storey's springs and
    dampers of every shape come close). Where a learned storey force is tried first."""
    ranked, r = _scored(study, current, found, views, rows)
    joint = {}
    for storey in sorted({c.storey for c in ranked}):
        d = np.stack([c.direction for c in ranked if c.storey == storey], axis=1)
        coef, *_ = np.linalg.lstsq(d, r, rcond=1e-8)
        fitted = d @ coef
        joint[storey] = float(fitted @ fitted)
    return sorted(joint, key=lambda i: -joint[i])


def _scored(
    study, current: BuildingState, found: list, views: list, rows: list[tuple[int, Evidence]]
) -> tuple[list[Ranked], np.ndarray]:
    """The candidates scored (best first) and the current model's residual, its parameters profiled out."""
    record, fit = study.record, study.fit
    mask = (record.t >= fit[0]) & (record.t <= fit[1])
    floors = measured_floors(record)
    scale = np.tile(floor_noise(record, current.noise, mask), int(mask.sum()))
    memo = _memo(study, current, found)
    if "r" not in memo:
        meas = record.a[mask][:, floors].reshape(-1) / scale
        base_sys, base_vals = building_with(study.system, current.values, found)
        resid = meas - _simulate(current.system, [current.values], record, floors, mask)[0] / scale
        q = _profiled(current.system, current.values, record, floors, mask, scale)
        memo.update(q=q, r=resid - q @ (q.T @ resid), rows={})
        memo["base"] = _simulate(base_sys, [base_vals], record, floors, mask)[0] / scale
    q, r, base = memo["q"], memo["r"], memo["base"]
    total = max(float(r @ r), 1e-300)
    out = []
    for storey, row in rows:
        key = (storey, row.effect, repr(sorted(row.parameters.items())))
        if key in memo["rows"]:
            if memo["rows"][key] is not None:
                out.append(memo["rows"][key])
            continue
        sig, _ = storey_signals(views[storey - 1], current.values[f"k{storey}"], study.period, fit[1])
        if not row.parameters:  # the weak form found no physical fit: a typical size is tried
            row = replace(row, parameters=EFFECTS[row.effect].sample(np.random.default_rng(0), sig))
        view = views[storey - 1]
        trials = _trials(row, fit, float(np.max(np.abs(view.drift))), float(current.values[f"k{storey}"]))
        start = trial_values(current.values, storey, row)
        systems = [
            building_with(study.system, start, [*found, Found(row.effect, storey, p, row, sig.context())])
            for p in trials
        ]
        sims = _simulate(systems[0][0], [s[1] for s in systems], record, floors, mask) / scale
        best = None
        for p, sim in zip(trials, sims):
            cand = _one(storey, row, p, sim - base, q, r, total)
            if cand is not None and (best is None or cand.chi2 > best.chi2):
                best = cand
        memo["rows"][key] = best
        if best is not None:
            out.append(best)
    out.sort(key=lambda c: -c.chi2)
    return out, r


def _memo(study, current: BuildingState, found: list) -> dict:
    """The score test's store for one model (its system, parameter values and named effects)."""
    store = getattr(study, "scores", None)
    if store is None:
        return {}
    model = (
        current.system.name,
        repr(sorted(current.values.items())),
        tuple((f.effect, f.storey) for f in found),
        repr(sorted(current.noise.items())),
    )
    return store.setdefault(model, {})


def _one(storey: int, row: Evidence, params: dict, d: np.ndarray, q: np.ndarray, r: np.ndarray, total: float):
    """One candidate's linearised score from its change ``d`` of the floor accelerations."""
    scored = linearised_chi2(d, q, r, _signed(row.effect))
    if scored is None:
        return None
    chi2, pd_ = scored
    return Ranked(storey, replace(row, parameters=params), chi2, chi2 / total, pd_)


def _signed(effect: str) -> bool:
    """Whether a row's fitted size may take either sign (``Effect.signed``; a learned force's
    row is no library effect)."""
    eff = EFFECTS.get(effect)
    return bool(eff is not None and eff.signed)
