"""A monomial of displacement and velocity: the regression library's general term."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import ForceTerm


class Monomial(ForceTerm):
    """p x^i x'^j: a column of a polynomial library (SINDy's cross terms), no physical law of its
    own; the physical monomials (x, x', x^2, x^3) are their own terms."""

    def __init__(
        self, i: int, j: int, value: float = 0.0, param: str | None = None, scale: float = 1.0
    ) -> None:
        """``scale``: the coefficient's typical size, f / (x^i x'^j) in the record's units, so
        that a search over it is well conditioned."""
        if i < 0 or j < 0 or i + j == 0:
            raise ValueError(f"monomial: need powers i, j >= 0 and not both 0, got {i}, {j}")
        if not scale > 0:
            raise ValueError(f"monomial: scale must be > 0, got {scale}")
        self.i, self.j, self.value, self.scale = i, j, value, float(scale)
        self.param = param or f"p{i}{j}"
        self.name, self.linear = f"monomial_{i}_{j}", (self.param,)
        parts = [f"x^{i}" if i > 1 else "x"] * bool(i) + [f"x'^{j}" if j > 1 else "x'"] * bool(j)
        self.symbol = " ".join(parts)

    def specs(self):
        return [
            ParamSpec(self.param, init=self.value, scale=self.scale, true=self.value, transform="identity")
        ]

    def force(self, t, x, v, z, p):
        out = p[self.param]
        if self.i:
            out = out * x**self.i
        if self.j:
            out = out * v**self.j
        return out

    def formula(self, p):
        return f"{p[self.param]:.5g} {self.symbol}"
