"""A cubic spring, hardening or softening: the sign is the fit's finding."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import CubicStiffness


class Cubic(Effect):
    name, key, tolerance = "cubic_stiffness", "k3", 0.2
    order = 1
    stands_for = ("trilinear_spring",)  # a softening branch before a stop

    def candidates(self, s):
        col = CubicStiffness(1.0, signed=True).columns(s.t, s.x, s.v, None, {})["k3"]
        yield Candidate(self.name, col[:, None], ("k3",), positive=(False,))

    signed = True

    def term(self, p, s):
        return CubicStiffness(p["k3"], signed=True)  # hardening or softening: the data decide

    def sample(self, rng, s, sign=None):
        sign = float(rng.choice([-1.0, 1.0])) if sign is None else float(np.sign(sign))
        # softening is kept milder: its tangent stiffness k + 3 k3 x^2 must stay positive
        size = self._size(rng, s) if sign > 0 else self._size(rng, s, 0.06, 0.15)
        return {"k3": sign * size / s.x_peak**3}
