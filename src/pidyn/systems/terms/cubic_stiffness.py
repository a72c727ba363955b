"""A cubic spring (Duffing): hardening or softening with the displacement."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm


class CubicStiffness(ForceTerm):
    name = "cubic_stiffness"
    symbol = "x^3"
    linear = ("k3",)

    def __init__(self, k3: float = 120.0, signed: bool = False) -> None:
        """``signed``: k3 may take either sign (hardening or softening is a finding, as when a
        diagnosis discovers the term); otherwise it is positive (a hardening Duffing spring)."""
        if not signed and k3 <= 0:
            raise ValueError(f"cubic_stiffness: k3={k3} is softening; use signed=True to allow k3 <= 0")
        self.k3, self.signed = k3, signed

    def specs(self):
        return [
            ParamSpec(
                "k3",
                init=self.k3,
                scale=abs(self.k3) or 1.0,
                true=self.k3,
                unit="N/m^3",
                transform="identity" if self.signed else "log",
            )
        ]

    def force(self, t, x, v, z, p):
        return p["k3"] * x**3

    def formula(self, p):
        return f"{p['k3']:.5g} x^3"
