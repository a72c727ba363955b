"""Quadratic (velocity-squared) damping."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm, _abs


class QuadraticDamping(ForceTerm):
    """c2 x'|x'|: drag-type damping that grows with the square of the velocity."""

    name = "quadratic_damping"
    symbol = "x'|x'|"
    linear = ("c2",)

    def __init__(self, c2: float = 0.5) -> None:
        self.c2 = c2

    def specs(self):
        return [ParamSpec("c2", init=self.c2, scale=self.c2, true=self.c2, unit="N s^2/m^2")]

    def force(self, t, x, v, z, p):
        return p["c2"] * v * _abs(v)

    def formula(self, p):
        return f"{p['c2']:.5g} x'|x'|"
