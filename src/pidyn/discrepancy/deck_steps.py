"""The steps of a deck's diagnosis: the nominal deck refined, every (effect, support) scored by
what it would change in the deck channels, the best tried by output error and named only when it
predicts the held-out part better; and which supports the data cannot tell apart.

The score is the building's score test (``pidyn.discrepancy.storey_ranking``) on the deck
channels: each candidate is simulated once at a typical size (the effect's own ``sample``, sized
against the support's deformation along the current model's motion); its change of the channels,
with the current model's parameters profiled out, is the direction it adds; the share of the
fitting part's misfit one step along it removes is its score. Two candidates whose directions are
nearly parallel change the channels alike: no record of these channels can say which it is.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pidyn.data.layout import end_motions
from pidyn.discrepancy.deck_model import (
    DeckState,
    Placed,
    candidate_deck,
    channel_errors,
    channels,
    simulated_channels,
    support_signals,
)
from pidyn.discrepancy.effects import EFFECTS
from pidyn.discrepancy.fit_test import fit_test
from pidyn.discrepancy.score_test import linearised_chi2, profiled_basis
from pidyn.discrepancy.storey_nominal import refined_best
from pidyn.refine.stage import refine
from pidyn.starts.data import start_from_data
from pidyn.supports import support_table
from pidyn.systems.modal import linear_matrices, modal_properties
from pidyn.systems.places import storey_param

log = logging.getLogger(__name__)

#: a candidate's fit starts from its best-scored trial and from this many next ones (the scores
#: are linearised: a Bouc-Wen support's best-scored loop shape ended in a poor optimum on simulated
#: decks where another shape of the grid did not)
OTHER_STARTS = 2
#: two candidates whose changes of the deck channels correlate this much (profiled directions)
#: are the same to these data: the supports they sit at are not told apart
ALIKE = 0.95


def rigid_test(study, values: dict[str, float]) -> dict[str, Any]:
    """Do the deck channels move as a deck rigid in plan does, before any model is fitted? With more
    channels than the deck's two motions, the part of the channels no rigid deck can move (their
    least-squares residual about the best end motions) is measured against its own noise floor, as
    the fit test measures a model's residual (``pidyn.discrepancy.fit_test``). Where it stands
    clear of the noise, the deck bends or twists in plan, and what the diagnosis names at a support
    may stand for that as much as for the support."""
    record, m = study.record, fit_mask(study.record, study.fit)
    meas, H, names = channels(record)
    rigid = end_motions(meas[m], H) @ H.T  # the best rigid motion of the deck, read by each channel
    off = meas[m] - rigid
    test = _channels_test(study, study.system, rigid, values)
    shares = {n: float(np.std(off[:, i]) / max(np.std(meas[m, i]), 1e-300)) for i, n in enumerate(names)}
    return {
        "rigid": not test["failed"],
        "off_share": shares,
        "channels": test["channels"],
        "failed_channels": test["failed_channels"],
    }


def support_effects() -> list[str]:
    """The effects tried at a support by default: the library's, and the structure that follows the
    amplitude (``Effect.tried_where_period_moves``: what the literature on bridge abutments finds,
    Goel and Chopra 1997, McCallen and Romstad 1994), which a single degree of freedom tries only
    where its running period moves."""
    return [n for n, e in EFFECTS.items() if e.library or e.tried_where_period_moves]


@dataclass
class Scored:
    """One (effect, support) scored: its trial parameters, the misfit (in units of each channel's
    nominal misfit) one linearised step removes, that as a share, and its direction."""

    effect: str
    support: int
    params: dict[str, float]
    ctx: dict
    chi2: float
    share: float
    direction: np.ndarray
    #: the next best trial parameters (a hysteresis's other loop shapes): further starts of its fit
    others: list[dict[str, float]] = field(default_factory=list)

    def row(self) -> dict[str, Any]:
        return {"effect": self.effect, "support": self.support, "share": self.share, "chi2": self.chi2}


def fit_mask(record, span: tuple[float, float]) -> np.ndarray:
    return (record.t >= span[0] - 1e-9) & (record.t <= span[1] + 1e-9)


def nominal_deck(study) -> tuple[DeckState, dict[str, Any]]:
    """The linear deck refined on the fitting part from the config's and the data's starts (the
    one whose simulation fits the fitting part's channels better kept); its report."""
    system, record, fit = study.system, study.record, study.fit
    config = {s.name: float(s.init) for s in system.param_specs()}
    starts = {"config": config}
    try:
        starts["data"] = {**config, **start_from_data(record.segment(*fit), system).values}
    except Exception as exc:  # a start that cannot be read leaves the config's
        log.info("no start from the data (%s)", exc)
    best = refined_best(
        record,
        system,
        starts,
        study.refine_settings,
        fit,
        config,
        lambda est: channel_errors(record, system, est, fit, fit).mean,
    )
    if best is None:
        raise RuntimeError(f"record '{record.name}': the nominal deck could not be refined from any start")
    _, values, res = best
    state = DeckState(system, values, channel_errors(record, system, values, study.held, fit), res)
    return state, {
        "params": values,
        "intervals": res.intervals,
        "heldout": state.heldout.to_dict(),
        "fit": channel_errors(record, system, values, fit, fit).to_dict(),
        "fit_test": deck_fit_test(study, system, values),
        "supports": support_table(system, values, res),
        "rigid_test": rigid_test(study, values),
    }


def deck_fit_test(study, system, values: dict[str, float]) -> dict:
    """The fit test (``pidyn.discrepancy.fit_test``) of every deck channel on the fitting part."""
    sim = simulated_channels(system, [values], study.record)[0]
    return _channels_test(study, system, sim[fit_mask(study.record, study.fit)], values)


def _channels_test(study, system, predicted: np.ndarray, values: dict[str, float]) -> dict:
    """The fit test of the deck channels on the fitting part against ``predicted`` (rows of the
    fitting part, one column a channel); the noise read above the deck's modes at ``values``."""
    record = study.record
    meas, _, names = channels(record)
    m = fit_mask(record, study.fit)
    f_top = float(max(modal_properties(*linear_matrices(system, values))["frequency_hz"]))
    th = study.settings.fit_test
    return fit_test(
        {n: meas[m, i] for i, n in enumerate(names)},
        {n: predicted[:, i] for i, n in enumerate(names)},
        {n: float(np.std(meas[m, i])) for i, n in enumerate(names)},
        record.dt,
        f_top,
        float(th.rms_ratio),
        float(th.min_excess),
    )


def score_candidates(study, current: DeckState, found: list[Placed]) -> list[Scored]:
    """Every (effect, support) not yet in the model, scored (the module's docstring), best first."""
    record, m = study.record, fit_mask(study.record, study.fit)
    meas = channels(record)[0][m]
    base = simulated_channels(current.system, [current.values], record)[0][m]
    scale = np.sqrt(np.mean((meas - base) ** 2, axis=0))  # each channel in units of its own misfit
    scale = np.where(scale > 0, scale, 1.0)
    r = ((meas - base) / scale).reshape(-1)
    q = _profiled(current, record, m, scale)
    r = r - q @ (q.T @ r)
    total = max(float(r @ r), 1e-300)
    signals = support_signals(record, current.system, current.values)
    taken = {(f.effect, f.support) for f in found}
    out = []
    for j, sig in enumerate(signals, start=1):
        for effect in study.effects:
            if (effect, j) in taken:
                continue
            params = EFFECTS[effect].sample(np.random.default_rng(0), sig)
            trials = [
                t
                for shape in EFFECTS[effect].shape_trials(params, sig)
                for t in EFFECTS[effect].storey_trials(shape, study.fit, sig.x_peak, sig.k_nominal)
            ]
            sets = [
                candidate_deck(study.system, current.values, found, Placed(effect, j, p, sig.context()))
                for p in trials
            ]
            sims = simulated_channels(sets[0][0], [s[1] for s in sets], record)[:, m]
            scored = [
                _one(effect, j, p, sig.context(), ((sim - base) / scale).reshape(-1), q, r, total)
                for p, sim in zip(trials, sims)
            ]
            scored = sorted((c for c in scored if c is not None), key=lambda c: -c.chi2)
            if scored:
                scored[0].others = [c.params for c in scored[1 : OTHER_STARTS + 1]]
                out.append(scored[0])
    out.sort(key=lambda c: -c.chi2)
    return out


def _profiled(current: DeckState, record, m: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """An orthonormal basis of how the channels move with the current model's trainable parameters."""

    def simulate(sets: list[dict[str, float]]) -> np.ndarray:
        return (simulated_channels(current.system, sets, record)[:, m] / scale).reshape(len(sets), -1)

    return profiled_basis(simulate, current.system, current.values, int(m.sum()) * len(scale))


def _one(effect, support, params, ctx, d, q, r, total) -> Scored | None:
    """A candidate's linearised score from its change ``d`` of the channels."""
    scored = linearised_chi2(d, q, r, EFFECTS[effect].signed)
    if scored is None:
        return None
    chi2, pd_ = scored
    return Scored(effect, support, params, ctx, chi2, chi2 / total, pd_)


def alike(scored: list[Scored], chosen: Scored) -> list[dict[str, Any]]:
    """The other supports whose same effect changes the channels as the chosen one does."""
    out = []
    for c in scored:
        if c.effect != chosen.effect or c.support == chosen.support:
            continue
        a, b = c.direction, chosen.direction
        rho = float(a @ b / max(np.sqrt((a @ a) * (b @ b)), 1e-300))
        if abs(rho) >= ALIKE:
            out.append({"effect": c.effect, "supports": [chosen.support, c.support], "correlation": rho})
    return out


def try_candidate(study, current: DeckState, found: list[Placed], cand: Scored) -> tuple[DeckState, dict]:
    """The deck with ``cand`` added, refined on the fitting part: its state and its report, with
    its fitting part's BIC (what candidates are chosen by) and whether it may be named: it predicts
    the held-out channels better by ``thresholds.min_name_gain`` and its size is determined
    (``storey_max_rel_std``)."""
    ext, values, res = _refined(study, current, found, cand)
    fit = study.fit
    ho = channel_errors(study.record, ext, values, study.held, fit)
    before = current.heldout.mean
    gain = float(study.settings.thresholds.min_name_gain)
    gain_ok = bool(np.isfinite(ho.mean) and ho.mean < before * (1.0 - gain))
    key = storey_param(EFFECTS[cand.effect].key, cand.support)
    rel = (res.intervals.get(key) or {}).get("rel_std_pct")
    spread = float(rel) / 100.0 if rel is not None and np.isfinite(rel) else 0.0
    determined = spread <= float(study.settings.storey_max_rel_std)
    names = [
        storey_param(s.name, cand.support) for s in EFFECTS[cand.effect].term(cand.params, cand.ctx).specs()
    ]
    report = {
        **cand.row(),
        "parameters": {f: float(values[f]) for f in names if f in values},
        "intervals": {f: res.intervals.get(f) for f in names if f in res.intervals},
        "fit_bic": fit_bic(study, ext, values),
        "heldout_before": before,
        "heldout_after": ho.mean,
        "size_rel_std": spread,
        "passes": gain_ok and determined,
        "accepted": False,
        "outcome": "passes"
        if gain_ok and determined
        else ("refused: its size is not determined" if gain_ok else "refused: no held-out gain"),
    }
    log.info(
        "support %d %s: held-out NRMSE %.4g -> %.4g, fitting-part BIC %.6g (%s)",
        cand.support,
        cand.effect,
        before,
        ho.mean,
        report["fit_bic"],
        report["outcome"],
    )
    return DeckState(ext, values, ho, res), report


def _refined(study, current: DeckState, found: list[Placed], cand: Scored):
    """The candidate's deck refined on the fitting part from its best-scored trial and the next
    ones (``OTHER_STARTS``; the refinement keeps the start that simulates best, and the lower
    cost): (system, values, the refinement's result)."""
    place = Placed(cand.effect, cand.support, cand.params, cand.ctx)
    ext, start = candidate_deck(study.system, current.values, found, place)
    log.info(
        "support %d: %s (score %.3g of the misfit), extending and refining",
        cand.support,
        cand.effect,
        cand.share,
    )
    starts = {"screening": start}
    for i, params in enumerate(cand.others, start=2):
        starts[f"shape {i}"] = candidate_deck(
            study.system, current.values, found, replace(place, params=params)
        )[1]
    fit = study.fit
    res = refine(
        ext, study.record, starts, study.refine_settings, t_start=fit[0], t_end=fit[1], prefer="screening"
    )
    return ext, {**starts.get(res.start, start), **res.params}, res


def fit_bic(study, system, values: dict[str, float]) -> float:
    """BIC of a model's simulation from rest on the fitting part: every deck channel's residual in
    units of its noise (the nominal deck's fit test's), and its trainable parameters."""
    record, m = study.record, fit_mask(study.record, study.fit)
    meas, _, names = channels(record)
    sim = simulated_channels(system, [values], record)[0]
    sd = np.array([study.noise.get(n) or np.std(meas[m, i]) for i, n in enumerate(names)], float)
    r = (sim[m] - meas[m]) / np.maximum(sd, 1e-300)
    chi2, n = float(np.sum(r**2)), int(r.size)
    k = sum(1 for s in system.param_specs() if s.trainable)
    return chi2 + k * float(np.log(max(n, 1))) if np.isfinite(chi2) else float("inf")


def choose(tried: list[tuple[Scored, DeckState, dict]]) -> tuple[Scored, DeckState, dict] | None:
    """Of the candidates tried, the one that fits the fitting part best (BIC) among those that may
    be named; the others' reports say why not."""
    passing = sorted((t for t in tried if t[2]["passes"]), key=lambda t: t[2]["fit_bic"])
    if not passing:
        return None
    best = passing[0]
    best[2]["accepted"], best[2]["outcome"] = True, "named"
    for _, _, rep in passing[1:]:
        rep["outcome"] = (
            f"passes, but {best[0].effect} at support {best[0].support} fits the fitting part better"
        )
    return best
