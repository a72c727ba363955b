"""A trilinear spring: a stiffness that changes at two displacements."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm, _relu


class TrilinearSpring(ForceTerm):
    """dk1 (|x| - x1)+ sign(x) + dk2 (|x| - x2)+ sign(x): the stiffness changes at |x| = x1 and
    again at x2 (softening at first yield, hardening at a stop). Not in the discrepancy library:
    it hides an effect the library cannot name."""

    name = "trilinear_spring"
    linear = ("dk1", "dk2")

    def __init__(self, dk1: float = -5.0, x1: float = 0.03, dk2: float = 10.0, x2: float = 0.06) -> None:
        if not 0 < x1 < x2:
            raise ValueError(f"trilinear_spring: need 0 < x1 < x2, got x1={x1}, x2={x2}")
        self.dk1, self.x1, self.dk2, self.x2 = dk1, x1, dk2, x2

    def specs(self):
        return [
            ParamSpec("dk1", init=self.dk1, scale=abs(self.dk1) or 1.0, true=self.dk1, transform="identity"),
            ParamSpec("dk2", init=self.dk2, scale=abs(self.dk2) or 1.0, true=self.dk2, transform="identity"),
            ParamSpec("x1", init=self.x1, scale=self.x1, true=self.x1, trainable=False, unit="m"),
            ParamSpec("x2", init=self.x2, scale=self.x2, true=self.x2, trainable=False, unit="m"),
        ]

    def force(self, t, x, v, z, p):
        return p["dk1"] * (_relu(x - p["x1"]) - _relu(-x - p["x1"])) + p["dk2"] * (
            _relu(x - p["x2"]) - _relu(-x - p["x2"])
        )

    def formula(self, p):
        return (
            f"{p['dk1']:.5g} (|x| - {p['x1']:.4g})+ sign(x) + {p['dk2']:.5g} (|x| - {p['x2']:.4g})+ sign(x)"
        )
