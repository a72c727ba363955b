"""Unscented Kalman filter for joint state-parameter estimation (the paper's comparison).

Augmented state [x, x', z, theta] (every degree of freedom) with theta in the same unconstrained coordinates as
PIDynNet (log / logit), a random walk on theta (process noise ``q_param`` per step in those
coordinates, so every parameter is equally free to move in relative terms), RK4 prediction
of all sigma points as one batch, and every measured channel (x, x', x'' of any floor; a
floor accelerometer's absolute acceleration is x'' + ag, the same innovation) with noise
variance from the known noise level (a floor keeps the filter consistent on clean data).
Scaled sigma points (van der Merwe): alpha, beta, kappa.

The parameter random walk ``q_param`` decides how fast the filter may move the parameters:
too small and it freezes before it has converged, too large and it chases the noise. A
fair baseline tunes it on the data: with ``q_param=None`` (the default) the filter runs
for each value of the grid ``tune`` and keeps the one with the largest innovation log-likelihood, sum over steps of
-1/2 (log det S + nu^T S^-1 nu), which needs no truth (a stated, data-only method).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from pidyn.baselines.common import BaselineResult, from_theta, starting_point
from pidyn.baselines.registry import estimator, row
from pidyn.data.sources import Record
from pidyn.integrate import input_hold, rk4, stage_excitation
from pidyn.parallel import map_ordered
from pidyn.refine.problem import record_channels

#: the q_param grid searched by default (``baselines.ukf.tune`` in the config mirrors it)
TUNE_GRID = (1e-11, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5)


def unscented_kalman_filter(
    record: Record,
    system,
    noise_level: float = 0.0,
    init: dict[str, float] | None = None,
    init_param_std: float = 0.7,
    q_param: float | None = None,
    q_state: float = 1e-10,
    r_floor: float = 1e-3,
    alpha: float = 0.5,
    beta: float = 2.0,
    kappa: float = 0.0,
    substeps: int = 2,
    thin: int = 10,
    tune: tuple[float, ...] | list[float] = TUNE_GRID,
) -> BaselineResult:
    """Joint state-parameter UKF; ``q_param``: the parameters' random-walk variance per step,
    or None to choose it from the grid ``tune`` by the innovation likelihood."""
    if q_param is None:
        if not len(tune):
            raise ValueError("ukf: q_param is None and the tuning grid is empty; give one of them")
        kw = dict(
            noise_level=noise_level,
            init=init,
            init_param_std=init_param_std,
            q_state=q_state,
            r_floor=r_floor,
            alpha=alpha,
            beta=beta,
            kappa=kappa,
            substeps=substeps,
            thin=thin,
        )
        return _tuned(record, system, list(tune), kw)
    t0 = time.perf_counter()
    specs, fixed, theta0 = starting_point(system, init)
    nd, ns, npar = system.n_dof, system.n_state, len(specs)
    chans = record_channels(record, nd)
    levels = dict(record.meta.noise_levels or {})
    R = np.diag(
        [max(levels.get(c.kind, noise_level), r_floor) ** 2 * _sensor_rms(record, c) ** 2 for c in chans]
    )
    m, P, Q = _prior(record, system, theta0, init_param_std, q_state, q_param)
    lam, wm, wc = _weights(ns + npar, alpha, beta, kappa)
    hold = stage_excitation(record.f, substeps, input_hold(record))
    flt = _Filter(system, specs, fixed, lam, wm, wc, Q, R, chans, substeps, hold)
    traj: list[dict] = []
    loglik = 0.0
    t, f = record.t, record.f
    for i in range(len(t) - 1):
        m, P, ll = _step(flt, m, P, t, f, i)
        loglik += ll
        if i % thin == 0 or i == len(t) - 2:
            vals = from_theta(specs, m[ns:])
            traj.append({"t": float(t[i + 1]), **{k: float(v) for k, v in vals.items()}})
    est = {k: float(v) for k, v in from_theta(specs, m[ns:]).items()}
    res = BaselineResult("ukf", est, time.perf_counter() - t0, trajectory=traj)
    res.loglik = float(loglik)
    return res


@dataclass
class _Filter:
    """What stays the same from step to step: the model, its parameters' coordinates, the sigma
    points' weights, the process and measurement noise, the channels."""

    system: Any
    specs: list
    fixed: dict
    lam: float
    wm: np.ndarray
    wc: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    chans: list
    substeps: int
    stages: np.ndarray | None = None  # the excitation at the RK4 stages (a band-limited record), or linear


def _step(flt: _Filter, m: np.ndarray, P: np.ndarray, t: np.ndarray, f: np.ndarray, i: int):
    """One filter step: the sigma points simulated from t[i] to t[i+1], the predicted belief,
    and its update with the measurement at t[i+1]; returns the new mean, covariance and the
    innovation log-likelihood."""
    system, specs, fixed, chans, substeps = flt.system, flt.specs, flt.fixed, flt.chans, flt.substeps
    lam, wm, wc, Q, R = flt.lam, flt.wm, flt.wc, flt.Q, flt.R
    ns, nd = system.n_state, system.n_dof
    rows = {
        "x": lambda Yp, Ap, d: Yp[:, d],
        "v": lambda Yp, Ap, d: Yp[:, nd + d],
        "a": lambda Yp, Ap, d: Ap[:, d],
    }
    X = _sigma_points(m, P, lam)
    p = from_theta(specs, X[ns:])
    p.update({k: np.full(X.shape[1], v) for k, v in fixed.items()})
    with np.errstate(all="ignore"):
        st = None if flt.stages is None else flt.stages[i : i + 1]
        Ys, Rs = rk4(system, p, t[i : i + 2], f[i : i + 2], X[:ns].T.copy(), substeps=substeps, stages=st)
        A = system.acceleration_output(Rs[1][:, nd : 2 * nd], f[i + 1], p)  # as the accelerometers read
        # a filter that diverges says so by its likelihood (-inf), not by floating-point warnings
        m, P, D = _predicted_belief(X, Ys[1], ns, wm, wc, Q)
        # --- update with the measurement at t[i+1]
        Y = np.nan_to_num(
            np.array([rows[c.kind](Ys[1], A, c.dof) for c in chans]), nan=0.0, posinf=1e6, neginf=-1e6
        )
        m, P, ll = _update(m, P, D, Y, np.array([c.data[i + 1] for c in chans]), R, wm, wc)
    return m, P, ll


def _prior(
    record: Record, system, theta0: np.ndarray, init_param_std: float, q_state: float, q_param: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, covariance and process noise of the augmented state [x, x', z, theta]: the
    structure at rest, the parameters at their start with ``init_param_std``; the states'
    process noise scaled by the record's displacement and velocity spreads."""
    nd, nz, npar = system.n_dof, system.n_latent, len(theta0)
    ns = 2 * nd + nz
    xs, vs = record.state_scales()
    m = np.zeros(ns + npar)
    m[ns:] = theta0
    P = np.diag([1e-12] * ns + [init_param_std**2] * npar)
    Q = np.diag(
        list(q_state * xs**2)
        + list(q_state * vs**2)
        + [q_state * float(np.max(xs)) ** 2] * nz
        + [q_param] * npar
    )
    return m, P, Q


def _predicted_belief(
    X: np.ndarray, Y_states: np.ndarray, ns: int, wm: np.ndarray, wc: np.ndarray, Q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, covariance and sigma deviations after propagating the sigma points ``X`` (their
    states now ``Y_states``); a diverged point is clipped so one bad draw cannot poison the mean."""
    Xp = X.copy()
    Xp[:ns] = Y_states.T
    Xp = np.nan_to_num(Xp, nan=0.0, posinf=1e6, neginf=-1e6)
    m = Xp @ wm
    D = Xp - m[:, None]
    return m, (wc * D) @ D.T + Q, D


def _weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Scaled sigma-point spread lambda and the mean and covariance weights (van der Merwe)."""
    lam = alpha**2 * (n + kappa) - n
    wm = np.full(2 * n + 1, 1 / (2 * (n + lam)))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + 1 - alpha**2 + beta
    return lam, wm, wc


def _sigma_points(m: np.ndarray, P: np.ndarray, lam: float) -> np.ndarray:
    """(n, 2n+1) sigma points; a covariance that lost definiteness to round-off is repaired."""
    n = len(m)
    try:
        S = np.linalg.cholesky((n + lam) * P)
    except np.linalg.LinAlgError:
        P = 0.5 * (P + P.T) + 1e-12 * np.eye(n)
        S = np.linalg.cholesky((n + lam) * P + 1e-9 * np.eye(n))
    return np.concatenate([m[:, None], m[:, None] + S, m[:, None] - S], axis=1)


def _update(
    m: np.ndarray,
    P: np.ndarray,
    D: np.ndarray,
    Y: np.ndarray,
    y: np.ndarray,
    R: np.ndarray,
    wm: np.ndarray,
    wc: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Measurement update from the predicted sigma deviations ``D`` and their measurements
    ``Y``; returns the new mean, covariance and the innovation log-likelihood term."""
    y_mean = Y @ wm
    DY = Y - y_mean[:, None]
    Syy = (wc * DY) @ DY.T + R
    # the filter diverged: no update, no likelihood
    if not (np.all(np.isfinite(Syy)) and np.all(np.isfinite(P))):
        return m, P, -np.inf
    Sinv = np.linalg.inv(Syy)
    K = ((wc * D) @ DY.T) @ Sinv
    nu = y - y_mean
    sign, logdet = np.linalg.slogdet(Syy)
    ll = -0.5 * (logdet + float(nu @ Sinv @ nu)) if sign > 0 else -np.inf
    P = P - K @ Syy @ K.T
    return m + K @ nu, 0.5 * (P + P.T), ll


def _sensor_rms(record: Record, ch) -> float:
    """RMS of what the sensor measured: an accelerometer under ground excitation measures
    x'' + ag, the noise level is a fraction of that."""
    one_ground = record.excitation == "ground" and record.n_inputs == 1  # several: the record's a is absolute
    y = ch.data + (record.f if ch.kind == "a" and one_ground else 0.0)
    return float(np.sqrt(np.mean(y**2)))


def _tuned(record: Record, system, grid: list[float], kw: dict) -> BaselineResult:
    """The filter for each ``q_param`` of the grid; the one with the largest innovation
    log-likelihood wins (the data choose, no truth involved)."""
    t0 = time.perf_counter()
    # the grid's filters are independent: shared among the job's workers (pidyn.parallel)
    runs = map_ordered(lambda q: unscented_kalman_filter(record, system, q_param=float(q), **kw), list(grid))
    finite = [i for i in range(len(runs)) if np.isfinite(runs[i].loglik)]
    if not finite:
        raise RuntimeError(
            f"the filter diverged for every q_param of the grid {grid} (no finite innovation "
            "log-likelihood): start it nearer (system.params.<name>.init) or widen the grid"
        )
    best = max(finite, key=lambda i: runs[i].loglik)
    out = runs[best]
    out.seconds = time.perf_counter() - t0
    out.note = (
        f"q_param={grid[best]:.3g} chosen from {len(grid)} values by the innovation log-likelihood "
        f"({out.loglik:.6g})"
    )
    return out


@estimator("ukf", unscented_kalman_filter, "UKF", parametric=True, order=4)
def _ukf_row(record, system, settings: dict, noise: float) -> dict:
    return row(unscented_kalman_filter(record, system, noise_level=noise, **settings))
