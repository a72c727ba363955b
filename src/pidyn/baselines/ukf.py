"""Unscented Kalman filter for joint state-parameter estimation (the paper's comparison).

Augmented state [x, x', z, theta] with theta in the same unconstrained coordinates as
PIDynNet (log / logit), a random walk on theta (process noise ``q_param`` per step in those
coordinates, so every parameter is equally free to move in relative terms), RK4 prediction
of all sigma points as one batch, and measurements x, x' (and x'' if recorded) with noise
variance from the known noise level (a floor keeps the filter consistent on clean data).
Scaled sigma points (van der Merwe): alpha, beta, kappa.

The parameter random walk ``q_param`` decides how fast the filter may move the parameters:
too small and it freezes before it has converged, too large and it chases the noise. A
fair baseline tunes it on the data: ``tune`` runs the filter for each value of a grid and
keeps the one with the largest innovation log-likelihood, sum over steps of
-1/2 (log det S + nu^T S^-1 nu), which needs no truth (a stated, data-only method).
"""

from __future__ import annotations

import time

import numpy as np

from pidyn.baselines.common import BaselineResult, from_theta, starting_point
from pidyn.baselines.fastsim import simulate_batch
from pidyn.data.sources import Record


def unscented_kalman_filter(
    record: Record,
    system,
    noise_level: float = 0.0,
    init: dict[str, float] | None = None,
    init_param_std: float = 0.7,
    q_param: float = 1e-5,
    q_state: float = 1e-10,
    r_floor: float = 1e-3,
    alpha: float = 0.5,
    beta: float = 2.0,
    kappa: float = 0.0,
    substeps: int = 2,
    thin: int = 10,
    tune: list[float] | None = None,
) -> BaselineResult:
    """Joint state-parameter UKF; ``tune``: a grid of ``q_param`` values to choose from by the
    innovation likelihood (None: use ``q_param`` as given)."""
    if tune:
        kw = dict(noise_level=noise_level, init=init, init_param_std=init_param_std, q_state=q_state,
                  r_floor=r_floor, alpha=alpha, beta=beta, kappa=kappa, substeps=substeps, thin=thin)
        return _tuned(record, system, list(tune), kw)
    t0 = time.perf_counter()
    specs, fixed, theta0 = starting_point(system, init)
    nz, npar = system.n_latent, len(specs)
    n = 2 + nz + npar
    chans = [("x", record.x[:, 0])]
    if record.v is not None:
        chans.append(("v", record.v[:, 0]))
    if record.a is not None:
        chans.append(("a", record.a[:, 0]))
    rms = {c: float(np.sqrt(np.mean(y**2))) for c, y in chans}
    R = np.diag([max(noise_level, r_floor) ** 2 * rms[c] ** 2 for c, _ in chans])
    m = np.zeros(n)
    m[2 + nz :] = theta0
    P = np.diag([1e-12, 1e-12] + [1e-12] * nz + [init_param_std**2] * npar)
    Q = np.diag([q_state * rms["x"] ** 2, q_state * rms.get("v", rms["x"]) ** 2] + [q_state * rms["x"] ** 2] * nz
                + [q_param] * npar)
    lam = alpha**2 * (n + kappa) - n
    wm = np.full(2 * n + 1, 1 / (2 * (n + lam)))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + 1 - alpha**2 + beta
    traj: list[dict] = []
    loglik = 0.0
    t, f = record.t, record.f
    for i in range(len(t) - 1):
        # --- predict
        try:
            S = np.linalg.cholesky((n + lam) * P)
        except np.linalg.LinAlgError:
            P = 0.5 * (P + P.T) + 1e-12 * np.eye(n)
            S = np.linalg.cholesky((n + lam) * P + 1e-9 * np.eye(n))
        X = np.concatenate([m[:, None], m[:, None] + S, m[:, None] - S], axis=1)  # (n, 2n+1)
        p = from_theta(specs, X[2 + nz :])
        p.update({k: np.full(X.shape[1], v) for k, v in fixed.items()})
        state0 = (X[0], X[1], X[2 : 2 + nz].T if nz else np.zeros((X.shape[1], 0)))
        out = simulate_batch(system, p, t[i : i + 2], f[i : i + 2], substeps=substeps, state0=state0)
        Xp = X.copy()
        Xp[0], Xp[1] = out["x"][1], out["v"][1]
        if nz:
            Xp[2 : 2 + nz] = out["z"][1].T
        Xp = np.nan_to_num(Xp, nan=0.0, posinf=1e6, neginf=-1e6)
        m = Xp @ wm
        D = Xp - m[:, None]
        P = (wc * D) @ D.T + Q
        # --- update with the measurement at t[i+1]
        Y = [Xp[0], Xp[1]] if record.v is not None else [Xp[0]]
        if record.a is not None:
            Y.append(out["a"][1])
        Y = np.array(Y)
        y_mean = Y @ wm
        DY = Y - y_mean[:, None]
        Syy = (wc * DY) @ DY.T + R
        Cxy = (wc * D) @ DY.T
        Sinv = np.linalg.inv(Syy)
        K = Cxy @ Sinv
        y = np.array([c[1][i + 1] for c in chans])
        nu = y - y_mean
        sign, logdet = np.linalg.slogdet(Syy)
        loglik += -0.5 * (logdet + float(nu @ Sinv @ nu)) if sign > 0 else -np.inf
        m = m + K @ nu
        P = P - K @ Syy @ K.T
        P = 0.5 * (P + P.T)
        if i % thin == 0 or i == len(t) - 2:
            vals = from_theta(specs, m[2 + nz :])
            traj.append({"t": float(t[i + 1]), **{k: float(v) for k, v in vals.items()}})
    est = {k: float(v) for k, v in from_theta(specs, m[2 + nz :]).items()}
    res = BaselineResult("ukf", est, time.perf_counter() - t0, trajectory=traj)
    res.loglik = float(loglik)
    return res


def _tuned(record: Record, system, grid: list[float], kw: dict) -> BaselineResult:
    """The filter for each ``q_param`` of the grid; the one with the largest innovation
    log-likelihood wins (the data choose, no truth involved)."""
    t0 = time.perf_counter()
    runs = [unscented_kalman_filter(record, system, q_param=float(q), **kw) for q in grid]
    best = max(range(len(runs)), key=lambda i: runs[i].loglik if np.isfinite(runs[i].loglik) else -np.inf)
    out = runs[best]
    out.seconds = time.perf_counter() - t0
    out.note = (f"q_param={grid[best]:.3g} chosen from {len(grid)} values by the innovation log-likelihood "
                f"({out.loglik:.6g})")
    return out
