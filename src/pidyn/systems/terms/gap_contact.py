"""A gap that closes: a stop engaged beyond a clearance."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm, _relu


class GapContact(ForceTerm):
    """kg (|x| - gap)_+ sign(x): a symmetric stop that engages beyond a gap."""

    name = "gap_contact"
    linear = ("kg",)
    proportional = True

    def __init__(self, kg: float = 50.0, gap: float = 0.05) -> None:
        self.kg, self.gap = kg, gap

    def specs(self):
        return [
            ParamSpec("kg", init=self.kg, scale=self.kg, true=self.kg, unit="N/m"),
            ParamSpec("gap", init=self.gap, scale=self.gap, true=self.gap, unit="m"),
        ]

    def force(self, t, x, v, z, p):
        return p["kg"] * (_relu(x - p["gap"]) - _relu(-x - p["gap"]))

    def formula(self, p):
        return f"{p['kg']:.5g} (|x| - {p['gap']:.4g})+ sign(x)"
