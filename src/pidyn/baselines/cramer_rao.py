"""Cramer-Rao bound: the smallest error spread any unbiased estimator can reach.

For measurements y_c(t) = simulated response + white Gaussian noise of std sigma_c, the
Fisher information is F = sum_c S_c^T S_c / sigma_c^2 with S_c the sensitivity of channel c
to the parameters. The sensitivities are the exact ones of the shooting problem (one
segment from rest, ``pidyn.refine.problem``), taken in the parameters' unconstrained
coordinates and reported relative to each value, so sqrt(diag(F^-1)) gives each parameter's
relative standard deviation. Use it on your own data with the identified model: it tells
which parameters the record can determine.

Two bounds: ``std_pct`` for a record known to start at rest (as an earthquake record does),
and ``std_pct_unknown_start`` with the initial state as unknowns too. On hysteretic systems
the second is about twice the first for beta, gamma and n: the latent state's memory lets an
initial z mimic them.
"""

from __future__ import annotations

import numpy as np

from pidyn.params import dvalue_draw
from pidyn.refine.problem import Channel, ShootingProblem, segment_bounds


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
    probe, u, chans = _clean_channels(system, params, t, f, layout, substeps)
    names = probe.names
    if max(levels.values(), default=0.0) <= 0:
        return {
            "names": names,
            "std_pct": {k: 0.0 for k in names},
            "std_pct_unknown_start": {k: 0.0 for k in names},
            "correlation": np.eye(len(names)).tolist(),
            "noise_level": noise_level,
            "channels": layout,
        }
    # an accelerometer measures x'' + ag (several inputs: the model's reading is absolute already)
    ground = np.asarray(f, float) if system.excitation == "ground" and system.n_inputs == 1 else 0.0
    for ch in chans:
        sensed = ch.data + (ground if ch.kind == "a" else 0.0)
        ch.sigma = max(levels.get(ch.kind, 0.0), 1e-12) * float(np.sqrt(np.mean(sensed**2)))
    std, corr, std_free = _relative_std(system, params, t, f, chans, substeps, u)
    return {
        "names": names,
        "std_pct": {k: float(100 * s) for k, s in zip(names, std)},
        "std_pct_unknown_start": {k: float(100 * s) for k, s in zip(names, std_free)},
        "correlation": corr.tolist(),
        "noise_level": noise_level,
        "channels": layout,
    }


def _clean_channels(system, params: dict[str, float], t, f, layout: dict[str, list[int]], substeps: int):
    """The noise-free response on every measured channel (the model simulated from rest), with
    the problem that simulated it and its packed parameters."""
    n = system.n_dof
    probe = ShootingProblem(
        system,
        t,
        f,
        [Channel("x", 0, np.zeros(len(t)), 1.0)],
        segment_bounds(t, None),
        substeps,
        fixed_state0=np.zeros(system.n_state),
        fixed=params,
    )
    u = probe.pack({s.name: params[s.name] for s in probe.specs}, np.zeros((1, system.n_state)))
    Y, R, A = probe.simulate(u)
    clean = {"x": Y[:, 0, :n], "v": Y[:, 0, n : 2 * n], "a": A[:, 0]}
    chans = [Channel(c, fl - 1, clean[c][:, fl - 1], 1.0) for c, floors in layout.items() for fl in floors]
    return probe, u, chans


def _relative_std(system, params: dict[str, float], t, f, chans: list, substeps: int, u: np.ndarray):
    """Relative standard deviations and correlations of the parameters from the sensitivity of
    the simulated channels: with the start at rest, and with the initial state unknown."""
    # the initial state as unknowns too (columns after the parameters), at rest
    prob = ShootingProblem(system, t, f, chans, segment_bounds(t, None), substeps, fixed=params)
    _, J, _, _ = prob.linearize(prob.pack(params, np.zeros((1, system.n_state))))
    # unconstrained -> relative coordinates: dr/d ln(value) = dr/draw * value / (dvalue/draw)
    nt = prob.n_theta
    rel = np.array([params[s.name] / dvalue_draw(s, float(u[i])) for i, s in enumerate(prob.specs)])
    Jr = J.copy()
    Jr[:, :nt] *= rel[None, :]
    cov = np.linalg.pinv(Jr[:, :nt].T @ Jr[:, :nt])  # the record is known to start at rest
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    corr = cov / np.outer(std, std).clip(1e-300)
    cov_free = np.linalg.pinv(Jr.T @ Jr)[:nt, :nt]  # its initial state is unknown
    std_free = np.sqrt(np.clip(np.diag(cov_free), 0, None))
    return std, corr, std_free
