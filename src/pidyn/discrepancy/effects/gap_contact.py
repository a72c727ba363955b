"""A symmetric stop engaged beyond a gap."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import GapContact


class Gap(Effect):
    """A symmetric stop beyond a gap (grid over the gap)."""

    name, key, tolerance = "gap_contact", "kg", 0.3
    order = 8
    stands_for = ("trilinear_spring",)  # a stop beyond a displacement
    n_grid = 1
    gap_shares = tuple(np.linspace(0.2, 0.85, 14))

    def candidates(self, s):
        for share in self.gap_shares:
            gap = share * s.x_peak
            col = GapContact(1.0, gap).columns(s.t, s.x, s.v, None, {"gap": gap})["kg"]
            yield Candidate(self.name, col[:, None], ("kg",), fixed={"gap": float(gap)}, positive=(True,))

    def storey_trials(self, params, span, drift_peak, k):
        """Every gap of the weak form's grid (shares of the storey's peak drift) with a contact as
        stiff as the storey at least: a stop that never engages at the weak form's gap has no
        gradient to bring it in, so a refinement from that gap alone can end where it started."""
        if drift_peak <= 0:
            return [params]
        kg = max(float(params.get("kg", 0.0)), k)
        return [params] + [{**params, "kg": kg, "gap": float(g * drift_peak)} for g in self.gap_shares]

    def term(self, p, s):
        return GapContact(p["kg"], p["gap"])

    def sample(self, rng, s, sign=None):
        share = float(rng.uniform(0.35, 0.7))
        kg = float(rng.uniform(0.5, 2.0)) * s.k_nominal
        return {"kg": kg, "gap": share * s.x_peak}
