"""Quadratic damping: a dissipation that grows with the square of the velocity."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import QuadraticDamping


class QuadDamping(Effect):
    name, key, tolerance = "quadratic_damping", "c2", 0.3
    order = 4

    def candidates(self, s):
        col = QuadraticDamping(1.0).columns(s.t, s.x, s.v, None, {})["c2"]
        yield Candidate(self.name, col[:, None], ("c2",), positive=(True,))

    def term(self, p, s):
        return QuadraticDamping(p["c2"])

    def sample(self, rng, s, sign=None):
        v_peak = float(np.max(np.abs(s.v)))
        return {"c2": self._size(rng, s, 0.08, 0.2) / v_peak**2}
