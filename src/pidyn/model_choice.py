"""Whether a richer model that contains a simpler one earns its parameters on the fitting part
alone (the held-out part stays out of every choice).

A likelihood-ratio test on the simulation errors of the same channels over the same span:
n ln(RSS_simple / RSS_rich) is chi-square with as many degrees of freedom as the richer model
has extra parameters when the residuals are white. A model's error on a real record is smooth,
not white; as the refinement's rest test does, the statistic is divided by (1 + rho) / (1 - rho)
for residuals correlated at lag 1 by rho (the variance inflation of an AR(1) sum), so a few
per cent less misfit on a thousand correlated samples does not buy eight parameters.
"""

from __future__ import annotations

import math

from scipy.stats import chi2


def nested_test(
    fit_simple: float, fit_rich: float, n: int, extra: int, lag1: float, level: float = 0.01
) -> dict:
    """The test of a richer model against the simpler one it contains, from their fitting-part
    NRMSEs (same channels and span: the ratio of their squares is the ratio of residual sums),
    ``n`` residuals, ``extra`` parameters more and the richer model's lag-1 residual correlation."""
    if not (fit_simple > 0 and fit_rich > 0 and n > 0 and extra > 0):
        raise ValueError(
            f"nested_test: needs positive errors, samples and extra parameters; got "
            f"{fit_simple}, {fit_rich}, {n}, {extra}"
        )
    rho = min(max(float(lag1), 0.0), 0.9999)
    inflation = (1 + rho) / (1 - rho)
    statistic = n * 2 * math.log(fit_simple / fit_rich) / inflation
    threshold = float(chi2.ppf(1 - level, extra))
    return {
        "statistic": statistic,
        "threshold": threshold,
        "level": level,
        "extra_params": int(extra),
        "samples": int(n),
        "lag1": rho,
        "inflation": inflation,
        "richer": bool(statistic > threshold),
    }
