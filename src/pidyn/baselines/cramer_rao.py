"""Cramer-Rao bound: the smallest error spread any unbiased estimator can reach.

For measurements y_c(t) = simulated response + white Gaussian noise of std sigma_c, the
Fisher information is F = sum_c S_c^T S_c / sigma_c^2 with S_c the sensitivity of channel c
to the parameters. The sensitivities are the exact ones of the shooting problem (one
segment from rest, ``pidyn.refine.problem``), taken in the parameters' unconstrained
coordinates and reported relative to each value, so sqrt(diag(F^-1)) gives each parameter's
relative standard deviation. Use it on your own data with the identified model: it tells
which parameters the record can determine.
"""

from __future__ import annotations

import numpy as np

from pidyn.refine.problem import Channel, ShootingProblem, segment_bounds
from pidyn.refine.uncertainty import _dvalue_draw


def cramer_rao(
    system,
    params: dict[str, float],
    t: np.ndarray,
    f: np.ndarray,
    noise_level: float,
    channels: tuple[str, ...] = ("x", "v"),
    substeps: int = 4,
) -> dict:
    """Relative standard deviations (%) and the correlation matrix of the parameter estimates.

    ``noise_level``: noise std as a fraction of each channel's RMS (as in ``add_noise``),
    channels of every degree of freedom.
    """
    n = system.n_dof
    probe = ShootingProblem(system, t, f, [Channel("x", 0, np.zeros(len(t)), 1.0)], segment_bounds(t, None),
                            substeps, fixed_state0=np.zeros(system.n_state), fixed=params)
    u = probe.pack({s.name: params[s.name] for s in probe.specs}, np.zeros((1, system.n_state)))
    Y, R = probe.simulate(u)
    clean = {"x": Y[:, 0, :n], "v": Y[:, 0, n:2 * n], "a": R[:, 0, n:2 * n]}
    chans = [Channel(c, d, clean[c][:, d], 1.0) for c in channels for d in range(n)]
    names = probe.names
    if noise_level <= 0:
        return {"names": names, "std_pct": {k: 0.0 for k in names}, "correlation": np.eye(len(names)).tolist(),
                "noise_level": noise_level}
    for ch in chans:
        ch.sigma = noise_level * float(np.sqrt(np.mean(ch.data**2)))
    prob = ShootingProblem(system, t, f, chans, segment_bounds(t, None), substeps, fixed_state0=np.zeros(system.n_state),
                           fixed=params)
    _, J, _, _ = prob.linearize(u)
    # unconstrained -> relative coordinates: dr/d ln(value) = dr/draw * value / (dvalue/draw)
    rel = np.array([params[s.name] / _dvalue_draw(s, float(u[i])) for i, s in enumerate(prob.specs)])
    Jr = J[:, : prob.n_theta] * rel[None, :]
    cov = np.linalg.pinv(Jr.T @ Jr)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    corr = cov / np.outer(std, std).clip(1e-300)
    return {"names": names, "std_pct": {k: float(100 * s) for k, s in zip(names, std)},
            "correlation": corr.tolist(), "noise_level": noise_level}

