"""A profile-likelihood interval for the period of a one-mode linear model.

The refinement's interval of the period is the sandwich covariance drawn through the modal map:
a quadratic picture of the cost about the estimate. On a weak record the cost in the period can
be flat over a wide range, or lean to one side, and a quadratic says neither. The profile does:
along the period family (``StructuralSystem.period_scaling``: the stiffnesses times lam^2, so
the period over lam) the stiffnesses are held and every other parameter is fitted by output
error from rest, and the confidence set is the periods whose fit is not significantly worse
than the best.

The residuals of a real record are a model's smooth error, correlated over several periods, and
the plain likelihood ratio n ln(RSS / RSS_min) would take them as white noise and make the set
far too narrow. So the statistic is adjusted (Chandler and Bate 2007, for a scalar parameter):
times the ratio of the naive variance of log lam (s^2 (J^T J)^-1) to its sandwich variance (the
Newey-West long-run covariance of the score over the refinement's bandwidth), so that where the
profile is quadratic the set is the sandwich's Wald interval, and where it is not, the set
follows the cost. Compared with chi^2_1's 95 % point."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import least_squares

from pidyn.compiled.kernel import tapes_kept
from pidyn.parallel import map_ordered
from pidyn.params import to_theta, trainable_specs
from pidyn.refine.output_error import output_error_problem
from pidyn.refine.period_scan import profile_point, scaled
from pidyn.refine.uncertainty import bandwidth, residual_correlation, sandwich
from pidyn.systems.modal import linear_matrices, modal_properties

#: chi^2 with one degree of freedom, its 95 % point
CHI2_95 = 3.841458820694124


@dataclass
class PeriodProfile:
    """The adjusted profile statistic of the period, and the 95 % set it gives."""

    periods: list[float]  # the grid, ascending (s)
    statistic: list[float | None]  # adjusted likelihood ratio at each (null: did not simulate)
    period_min: float  # where the output-error profile is lowest (s)
    ci95: list[float | None]  # the connected part of the set about period_min; null: open to the grid's end
    adjustment: float  # naive / sandwich variance of log period (1: white residuals)
    lags: int  # the sandwich's bandwidth (samples)
    disjoint: bool  # another part of the grid, outside ci95, is inside the set too
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)


@tapes_kept()  # one system, hundreds of simulations: its tape recorded once
def profile_period(
    system,
    record,
    values: dict[str, float],
    substeps: int = 4,
    sds: float = 4.0,
    points: int = 13,
    profile_nfev: int = 20,
) -> PeriodProfile | None:
    """The profile over ``record`` (the span the estimate was fitted to) about ``values``; None
    for a model that is not one linear mode (no family, or several modes moving together, whose
    common factor is not any one mode's period). Grid: ``points`` within ``sds`` sandwich
    standard deviations of log period each way, and a coarse grid out to a factor of two."""
    powers = {k: p for k, p in system.period_scaling().items() if k in values}
    held = [k for k, p in powers.items() if p == 2.0]
    if not held or getattr(system, "n_dof", 1) != 1:
        return None
    t0 = time.perf_counter()
    problem, theta = output_error_problem(record, system, values, substeps)
    specs = trainable_specs(system)
    free = np.array([s.name not in held for s in specs])
    fun, jac = problem.fd_fun_and_jac()
    with np.errstate(all="ignore"):
        sol = least_squares(fun, theta, jac=jac, method="trf", max_nfev=30)
    if not np.all(np.isfinite(sol.fun)):
        return None
    fixed = {s.name: float(s.init) for s in system.param_specs()}  # the mass and other held values
    best = {**fixed, **values, **problem.values(sol.x)}
    r, rss_min = sol.fun, float(sol.fun @ sol.fun)
    adjustment, sd, lags = _adjustment(problem, jac(sol.x), r, specs, best, powers, held, free)
    grid = np.unique(
        np.concatenate([np.linspace(-sds * sd, sds * sd, points), np.log(np.geomspace(0.5, 2.0, 13))])
    )
    costs = map_ordered(  # u = log lam: the period over e^u
        lambda u: profile_point(
            problem, to_theta(specs, scaled(best, powers, float(np.exp(u)))), free, profile_nfev
        )[1],
        list(grid),
    )
    stats = []
    for cost in costs:
        rss = 2.0 * cost
        stats.append(
            adjustment * len(r) * np.log(max(rss, rss_min) / rss_min) if np.isfinite(rss) else np.inf
        )
    t_min = _period(system, best)
    periods, stat = t_min / np.exp(grid[::-1]), np.asarray(stats)[::-1]
    lo, hi, disjoint = _connected_set(periods, stat, t_min)
    return PeriodProfile(
        periods=periods.tolist(),
        statistic=[float(s) if np.isfinite(s) else None for s in stat],
        period_min=t_min,
        ci95=[lo, hi],
        adjustment=adjustment,
        lags=lags,
        disjoint=disjoint,
        seconds=time.perf_counter() - t0,
    )


def _adjustment(problem, J, r, specs, best, powers, held, free) -> tuple[float, float, int]:
    """Naive over sandwich variance of log lam at the output-error optimum, the sandwich standard
    deviation of log lam, and the bandwidth. The interest direction moves the held stiffnesses
    along the family; the other parameters keep their own columns."""
    h = 1e-4
    theta = to_theta(specs, best)
    dtheta = (to_theta(specs, scaled(best, {k: powers[k] for k in held}, float(np.exp(h)))) - theta) / h
    Jp = np.column_stack([J @ dtheta, J[:, free]])
    A_inv = np.linalg.pinv(Jp.T @ Jp, rcond=1e-12, hermitian=True)
    naive = float(r @ r) / len(r) * A_inv[0, 0]
    lags = bandwidth(residual_correlation(problem, r), len(r) // max(len(problem.channels), 1))
    robust = float((A_inv @ sandwich(Jp, r, problem.channel_slices(), lags) @ A_inv)[0, 0]) if lags else naive
    if not (naive > 0 and robust > 0):
        return 1.0, 0.05, lags
    return naive / robust, float(np.sqrt(robust)), lags


def _period(system, values: dict[str, float]) -> float:

    return float(modal_properties(*linear_matrices(system, values))["period_s"][0])


def _connected_set(
    periods: np.ndarray, stat: np.ndarray, t_min: float
) -> tuple[float | None, float | None, bool]:
    """The part of {stat <= chi2_1(95 %)} that holds ``t_min``, its ends interpolated between grid
    points (None where it runs to the grid's end), and whether the set has other parts."""
    inside = stat <= CHI2_95
    i0 = int(np.argmin(np.abs(periods - t_min)))
    lo_i, hi_i = i0, i0
    while lo_i > 0 and inside[lo_i - 1]:
        lo_i -= 1
    while hi_i < len(periods) - 1 and inside[hi_i + 1]:
        hi_i += 1

    def cross(a: int, b: int) -> float:  # between an inside point a and an outside point b
        sa, sb = stat[a], stat[b]
        if not np.isfinite(sb):
            return float(periods[b])
        w = (CHI2_95 - sa) / (sb - sa)
        return float(np.exp(np.log(periods[a]) + w * (np.log(periods[b]) - np.log(periods[a]))))

    lo = cross(lo_i, lo_i - 1) if lo_i > 0 else None
    hi = cross(hi_i, hi_i + 1) if hi_i < len(periods) - 1 else None
    disjoint = bool(inside[:lo_i].any() or inside[hi_i + 1 :].any())
    return lo, hi, disjoint
