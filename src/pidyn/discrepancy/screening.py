"""Name the cause: test the nominal model's unexplained force against each candidate effect.

For every effect (and every grid point of its nonlinear parameters) the nominal
parameters and the effect's coefficients are refitted together on the weak-form rows of
the fitting part; the nominal parameters must be free, because they absorb part of any
missing effect. Evidence per effect:

* ``explained``: share of the nominal model's residual the effect removes (fitting part);
* ``force_share``: the same, as a share of the whole weak-form force (a relevance floor);
* ``delta_bic``: change of the Bayesian information criterion, counting overlapping rows as
  the independent rows their noise is worth (``WeakForm.rows_per_independent``) and
  grid-searched parameters as parameters;
* ``cv_gain``: reduction of the residual in blocked cross-validation over the fitting part
  (five contiguous blocks, each predicted from the other four: a check that does not reward
  flexibility, and does not depend on how much the structure moves in one particular tail);
* ``heldout_gain``: the same on the held-out rows, with coefficients from the fitting part.

``score = -delta_bic``. The verdict is ``discrepancy`` only when the best effect passes the
evidence, cross-validation and relevance thresholds; otherwise ``none``: nothing explains
more than noise and the model's own error would. A fit that does not describe a physical
structure (``Effect.admissible``: a damping change to no damping or less) is no evidence,
a step in time must persist into the held-out part, and any other effect must not predict
the held-out part worse than the nominal model where a generic force predicts it better.
Between passing effects that BIC does not separate (less than ``tie_delta_bic``) the one
with the clearly better cross-validation gain is named.

Two effects at once can hide behind a third: dry friction plus a stop look, one at a time,
most like a hardening cubic spring, and friction alone, its force soaked up by the refitted
viscous damping, may score nothing. Every pair of effects is therefore fitted jointly too.
When the best pair leaves out the best single effect and beats every pair that holds it, or
holds it while that effect alone fails and the pair passes by a wide margin, the pair's
member with the better single score is named first (``structure["pair"]`` says why); the
next screening, of the model extended with it, must still find the partner on its own.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Candidate, Effect, Signals
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.regression import _cv_rss, _folds, fit_candidate, lstsq
from pidyn.discrepancy.screening_rules import (
    Thresholds,
    _mark_fleeting_step,
    _mark_heldout_miss,
    _passes,
    _verdict,
)
from pidyn.discrepancy.verdicts import Verdict
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.terms import latent_path
from pidyn.weak_form import WeakForm

#: effects that exclude each other in one model, by their ``exclusive_group`` (one change in time
#: at a time)
EXCLUSIVE = tuple(
    {n for n, e in EFFECTS.items() if e.exclusive_group == g}
    for g in dict.fromkeys(e.exclusive_group for e in EFFECTS.values() if e.exclusive_group)
)


@dataclass
class Screening:
    """Outcome of the screening: nominal refit, ranking, verdict."""

    nominal_params: dict[str, float]
    ranking: list[Evidence]
    verdict: Verdict
    cause: str | None
    rss_nominal_fit: float
    rss_nominal_heldout: float | None
    n_independent: float
    residual_rows: dict[str, np.ndarray] = field(default_factory=dict)
    structure: dict = field(default_factory=dict)  # how much a generic f(x, x') explains


def nominal_columns(
    system: SDOFSystem, s: Signals, values: dict[str, float]
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Columns for the nominal parameters the force is linear in, and the remaining fixed force."""
    names, cols = [], []
    remainder = np.zeros_like(s.x)
    for term in system.terms:
        # along the measured signals: a friction found in an earlier step is no sharper than the
        # velocity noise, as in its screening (sharper, noise near rest reads as a damping change)
        if term.n_latent:  # e.g. a hysteresis found in an earlier step: its z along the measured motion
            remainder = remainder + term.measured_force(
                s.t, s.x, s.v, latent_path(term, s.t, s.x, s.v, values), values, s.v_noise
            )
            continue
        # a stop's kg is refitted too (its gap held): held at the value fitted without the next
        # effect, it keeps what it soaked up of that effect (friction, seen by a gap alone)
        if len(term.linear) != 1 or not (_is_linear_only(term) or term.proportional):
            remainder = remainder + term.measured_force(s.t, s.x, s.v, None, values, s.v_noise)
            continue
        name = term.linear[0]
        cols.append(term.measured_force(s.t, s.x, s.v, None, {**values, name: 1.0}, s.v_noise))
        names.append(name)
    return names, np.stack(cols, axis=1) if cols else np.zeros((len(s.x), 0)), remainder


def weak_system(
    system: SDOFSystem,
    values: dict[str, float],
    s: Signals,
    f: np.ndarray,
    x_raw: np.ndarray,
    weak: WeakForm,
    mass_known: bool = True,
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The nominal model's weak-form regression: parameter names, columns A0 and target y
    (one row per window), so that A0 theta = y holds where the nominal model is right."""
    m = values["m"]
    forcing = -m * f if system.excitation == "ground" else f
    names, cols, remainder = nominal_columns(system, s, values)
    y = weak.project(forcing - remainder)[:, 0]
    A0 = weak.project(cols)
    inertia = weak.inertia(x_raw, 1.0)
    if mass_known:
        y = y - m * inertia
    else:
        A0 = np.column_stack([inertia, A0])
        names = ["m", *names]
    return names, A0, y


def _is_linear_only(term) -> bool:
    return {sp.name for sp in term.specs()} == set(term.linear)


def screen(
    system: SDOFSystem,
    values: dict[str, float],
    s: Signals,
    f: np.ndarray,
    x_raw: np.ndarray,
    weak: WeakForm,
    fit_end: float,
    mass_known: bool = True,
    effects: dict[str, Effect] | None = None,
    thresholds: Thresholds | None = None,
) -> Screening:
    """Rank the candidate effects for a nominal ``system`` (parameters ``values``).

    ``f`` is the excitation (ground acceleration or force), ``x_raw`` the measured
    displacement (the inertia term uses it unsmoothed), rows with windows inside
    [0, fit_end] fit, rows wholly after it are held out.
    """
    effects = LIBRARY if effects is None else effects
    th = thresholds or Thresholds()
    base = _nominal_fit(system, values, s, f, x_raw, weak, fit_end, mass_known)
    # every candidate's columns projected once: the single and the pair fits use them all
    projected = {n: [(c, weak.project(c.columns)) for c in e.candidates(s)] for n, e in effects.items()}
    ranking = [_score_effect(eff, projected[n], base, values) for n, eff in effects.items()]
    structure = _structure(s, weak, base)
    ranking.sort(key=lambda r: -np.inf if r.score is None else r.score, reverse=True)
    for r in ranking:
        _mark_fleeting_step(r, th)
        _mark_heldout_miss(r, structure, th)
        r.passes = bool(r.score is not None and _passes(r, th))
    pairs = _score_pairs(effects, projected, ranking, base, values)
    structure["pair"] = pair_lead(ranking, pairs, structure, th)
    verdict, cause = _verdict(ranking, structure, th)
    return _screening(base, weak, ranking, structure, verdict, cause)


def _screening(base, weak: WeakForm, ranking: list[Evidence], structure: dict, verdict, cause) -> Screening:
    """The screening's outcome with the nominal regression's residual rows."""
    return Screening(
        nominal_params=dict(zip(base.names, map(float, base.theta0))),
        ranking=ranking,
        verdict=verdict,
        cause=cause,
        rss_nominal_fit=base.rss0,
        rss_nominal_heldout=base.rss0_ho,
        n_independent=float(base.n_eff),
        residual_rows={
            "t": weak.centers,
            "residual": base.y - base.A0 @ base.theta0,
            "fit": base.fit,
            "heldout": base.ho,
        },
        structure=structure,
    )


@dataclass
class _NominalFit:
    """The nominal model's weak-form regression: what every effect is scored against."""

    names: list[str]
    A0: np.ndarray
    y: np.ndarray
    fit: np.ndarray  # rows in the fitting part
    ho: np.ndarray  # rows wholly held out
    folds: list
    theta0: np.ndarray
    rss0: float
    rss0_ho: float | None
    rss0_cv: float
    ss_total: float
    n_eff: float  # independent rows


def _nominal_fit(
    system: SDOFSystem,
    values: dict[str, float],
    s: Signals,
    f: np.ndarray,
    x_raw: np.ndarray,
    weak: WeakForm,
    fit_end: float,
    mass_known: bool,
) -> _NominalFit:
    names, A0, y = weak_system(system, values, s, f, x_raw, weak, mass_known)
    starts = weak.starts
    w = 2 * weak.half + 1
    t_first, t_last = weak.t[starts], weak.t[starts + w - 1]
    fit = t_last <= fit_end + 1e-9
    ho = t_first >= fit_end - 1e-9
    if fit.sum() < 4:
        raise ValueError(
            f"only {int(fit.sum())} weak-form windows fit in the fitting part (0-{fit_end:g} s); "
            "use a longer record or a shorter fitting split"
        )
    folds = _folds(fit, 5)
    theta0 = lstsq(A0[fit], y[fit])
    r0 = y - A0 @ theta0
    return _NominalFit(
        names=names,
        A0=A0,
        y=y,
        fit=fit,
        ho=ho,
        folds=folds,
        theta0=theta0,
        rss0=float(np.sum(r0[fit] ** 2)),
        rss0_ho=float(np.sum(r0[ho] ** 2)) if ho.any() else None,
        rss0_cv=_cv_rss(A0, y, folds),
        ss_total=float(np.sum(y[fit] ** 2)),
        n_eff=max(fit.sum() / weak.rows_per_independent, 2.0),
    )


def _score_effect(
    eff: Effect, projected: list[tuple[Candidate, np.ndarray]], base: _NominalFit, values: dict[str, float]
) -> Evidence:
    """The effect's best candidate added to the nominal regression: its BIC score, shares of the
    force it explains (in sample, cross-validated, held out) and its parameters."""
    best = None
    for cand, B in projected:
        row = fit_candidate(cand, base.A0, B, base.y, base.fit, base.ho)
        if row is not None and not _admissible(
            eff, cand, list(row["coef"].values()), row["theta"], base, values
        ):
            row = None
        if row is not None:
            row["B"] = B
        if row is not None and (best is None or row["rss_fit"] < best["rss_fit"]):
            best = row
    if best is None:
        return Evidence(eff.name, note="no physical fit (wrong sign)")
    rss0, rss0_cv, rss0_ho = base.rss0, base.rss0_cv, base.rss0_ho
    rss_cv = _cv_rss(np.column_stack([base.A0, best.pop("B")]), base.y, base.folds, n_fixed=base.A0.shape[1])
    k = len(best["coef"]) + eff.n_grid
    rss = max(best["rss_fit"], 1e-300)
    delta_bic = base.n_eff * np.log(rss / max(rss0, 1e-300)) + k * np.log(base.n_eff)
    nominal_fit = {n: best["theta"][i] for i, n in enumerate(base.names)}
    params = eff.parameters(best["coef"], best["fixed"], {**values, **nominal_fit})
    return Evidence(
        eff.name,
        step_in_time=eff.step_in_time,
        score=float(-delta_bic),
        delta_bic=float(delta_bic),
        explained=float(1 - rss / max(rss0, 1e-300)),
        force_share=float((rss0 - rss) / max(base.ss_total, 1e-300)),
        cv_gain=float(1 - rss_cv / max(rss0_cv, 1e-300)),
        heldout_gain=None if rss0_ho is None else float(1 - best["rss_ho"] / max(rss0_ho, 1e-300)),
        parameters={k_: float(v) for k_, v in params.items()},
        nominal_refit={k_: float(v) for k_, v in nominal_fit.items()},
    )


#: a pair's two grids are searched in full up to this many joint candidates, by alternating
#: (coordinate) search from each effect's best single candidate beyond it
PAIR_FULL_GRID = 600


def _admissible(
    eff: Effect, cand: Candidate, coef, theta, base: _NominalFit, values: dict[str, float]
) -> bool:
    """The effect's own test of a fit (``Effect.admissible``), on its physical parameters."""
    nominal = {**values, **{n: float(theta[i]) for i, n in enumerate(base.names)}}
    params = eff.parameters(dict(zip(cand.coef_names, map(float, coef))), cand.fixed, nominal)
    return eff.admissible(params, nominal)


def _score_pairs(
    effects: dict[str, Effect],
    projected: dict[str, list[tuple[Candidate, np.ndarray]]],
    ranking: list[Evidence],
    base: _NominalFit,
    values: dict[str, float],
) -> list[dict]:
    """Every pair of effects fitted jointly with the nominal parameters, best first."""
    fitted = {r.effect for r in ranking if r.score is not None}
    cols = {n: c for n, c in projected.items() if n in fitted}

    def rss(a: str, b: str, i: int, j: int) -> float:
        (ca, Ba), (cb, Bb) = cols[a][i], cols[b][j]
        names = tuple(f"{a}.{n}" for n in ca.coef_names) + tuple(f"{b}.{n}" for n in cb.coef_names)
        both = Candidate(
            f"{a}+{b}",
            np.empty((0, 0)),
            names,
            positive=(ca.positive or (False,) * Ba.shape[1]) + (cb.positive or (False,) * Bb.shape[1]),
        )
        row = fit_candidate(both, base.A0, np.column_stack([Ba, Bb]), base.y, base.fit, base.ho)
        if row is None:  # a coefficient of the wrong sign
            return np.inf
        coef, theta = list(row["coef"].values()), row["theta"]
        if not (
            _admissible(effects[a], ca, coef[: Ba.shape[1]], theta, base, values)
            and _admissible(effects[b], cb, coef[Ba.shape[1] :], theta, base, values)
        ):
            return np.inf
        return row["rss_fit"]

    out = []
    for a, b in itertools.combinations(sorted(cols), 2):
        if any({a, b} <= g for g in EXCLUSIVE):
            continue
        best, i, j = _best_pair_point(lambda i, j, a=a, b=b: rss(a, b, i, j), len(cols[a]), len(cols[b]))
        if not np.isfinite(best):
            continue
        k = sum(len(cols[e][q][0].coef_names) + effects[e].n_grid for e, q in ((a, i), (b, j)))
        delta_bic = base.n_eff * np.log(max(best, 1e-300) / max(base.rss0, 1e-300)) + k * np.log(base.n_eff)
        A = np.column_stack([base.A0, cols[a][i][1], cols[b][j][1]])
        out.append(
            {
                "effects": [a, b],
                "score": float(-delta_bic),
                "delta_bic": float(delta_bic),
                "explained": float(1 - best / max(base.rss0, 1e-300)),
                "cv_gain": float(
                    1 - _cv_rss(A, base.y, base.folds, n_fixed=base.A0.shape[1]) / max(base.rss0_cv, 1e-300)
                ),
            }
        )
    out.sort(key=lambda p: p["score"], reverse=True)
    return out


def _best_pair_point(rss, na: int, nb: int) -> tuple[float, int, int]:
    """The grid point (i, j) of a pair with the least misfit ``rss(i, j)``: the whole grid when
    it is small, else three passes of coordinate search."""
    if na * nb <= PAIR_FULL_GRID:
        return min((rss(i, j), i, j) for i in range(na) for j in range(nb))
    i = j = 0
    for _ in range(3):
        i = min(range(na), key=lambda q: rss(q, j))
        j = min(range(nb), key=lambda q: rss(i, q))
    return rss(i, j), i, j


def pair_lead(ranking: list[Evidence], pairs: list[dict], structure: dict, th: Thresholds) -> dict | None:
    """The effect to name first when a pair explains the residual better than greedy
    one-at-a-time naming would (see the module's notes); None leaves the single ranking in charge."""
    if not pairs or not ranking or ranking[0].score is None:
        return None
    singles = {r.effect: r.score if r.score is not None else -np.inf for r in ranking}
    # a step that does not last, or an effect that misses the held-out part where a generic force
    # does not, leads nowhere: the rules that refuse it alone refuse it in a pair too
    refused = {r.effect for r in ranking if r.persists is False or r.heldout_miss}
    pairs = [p for p in pairs if not refused & set(p["effects"])]
    if not pairs:
        return None
    top, s_top = ranking[0].effect, ranking[0].score
    best = pairs[0]
    a, b = best["effects"]
    if best["delta_bic"] > -th.min_delta_bic or best["cv_gain"] < th.min_cv_gain:
        return None
    if (
        structure.get("cv_gain") is not None
        and structure["cv_gain"] >= th.min_structure_gain
        and best["cv_gain"] < th.min_library_share * structure["cv_gain"]
    ):
        return None  # the pair, too, explains only a small part of a clearly structured residual
    with_top = [p["score"] for p in pairs if top in p["effects"]]
    if top not in (a, b):
        rival = max(with_top) if with_top else -np.inf
        if best["score"] - rival < th.pair_margin or best["score"] - s_top < th.pair_margin:
            return None
        why = (
            f"{a} and {b} together score {best['score']:.1f}, more than {top} with any partner "
            f"({rival:.1f}) or alone ({s_top:.1f}): {top} stood in for them"
        )
    elif not ranking[0].passes and best["score"] - s_top >= th.min_delta_bic:
        other = b if a == top else a
        why = f"{top} alone scores {s_top:.1f}, with {other} {best['score']:.1f}: the two are needed together"
    else:
        return None
    lead = max((a, b), key=lambda e: singles[e])
    return {**best, "lead": lead, "why": why}


def generic_columns(s: Signals, knots: int = 11) -> np.ndarray:
    """A generic force f1(x) + f2(x') with no physics in it: piecewise-linear hat functions on
    ``knots`` points over the range of x and of x' (bounded: they cannot blow up where a
    cross-validation block reaches beyond the others' range), and a smoothed sign of x' for
    any dry friction."""
    cols = []
    grid = np.linspace(-1.0, 1.0, knots)
    h = grid[1] - grid[0]
    for sig in (s.x, s.v):
        u = sig / max(np.max(np.abs(sig)), 1e-300)
        cols += [np.maximum(1.0 - np.abs(u - g) / h, 0.0) for g in grid]
    cols.append(np.tanh(s.v / max(s.friction_eps, 1e-300)))
    return np.stack(cols, axis=1)


def _structure(s: Signals, weak: WeakForm, base: _NominalFit) -> dict:
    """How much of the nominal residual a generic f(x, x') explains: the yardstick for
    "clearly structured" and for whether a named effect explains a fair share of it."""
    A0, y, fit, ho, folds = base.A0, base.y, base.fit, base.ho, base.folds
    rss0, rss0_cv, rss0_ho, n_eff = base.rss0, base.rss0_cv, base.rss0_ho, base.n_eff
    G = weak.project(generic_columns(s))
    A = np.column_stack([A0, G])
    ridge = np.r_[np.zeros(A0.shape[1]), np.full(G.shape[1], 1e-3)]
    theta = lstsq(A[fit], y[fit], ridge)
    r = y - A @ theta
    rss = max(float(np.sum(r[fit] ** 2)), 1e-300)
    return {
        "cv_gain": float(1 - _cv_rss(A, y, folds, ridge) / max(rss0_cv, 1e-300)),
        "explained": float(1 - rss / max(rss0, 1e-300)),
        "delta_bic": float(n_eff * np.log(rss / max(rss0, 1e-300)) + G.shape[1] * np.log(n_eff)),
        "heldout_gain": None if rss0_ho is None else float(1 - np.sum(r[ho] ** 2) / max(rss0_ho, 1e-300)),
        "columns": int(G.shape[1]),
    }
