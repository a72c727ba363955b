"""Bouc-Wen hysteresis: a spring whose force lags the displacement through a latent state."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm, _abs, _clamp_min, _spow


class BoucWenHysteresis(ForceTerm):
    """k z with z' = x' - gamma |x'| |z|^(n-1) z - beta x' |z|^n (Bouc 1967, Wen 1976).

    The paper's Eq. 16 uses this term alone as the restoring force (no elastic part).
    """

    name = "hysteresis"
    n_latent = 1
    is_the_spring = True

    def __init__(
        self,
        k: float = 12.0,
        beta: float = 1.0,
        gamma: float = 2.0,
        n: float = 2.0,
        param: str = "k",
        shape_scale: float = 1.0,
        gamma_lower: float | None = None,
        beta_lower: float = 0.0,
    ) -> None:
        """``shape_scale`` sizes beta's and gamma's bounds (+-10 x it): they scale with
        displacement^-n, so a response in centimetres needs a larger range than one in metres.
        ``gamma_lower`` (default -10 x shape_scale) can keep beta + gamma > 0 (bounded z).
        ``beta_lower`` < 0 lets beta take either sign (a box transform): the Bouc-Wen
        benchmark's own x'|z|^n coefficient is negative, a hardening loop."""
        self.k, self.beta, self.gamma, self.n, self.param = k, beta, gamma, n, param
        self.shape_scale = shape_scale
        self.gamma_lower = -10.0 * shape_scale if gamma_lower is None else gamma_lower
        self.beta_lower = beta_lower
        self.linear = (param,)

    def specs(self):
        S = self.shape_scale
        signed = self.beta_lower < 0
        return [
            ParamSpec(self.param, init=self.k, scale=self.k, true=self.k, unit="N/m"),
            ParamSpec(
                "beta",
                init=self.beta,
                scale=S,
                true=self.beta,
                lower=self.beta_lower,
                upper=10.0 * S,
                transform="box" if signed else "log",
            ),
            ParamSpec(
                "gamma",
                init=self.gamma,
                scale=S,
                true=self.gamma,
                lower=self.gamma_lower,
                upper=10.0 * S,
                transform="box",
            ),
            ParamSpec("n", init=self.n, scale=1.0, true=self.n, lower=0.5, upper=6.0, transform="box"),
        ]

    def force(self, t, x, v, z, p):
        return p[self.param] * z[..., 0]

    def latent_rate(self, t, x, v, z, p):
        z0 = z[..., 0]
        zn = _spow(z0, p["n"])
        sgn_z = z0 / _clamp_min(_abs(z0), 1e-12)
        rate = v - p["gamma"] * _abs(v) * zn * sgn_z - p["beta"] * v * zn
        return rate[..., None]

    def formula(self, p):
        return f"{p[self.param]:.5g} z"
