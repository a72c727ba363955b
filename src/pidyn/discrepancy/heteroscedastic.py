"""Residuals whose scale follows the response: the weights of the heteroscedastic likelihood.

A linear model's error on an earthquake record is mostly the structure's own nonlinearity, so it
is large in the strong seconds and small in the coda. Least squares with one noise level then lets
the strong seconds alone set every parameter, and the coda is seen through a model they chose.

The alternative noise model gives each sample a standard deviation proportional to the measured
response's envelope w (its RMS over a few periods, floored at a share of its peak so that the quiet
seconds before the shaking do not dominate). Both models have one free scale; their
log-likelihoods on a fit's residuals differ by n ln(mean r^2 / mean (r / w)^2) (w of geometric
mean 1), counted here over the residuals' independent samples. Where that favours the envelope by
more than ``min_gain`` (the diagnosis's evidence level), the fit is redone with each residual
divided by w: the maximum-likelihood estimate under the noise model the residuals support."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from pidyn.discrepancy.confirm import independent_samples


@dataclass
class ScaleTest:
    """The envelope noise model against one noise level, on a fit's residuals."""

    statistic: float  # 2 x log-likelihood gain of the envelope model, over independent samples
    independent_samples: float
    window_s: float
    floor: float
    follows: bool  # the statistic above the evidence level: refit with the weights

    def to_dict(self) -> dict:
        return asdict(self)


def envelope(y: np.ndarray, dt: float, window_s: float, floor: float = 0.1) -> np.ndarray:
    """The envelope w of ``y`` ((N,) or (N, p): the channels' mean square): RMS over ``window_s``,
    floored at ``floor`` of its peak, scaled to geometric mean 1."""
    y = np.asarray(y, float)
    power = np.mean(y**2, axis=1) if y.ndim == 2 else y**2
    size = max(int(round(window_s / dt)), 3)
    env = np.sqrt(uniform_filter1d(power, size, mode="nearest"))
    env = np.maximum(env, floor * float(np.max(env)) + 1e-300)
    return env / np.exp(np.mean(np.log(env)))


def scale_test(
    r: np.ndarray, w: np.ndarray, window_s: float, floor: float = 0.1, min_gain: float = 10.0
) -> ScaleTest:
    """Does the residual ``r`` (N,) follow the envelope ``w`` (N, geometric mean 1)?"""
    r = np.asarray(r, float)
    n = len(r)
    gain = n * np.log(np.mean(r**2) / np.mean((r / w) ** 2))
    m = independent_samples(r)
    stat = float(gain * m / n)
    return ScaleTest(stat, float(m), float(window_s), float(floor), bool(stat > min_gain))
