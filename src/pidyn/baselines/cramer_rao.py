"""Cramer-Rao bound: the smallest error spread any unbiased estimator can reach.

For measurements y_c(t) = simulated response + white Gaussian noise of std sigma_c, the
Fisher information is F = sum_c S_c^T S_c / sigma_c^2 with S_c the sensitivity of channel c
to the parameters. Sensitivities are taken to relative changes (d y / d ln theta), so
sqrt(diag(F^-1)) is directly each parameter's relative standard deviation. Use it on your
own data with the identified model: it tells which parameters the record can determine.
"""

from __future__ import annotations

import numpy as np

from pidyn.baselines.common import fixed_values, trainable_specs
from pidyn.baselines.fastsim import simulate_batch


def cramer_rao(
    system,
    params: dict[str, float],
    t: np.ndarray,
    f: np.ndarray,
    noise_level: float,
    channels: tuple[str, ...] = ("x", "v"),
    rel_step: float = 1e-5,
    substeps: int = 4,
) -> dict:
    """Relative standard deviations (%) and the correlation matrix of the parameter estimates.

    ``noise_level``: noise std as a fraction of each channel's RMS (as in ``add_noise``).
    """
    specs = trainable_specs(system)
    names = [s.name for s in specs]
    n = len(names)
    base = np.array([params[k] for k in names], float)
    P = 2 * n + 1
    batch = {k: np.repeat(base[i], P) for i, k in enumerate(names)}
    for i, k in enumerate(names):
        batch[k][1 + 2 * i] *= 1 + rel_step
        batch[k][2 + 2 * i] *= 1 - rel_step
    batch.update({k: np.full(P, v) for k, v in fixed_values(system).items()})
    out = simulate_batch(system, batch, t, f, substeps=substeps)
    F = np.zeros((n, n))
    for c in channels:
        y = out[c]
        sigma = noise_level * float(np.sqrt(np.mean(y[:, 0] ** 2)))
        S = np.stack([(y[:, 1 + 2 * i] - y[:, 2 + 2 * i]) / (2 * rel_step) for i in range(n)], axis=1)
        if sigma > 0:
            F += S.T @ S / sigma**2
    if noise_level <= 0:
        return {"names": names, "std_pct": {k: 0.0 for k in names}, "correlation": np.eye(n).tolist(),
                "noise_level": noise_level}
    cov = np.linalg.pinv(F)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    corr = cov / np.outer(std, std).clip(1e-300)
    return {"names": names, "std_pct": {k: float(100 * s) for k, s in zip(names, std)},
            "correlation": corr.tolist(), "noise_level": noise_level}
