"""Stribeck friction: a static friction above the sliding one, falling with the velocity."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm, _exp, _tanh


class StribeckFriction(ForceTerm):
    """(Fc + (Fs - Fc) exp(-(x'/vs)^2)) sign(x'): dry friction whose static level Fs exceeds the
    sliding level Fc (the Stribeck drop at low speed). Not in the discrepancy library."""

    name = "stribeck_friction"

    def __init__(self, Fc: float = 0.1, Fs: float = 0.25, vs: float = 0.02, eps: float = 1e-3) -> None:
        self.Fc, self.Fs, self.vs, self.eps = Fc, Fs, vs, eps

    def specs(self):
        return [
            ParamSpec("Fc", init=self.Fc, scale=self.Fc, true=self.Fc, unit="N"),
            ParamSpec("Fs", init=self.Fs, scale=self.Fs, true=self.Fs, unit="N"),
            ParamSpec("vs", init=self.vs, scale=self.vs, true=self.vs, trainable=False, unit="m/s"),
        ]

    def force(self, t, x, v, z, p):
        level = p["Fc"] + (p["Fs"] - p["Fc"]) * _exp(-((v / p["vs"]) ** 2))
        return level * _tanh(v / self.eps)

    def formula(self, p):
        return f"({p['Fc']:.4g} + ({p['Fs']:.4g} - {p['Fc']:.4g}) exp(-(x'/{p['vs']:.3g})^2)) sign(x')"
