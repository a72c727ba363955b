"""A quadratic spring: an asymmetric stiffness."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm


class QuadraticStiffness(ForceTerm):
    """k2 x^2: a stiffness that differs in tension and compression (asymmetric)."""

    name = "quadratic_stiffness"
    symbol = "x^2"
    linear = ("k2",)

    def __init__(self, k2: float = 10.0, scale: float | None = None) -> None:
        self.k2, self.scale = k2, scale

    def specs(self):
        s = self.scale or (abs(self.k2) or 1.0)
        return [ParamSpec("k2", init=self.k2, scale=s, true=self.k2, transform="identity", unit="N/m^2")]

    def force(self, t, x, v, z, p):
        return p["k2"] * x**2

    def formula(self, p):
        return f"{p['k2']:.5g} x^2"
