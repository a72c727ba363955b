"""The linear dashpot and spring: the nominal model's terms."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm


class ViscousDamping(ForceTerm):
    name = "viscous_damping"
    symbol = "x'"
    linear = ("c",)

    def __init__(self, c: float = 0.5) -> None:
        self.c = c

    def specs(self) -> list[ParamSpec]:
        return [ParamSpec("c", init=self.c, scale=self.c, true=self.c, unit="N s/m")]

    def force(self, t, x, v, z, p):
        return p["c"] * v

    def formula(self, p):
        return f"{p['c']:.5g} x'"


class LinearStiffness(ForceTerm):
    name = "linear_stiffness"
    symbol = "x"

    def __init__(self, k: float = 15.0, param: str = "k") -> None:
        self.k, self.param = k, param
        self.linear = (param,)

    def specs(self):
        return [ParamSpec(self.param, init=self.k, scale=self.k, true=self.k, unit="N/m")]

    def force(self, t, x, v, z, p):
        return p[self.param] * x

    def formula(self, p):
        return f"{p[self.param]:.5g} x"
