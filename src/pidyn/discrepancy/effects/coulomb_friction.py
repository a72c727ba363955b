"""Dry friction, its sign turning with the velocity's, smoothed no sharper than the noise."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import CoulombFriction

#: the range of a friction's identified transition width, in shares of the record's (2 % of the
#: RMS drift velocity); narrower than half would make the sticking friction a damper too stiff
#: for the integrator's step
WIDTH_RANGE = (0.5, 3.0)


class Coulomb(Effect):
    name, key, tolerance = "coulomb_friction", "Fc", 0.25
    order = 3
    stands_for = ("stribeck_friction",)  # dry friction with a drop at low speed

    def candidates(self, s):
        # near rest, noise flips the sign of the measured velocity: a column no sharper than
        # the noise (the term's own rule, so a screening of the extended model sees the same)
        term = CoulombFriction(1.0, eps=s.friction_eps)
        col = term.columns(s.t, s.x, s.v, None, {}, v_noise=s.v_noise)["Fc"]
        yield Candidate(self.name, col[:, None], ("Fc",), positive=(True,))

    def term(self, p, s):
        eps = float(p.get("eps", s["friction_eps"]))
        if not s.get("free_width"):
            return CoulombFriction(p["Fc"], eps=eps)
        # the width identified too (``CoulombFriction``), within a range about the record's
        lo, hi = (f * float(s["friction_eps"]) for f in WIDTH_RANGE)
        return CoulombFriction(p["Fc"], eps=float(np.clip(eps, 1.01 * lo, 0.99 * hi)), eps_range=(lo, hi))

    def sample(self, rng, s, sign=None):
        return {"Fc": self._size(rng, s, 0.04, 0.1)}
