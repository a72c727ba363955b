"""A quadratic spring: a stiffness that differs in the two directions."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import QuadraticStiffness


class Quadratic(Effect):
    name, key, tolerance = "quadratic_stiffness", "k2", 0.25
    order = 2

    def candidates(self, s):
        col = QuadraticStiffness(1.0).columns(s.t, s.x, s.v, None, {})["k2"]
        yield Candidate(self.name, col[:, None], ("k2",), positive=(False,))

    def term(self, p, s):
        return QuadraticStiffness(p["k2"])

    signed = True

    def sample(self, rng, s, sign=None):
        drawn = float(rng.choice([-1.0, 1.0]))
        sign = drawn if sign is None else float(np.sign(sign))
        return {"k2": sign * self._size(rng, s) / s.x_peak**2}
