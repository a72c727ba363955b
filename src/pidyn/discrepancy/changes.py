"""Changes in time: is the structure on the held-out data still the one that was fitted?

A structural health monitoring user meets damage as "the model was fine until time t, then
the structure changed". When the change falls late in the fitting part, or after it, the
screening on the fitting part has little or nothing to see. Two pieces close that gap:

* :func:`heldout_check` compares the nominal model's simulation error on the held-out part
  with its error on the fitting part, each above the measurement noise. A model that is far
  worse on data it was not fitted on is evidence in itself.
* :func:`locate_change` then searches the whole record (or a given span) for a step in a
  nominal parameter (stiffness or damping) on the weak-form rows: the profile of the residual
  over the change time gives the time, a likelihood-ratio interval for it, and the size of
  the step.

:func:`running_estimate` refits the nominal parameters in sliding windows over the record:
the figure a user reads the change from.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pidyn.discrepancy.effects import EFFECTS, get_effect
from pidyn.discrepancy.regression import lstsq
from pidyn.discrepancy.screening import weak_system

log = logging.getLogger(__name__)

#: chi-square(1) 95 % quantile: the profile-likelihood interval of the change time
CHI2_95 = 3.841


@dataclass
class Change:
    """A step in one nominal parameter at ``t_change``."""

    effect: str  # stiffness_loss or damping_change
    parameter: str  # the nominal parameter that changes
    t_change: float
    ci95: tuple[float, float]
    fraction: float  # relative change of the parameter (a stiffness loss of 30 %: -0.3)
    delta_bic: float
    explained: float  # share of the residual the step removes
    profile: dict[str, list[float]] = field(default_factory=dict)
    #: share of the held-out rows' residual the step removes, fitted without them (None: no rows)
    heldout_gain: float | None = None

    def to_dict(self) -> dict:
        return {
            "effect": self.effect,
            "parameter": self.parameter,
            "t_change": self.t_change,
            "t_change_ci95": list(self.ci95),
            "fraction": self.fraction,
            "delta_bic": self.delta_bic,
            "explained": self.explained,
            "heldout_gain": self.heldout_gain,
        }

    def effect_parameters(self) -> dict[str, float]:
        """The library effect's parameters (what the extension starts from)."""
        return get_effect(self.effect).from_change(self.fraction, self.t_change)

    def sentence(self, unit: str = "s") -> str:
        what = get_effect(self.effect).changes
        how = "fell" if self.fraction < 0 else "rose"
        return (
            f"the structure changed at t = {self.t_change:.2f} {unit} (95 % interval {self.ci95[0]:.2f}-"
            f"{self.ci95[1]:.2f} {unit}): its {what} {how} by {100 * abs(self.fraction):.0f} %"
        )


@dataclass
class StepRegression:
    """The nominal model's weak-form regression and the signals a step in time is built from:
    parameter names, columns ``A0`` and target ``y`` (one row per window), each window's first
    and last time, the smoothed x and x' on the record's times, the weak form."""

    names: list[str]
    A0: np.ndarray
    y: np.ndarray
    t_first: np.ndarray
    t_last: np.ndarray
    x: np.ndarray
    v: np.ndarray
    t: np.ndarray
    weak: Any

    @classmethod
    def of(cls, regression: tuple, s, weak) -> StepRegression:
        """From ``weak_system``'s (names, A0, y) on the signals ``s``."""
        w = 2 * weak.half + 1
        return cls(*regression, weak.t[weak.starts], weak.t[weak.starts + w - 1], s.x, s.v, s.t, weak)


def locate_change(
    reg: StepRegression,
    rows: np.ndarray,
    n_eff: float,
    params: dict[str, str],
    nominal: dict[str, float],
    n_grid: int = 1500,
    heldout: np.ndarray | None = None,
) -> Change | None:
    """The best single step in a nominal parameter over the regression's rows ``rows``.

    ``params`` maps each candidate effect to the nominal parameter it steps (``stiffness_loss``:
    ``k``, ``damping_change``: ``c``); its column is that parameter's force times H(t - t_c).
    For every t_c on a grid over the rows' span the nominal parameters and the step are fitted
    together; the residual's profile over t_c gives the estimate and its 95 % interval
    (n_eff log RSS(t_c) / RSS_min <= chi2_1(0.95)). None when nothing improves on no step.
    ``heldout`` (rows no fit uses): the step's ``heldout_gain`` there, whether it persists.
    """
    A0, y, t = reg.A0, reg.y, reg.t
    A = A0[rows]
    theta0 = lstsq(A, y[rows])
    rss0 = float(np.sum((y[rows] - A @ theta0) ** 2))
    has_ho = heldout is not None and bool(np.any(heldout))
    rss0_ho = float(np.sum((y[heldout] - A0[heldout] @ theta0) ** 2)) if has_ho else None
    lo, hi = float(reg.t_first[rows].min()), float(reg.t_last[rows].max())
    # the change time on the samples themselves (at most n_grid of them): no finer than the data
    inner = np.flatnonzero((t > lo) & (t < hi))
    grid = t[inner[:: max(1, int(np.ceil(len(inner) / n_grid)))]]
    best: Change | None = None
    base = _NoStep(rows, heldout if has_ho else None, rss0, rss0_ho, grid, n_eff)
    for effect, pname in params.items():
        force = {"k": reg.x, "k1": reg.x, "c": reg.v}.get(pname)
        if force is None or pname not in reg.names:
            continue
        cand = _best_step(effect, pname, force, reg, base, nominal)
        if best is None or cand.delta_bic < best.delta_bic:
            best = cand
    return best


@dataclass
class _NoStep:
    """The rows a step is fitted on and judged by, the misfit without a step there, and the
    grid of change times."""

    rows: np.ndarray
    heldout: np.ndarray | None
    rss0: float
    rss0_ho: float | None
    grid: np.ndarray
    n_eff: float


def _best_step(
    effect: str, pname: str, force: np.ndarray, reg: StepRegression, base: _NoStep, nominal: dict[str, float]
) -> Change:
    """The best step of ``pname`` (its force ``force``) over the grid of change times: the
    estimate, its profile interval, its BIC against no step, its held-out gain."""
    A0, y, t, weak = reg.A0, reg.y, reg.t, reg.weak
    rows, heldout, rss0, rss0_ho, grid, n_eff = (
        base.rows,
        base.heldout,
        base.rss0,
        base.rss0_ho,
        base.grid,
        base.n_eff,
    )
    rss, coefs = _step_profile(A0[rows], y[rows], rows, weak, force, t, grid)
    j = int(np.argmin(rss))
    gain_ho = None
    if heldout is not None:  # the best step, fitted on ``rows``, predicting the rows no fit used
        gain_ho = _step_heldout_gain(
            A0, y, rows, heldout, weak.project(force * (t >= grid[j]))[:, 0], rss0_ho
        )
    prof = n_eff * np.log(np.maximum(rss, 1e-300) / max(rss[j], 1e-300))
    inside = np.flatnonzero(prof <= CHI2_95)
    # the interval reaches to the neighbouring grid points: it is never narrower than the grid
    ci = (float(grid[max(inside.min() - 1, 0)]), float(grid[min(inside.max() + 1, len(grid) - 1)]))
    delta_bic = n_eff * np.log(max(rss[j], 1e-300) / max(rss0, 1e-300)) + 2 * np.log(n_eff)
    base = nominal.get(pname, 1.0)
    return Change(
        effect,
        pname,
        float(grid[j]),
        ci,
        float(coefs[j] / base),
        float(delta_bic),
        float(1 - rss[j] / max(rss0, 1e-300)),
        {"t": grid.tolist(), "profile": prof.tolist()},
        gain_ho,
    )


def _step_profile(
    A: np.ndarray, y: np.ndarray, rows: np.ndarray, weak, force: np.ndarray, t: np.ndarray, grid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The residual sum of squares and the step's coefficient for a step at every grid time,
    the nominal parameters fitted with it."""
    rss = np.empty(len(grid))
    coefs = np.empty(len(grid))
    for i, tc in enumerate(grid):
        B = weak.project(force * (t >= tc))[:, 0]
        M = np.column_stack([A, B[rows]])
        theta = lstsq(M, y)
        rss[i] = float(np.sum((y - M @ theta) ** 2))
        coefs[i] = theta[-1]
    return rss, coefs


def _step_heldout_gain(
    A0: np.ndarray, y: np.ndarray, rows: np.ndarray, heldout: np.ndarray, B: np.ndarray, rss0_ho: float
) -> float:
    """The step's column ``B`` fitted on ``rows`` with the nominal ones, predicting ``heldout``:
    the share of the nominal model's held-out misfit it removes."""
    theta = lstsq(np.column_stack([A0[rows], B[rows]]), y[rows])
    rss_ho = float(np.sum((y[heldout] - np.column_stack([A0[heldout], B[heldout]]) @ theta) ** 2))
    return float(1 - rss_ho / max(rss0_ho, 1e-300))


def running_estimate(
    names: list[str],
    A0: np.ndarray,
    y: np.ndarray,
    centers: np.ndarray,
    width: float,
    step: float | None = None,
) -> dict[str, np.ndarray]:
    """The nominal parameters refitted in sliding windows of ``width`` seconds (weak-form rows
    whose centres fall inside), every ``step`` seconds: how the structure's stiffness and
    damping move over the record."""
    step = width / 4 if step is None else step
    mids = np.arange(centers[0] + width / 2, centers[-1] - width / 2 + 1e-9, step)
    out = {"t": mids, **{n: np.full(len(mids), np.nan) for n in names}}
    for i, tm in enumerate(mids):
        m = np.abs(centers - tm) <= width / 2
        if m.sum() > 2 * len(names):
            theta = lstsq(A0[m], y[m])
            for j, n in enumerate(names):
                out[n][i] = theta[j]
    return out


def locate_step(
    nominal,
    values: dict[str, float],
    s,
    f: np.ndarray,
    x_raw: np.ndarray,
    weak,
    fit: tuple[float, float],
    held: tuple[float, float],
    mass_known: bool,
    candidates: dict[str, str],
    th,
    whole_record: bool,
) -> tuple[Change | None, tuple[float, float], tuple[float, float]]:
    """A step in stiffness or damping: its time, interval and size, and the split to measure it on.

    ``whole_record`` (the nominal model failed on the held-out part): search every row of the
    record; a change found late or after the split moves the split to halfway between the
    change and the record's end, the change is then estimated again on the new fitting part
    only, and the gain is measured on the rest, which no fit has used. Otherwise the search
    runs on the fitting part (the screening already named the time-varying effect).

    A step that fits the rows after its fitting part worse than no step (held-out gain below
    ``th.min_step_heldout_gain``) does not persist: a stiffness lower only in the strong motion
    depends on the amplitude (softening), it is no damage. Nothing is named then, the split stays
    where it was, and the screening's rule for a step in time holds here too."""
    search = _step_search(
        weak_system(nominal, values, s, f, x_raw, weak, mass_known), s, weak, candidates, values
    )
    t_end = float(s.t[-1])
    fit0, held0 = fit, held
    change = search(t_end if whole_record else fit[1])
    if not _nameable(change, candidates, values, th):
        return None, fit, held
    if whole_record:
        change, fit, held = _search_again(change, search, fit, held, t_end, values)
        if change is None:
            return None, fit0, held0
    if not th.step_persists(change.heldout_gain):
        log.info(
            "%s, but the step does not persist: fitted up to %.4g s it fits the rest worse than no step "
            "(held-out gain %.2f); a change in time lasts, a stiffness or damping that differs only in the "
            "strong motion depends on the amplitude; none is named",
            change.sentence(),
            fit[1],
            change.heldout_gain,
        )
        return None, fit0, held0
    return change, fit, held


def _step_search(regression: tuple, s, weak, candidates: dict[str, str], values: dict[str, float]):
    """``search(end)``: the best step over the weak-form rows that end by ``end``, its held-out
    gain on the rows after it (``locate_change``)."""
    reg = StepRegression.of(regression, s, weak)

    def search(end: float):
        rows = reg.t_last <= end + 1e-9
        n_eff = max(rows.sum() / weak.rows_per_independent, 2.0)
        return locate_change(reg, rows, n_eff, candidates, values, heldout=reg.t_first >= end - 1e-9)

    return search


def _nameable(change: Change | None, candidates: dict[str, str], values: dict[str, float], th) -> bool:
    """The best step is one the library can name: inside its range, no stiffening, and passing
    the screening's thresholds."""
    if change is not None and not EFFECTS[change.effect].admissible(change.effect_parameters(), values):
        log.info(
            "the best step in time, %s, is not one the library can name (outside its range)",
            change.sentence(),
        )
        return False
    if change is not None and is_stiffening(change):
        return False
    if change is None or change.delta_bic > -th.min_delta_bic or change.explained < th.min_cv_gain:
        log.info(
            "no step in %s explains the residual%s",
            " or ".join(sorted(set(candidates.values()))),
            "" if change is None else f" (best: {change.sentence()}, dBIC {change.delta_bic:.1f})",
        )
        return False
    return True


def _search_again(
    change: Change, search, fit: tuple[float, float], held: tuple[float, float], t_end: float, values: dict
) -> tuple[Change | None, tuple[float, float], tuple[float, float]]:
    """A change found on the whole record, late in or beyond the fitting part: the split moves to
    halfway between it and the record's end and the change is estimated again on the new fitting
    part. None when the new estimate is a stiffening or outside the library's range."""
    cut = max(fit[1], change.t_change + 0.5 * (t_end - change.t_change))
    if cut > fit[1]:
        log.info(
            "the change lies at %.4g s, late in or beyond the fitting part: fitting now %.4g-%.4g s, "
            "held out %.4g-%.4g s",
            change.t_change,
            fit[0],
            cut,
            cut,
            held[1],
        )
        fit, held = (fit[0], cut), (cut, held[1])
    again = search(fit[1])
    if again is not None and is_stiffening(again):
        return None, fit, held
    change = again if again is not None else change
    if not EFFECTS[change.effect].admissible(change.effect_parameters(), values):
        log.info(
            "re-estimated on the new fitting part, %s is outside the library's range; none is named",
            change.sentence(),
        )
        return None, fit, held
    return change, fit, held


def is_stiffening(change: Change) -> bool:
    """A stiffness that rises at some time is not a stiffness loss: under an earthquake it is
    the mark of a stiffness that depends on the amplitude (softening in the strong motion,
    stiffer again as the motion dies down), which no change in time explains. Say so, name
    nothing."""
    if get_effect(change.effect).changes != "stiffness" or change.fraction <= 0:
        return False
    log.info(
        "the best step in time is a stiffness rise (%s): that is an amplitude-dependent stiffness, not damage; "
        "no change in time is named",
        change.sentence(),
    )
    return True
