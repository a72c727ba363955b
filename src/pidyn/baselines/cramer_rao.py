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
    noise_level: float | dict[str, float],
    channels: tuple[str, ...] | dict[str, list[int]] = ("x", "v"),
    substeps: int = 4,
) -> dict:
    """Relative standard deviations (%) and the correlation matrix of the parameter estimates.

    ``channels``: kinds measured on every degree of freedom (``("x", "v")``), or the measured
    floors per kind (``{"a": [1, 3, 5]}``, 1-based, as ``Record.sensors()`` gives them).
    ``noise_level``: noise std as a fraction of each sensor's RMS (as in ``add_noise``; an
    accelerometer's RMS is that of the absolute acceleration under ground excitation), one
    value or one per kind.
    """
    n = system.n_dof
    layout = dict(channels) if isinstance(channels, dict) else {c: list(range(1, n + 1)) for c in channels}
    levels = dict(noise_level) if isinstance(noise_level, dict) else {c: float(noise_level) for c in layout}
    probe = ShootingProblem(system, t, f, [Channel("x", 0, np.zeros(len(t)), 1.0)], segment_bounds(t, None),
                            substeps, fixed_state0=np.zeros(system.n_state), fixed=params)
    u = probe.pack({s.name: params[s.name] for s in probe.specs}, np.zeros((1, system.n_state)))
    Y, R = probe.simulate(u)
    clean = {"x": Y[:, 0, :n], "v": Y[:, 0, n:2 * n], "a": R[:, 0, n:2 * n]}
    chans = [Channel(c, fl - 1, clean[c][:, fl - 1], 1.0) for c, floors in layout.items() for fl in floors]
    names = probe.names
    if max(levels.values(), default=0.0) <= 0:
        return {"names": names, "std_pct": {k: 0.0 for k in names}, "correlation": np.eye(len(names)).tolist(),
                "noise_level": noise_level, "channels": layout}
    ground = np.asarray(f, float) if system.excitation == "ground" else 0.0
    for ch in chans:
        sensed = ch.data + (ground if ch.kind == "a" else 0.0)  # an accelerometer measures x'' + ag
        ch.sigma = max(levels.get(ch.kind, 0.0), 1e-12) * float(np.sqrt(np.mean(sensed**2)))
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
            "correlation": corr.tolist(), "noise_level": noise_level, "channels": layout}
