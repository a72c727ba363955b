"""The natural period and damping ratio through a record, window by window, by output error.

The weak form's running estimate (``changes.running_estimate``) regresses the force on the
measured motion. On an accelerometer record the motion is integrated from a small difference of
large accelerations, and that regression sees little. Here each window is fitted on what the
sensors read instead: the model's stiffness and damping, with the window's own initial state
(a shooting segment), every other parameter held at the whole record's fit. The period and the
damping ratio follow, with 95 % intervals from the window's Gauss-Newton covariance, so a
period that lengthens in strong motion and recovers in the coda shows as such, and how sure
each window is of it.
"""

from __future__ import annotations

import copy
import logging

import numpy as np
from scipy.optimize import least_squares

from pidyn.compiled.kernel import tapes_kept
from pidyn.params import to_theta
from pidyn.refine.problem import ShootingProblem, record_channels
from pidyn.refine.uncertainty import residual_covariance
from pidyn.simulate import input_hold
from pidyn.systems.base import merge_specs
from pidyn.systems.modal import damping_params, stiffness_params

log = logging.getLogger(__name__)

Z95 = 1.959963984540054


@tapes_kept()  # one system, hundreds of simulations: its tape recorded once
def running_modes(
    record, system, values: dict[str, float], width: float, step: float | None = None, substeps: int = 4
) -> dict[str, np.ndarray]:
    """Windows of ``width`` s every ``step`` s (default a quarter width): their centre ``t``,
    ``period`` and ``damping`` with ``period_lo/hi`` and ``damping_lo/hi`` (95 %), and the peak
    of the first measured channel there (``peak``). A window whose fit fails gives NaN."""
    local = _window_system(system, values)
    step = width / 4 if step is None else step
    t = record.t
    dt = float(t[1] - t[0])
    n_win = max(2, int(round(width / dt)))
    starts = np.arange(0, len(t) - n_win, max(1, int(round(step / dt))))
    channels = record_channels(record, system.n_dof)
    rows = {
        key: np.full(len(starts), np.nan)
        for key in ("t", "period", "period_lo", "period_hi", "damping", "damping_lo", "damping_hi", "peak")
    }
    m = float(values.get("m", 1.0))
    theta = to_theta([s for s in local.param_specs() if s.trainable], values)
    # the last fitted window: its start and simulated states (the whole window's: a failed window's
    # successor starts further on, still inside it)
    warm: tuple[int, np.ndarray] | None = None
    for i, i0 in enumerate(starts):
        i1 = i0 + n_win
        rows["t"][i] = 0.5 * (t[i0] + t[i1])
        rows["peak"][i] = float(np.nanmax(np.abs(channels[0].data[i0 : i1 + 1])))
        u0 = _warm_start(warm, i0, theta, local.n_state)
        try:
            res = _window_fit(local, t, record.f, channels, i0, i1, u0, substeps, input_hold(record))
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            continue
        (k, c), cov, states = res
        if not (k > 0 and np.all(np.isfinite(cov))):
            continue
        warm = (int(i0), states) if np.all(np.isfinite(states)) else None
        # log coordinates (the specs' log transforms): the intervals map monotonically
        sk, sc = np.sqrt(max(cov[0, 0], 0.0)), np.sqrt(max(cov[1, 1], 0.0))
        rho = cov[0, 1] / max(sk * sc, 1e-300)
        period = 2 * np.pi * np.sqrt(m / k)
        rows["period"][i] = period
        zeta = c / (2 * np.sqrt(k * m))
        s_log_zeta = np.sqrt(max(sc**2 + 0.25 * sk**2 - rho * sc * sk, 0.0))
        rows["damping"][i] = zeta
        with np.errstate(over="ignore"):  # a window that knows nothing of them: an open interval
            rows["period_lo"][i], rows["period_hi"][i] = (
                period * np.exp(-0.5 * Z95 * sk),
                period * np.exp(0.5 * Z95 * sk),
            )
            rows["damping_lo"][i], rows["damping_hi"][i] = (
                zeta * np.exp(-Z95 * s_log_zeta),
                zeta * np.exp(Z95 * s_log_zeta),
            )
    return rows


def _window_system(system, values: dict[str, float]):
    """``system`` with its one stiffness and one damping trainable, everything else held at ``values``."""
    ks, cs = stiffness_params(system), damping_params(system)
    if len(ks) != 1 or len(cs) != 1:
        raise ValueError(f"{system.name}: a running period needs one stiffness and one damping parameter")
    local = copy.copy(system)
    local._specs = merge_specs(
        system.param_specs(),
        {
            n: {"trainable": n in (ks[0], cs[0]), **({"init": float(values[n])} if n in values else {})}
            for n in (s.name for s in system.param_specs())
        },
    )
    return local


def _warm_start(warm, i0: int, theta0: np.ndarray, n_state: int) -> np.ndarray:
    """A window's unknowns (log k, log c, initial state): the whole record's k and c, and the
    previous window's simulated state at this window's start where they overlap (the windows
    overlap by half or more, so the fit starts next to its end); else from rest. Each window
    starts from the record's values, not the previous window's: a quiet window that drove the
    damping towards zero (log c without bound) would otherwise hand that on to every later one."""
    if warm is not None and 0 <= i0 - warm[0] < len(warm[1]):
        j0, states = warm
        return np.concatenate([theta0, states[i0 - j0]])
    return np.concatenate([theta0, np.zeros(n_state)])


def _window_fit(
    system, t, f, channels, i0: int, i1: int, u0: np.ndarray, substeps: int, hold: str = "linear"
):
    """(k, c), their covariance in log coordinates and the simulated states on samples i0..i1,
    the window's initial state free (the sandwich where the residuals are a model's smooth error,
    as a measured record's are)."""
    seg_channels = [
        type(ch)(ch.kind, ch.dof, ch.data[i0 : i1 + 1], max(float(np.nanstd(ch.data[i0 : i1 + 1])), 1e-300))
        for ch in channels
    ]
    problem = ShootingProblem(
        system,
        t[i0 : i1 + 1],
        np.asarray(f)[i0 : i1 + 1],
        seg_channels,
        np.array([0, i1 - i0]),
        substeps,
        hold=hold,  # read from the window alone: the interpolation filter touches a few samples at its ends
    )

    # the iterations on a forward-difference Jacobian from one batched plain simulation (a quarter
    # of the exact dual-number one's cost); the covariance below from the exact one
    fun, jac = problem.fd_fun_and_jac()
    sol = least_squares(fun, u0, jac=jac, method="lm", max_nfev=60)
    r, J, _, C = problem.linearize(sol.x)
    cov = residual_covariance(problem, r, J, C)[0]  # the sandwich where the window's residuals are correlated
    names = problem.names
    vals = problem.values(sol.x[: problem.n_theta])
    ik, ic = names.index(_name(system, "k")), names.index(_name(system, "c"))
    cov_kc = cov[np.ix_([ik, ic], [ik, ic])]
    states = np.asarray(problem.simulate(sol.x)[0])[:, 0, :]
    return (vals[names[ik]], vals[names[ic]]), cov_kc, states


def _name(system, which: str) -> str:
    return (stiffness_params(system) if which == "k" else damping_params(system))[0]


def period_varies(
    running: dict,
    width: float,
    margin: float = 0.03,
    min_peak_share: float = 0.1,
    period: float | None = None,
) -> dict:
    """Does the period change through the record beyond what each window is sure of? Among
    windows whose motion reaches ``min_peak_share`` of the record's peak, any two a full width
    apart (no shared samples): the largest lower 95 % bound of one against the smallest upper
    bound of the other, apart by more than ``margin`` of the period: no one time-invariant model
    holds. Every such pair counts, not one tiling of the record: a tiling started at the first
    window can step over the strongest seconds, where a softening shows most. ``period``: the
    nominal model's; a window whose period is not within a factor of two of it is not counted
    (a window fitted to a quiet stretch can return a mode near the sampling rate)."""
    t = np.asarray(running["t"])
    p = np.asarray(running["period"], float)
    ok = np.isfinite(p)
    if period is not None:
        ok &= (p >= 0.5 * period) & (p <= 2.0 * period)
    peak = np.asarray(running["peak"])
    ok &= peak >= min_peak_share * float(np.nanmax(peak)) if ok.any() else ok
    idx = np.flatnonzero(ok)
    apart = np.abs(t[idx, None] - t[None, idx]) >= width - 1e-9
    chosen = _independent(t[idx], width)
    if len(chosen) < 3:
        return {
            "varies": False,
            "windows": len(chosen),
            "reason": "fewer than 3 independent windows with motion",
        }
    lo, hi = np.asarray(running["period_lo"])[idx], np.asarray(running["period_hi"])[idx]
    gaps = np.where(apart, lo[:, None] - hi[None, :], -np.inf)
    a, b = np.unravel_index(int(np.argmax(gaps)), gaps.shape)
    i_long, i_short = int(idx[a]), int(idx[b])
    gap = float(gaps[a, b])
    varies = bool(gap > margin * float(np.median(p[idx])))
    return {
        "varies": varies,
        "windows": len(idx),
        "gap_s": gap,
        "longest": {
            "t": float(t[i_long]),
            "period": float(running["period"][i_long]),
            "ci95": [float(running["period_lo"][i_long]), float(running["period_hi"][i_long])],
        },
        "shortest": {
            "t": float(t[i_short]),
            "period": float(running["period"][i_short]),
            "ci95": [float(running["period_lo"][i_short]), float(running["period_hi"][i_short])],
        },
    }


def _independent(t: np.ndarray, width: float) -> list[int]:
    """The most windows of ``t`` (sorted) that share no samples, taken greedily from the first."""
    chosen, last = [], -np.inf
    for i, ti in enumerate(t):
        if ti - last >= width - 1e-9:
            chosen.append(i)
            last = ti
    return chosen
