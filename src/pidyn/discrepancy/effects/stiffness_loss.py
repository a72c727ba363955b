"""A stiffness that falls by a fraction at an unknown time: damage in the shaking."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import ForceTerm, LinearStiffness, StiffnessLoss


class Damage(Effect):
    """The stiffness falls by a fraction at an unknown time (grid over the time)."""

    name, key, tolerance = "stiffness_loss", "drop", 0.25
    order = 6
    exclusive_group = "change in time"
    changes = "stiffness"
    n_grid = 1
    step_in_time = True
    n_times = 40
    storey_times = 16  # a building's trial tries the step at this many times over the span

    def _span(self, s):
        t_end = s.t_fit_end if s.t_fit_end is not None else float(s.t[-1])
        return float(s.t[0]) + 0.05 * (t_end - s.t[0]), t_end

    signal, coef = "x", "dk"  # the force that steps: k x (a damping change steps c x')
    base: ForceTerm = LinearStiffness(1.0, param="k")  # the nominal term whose column steps
    #: the column is -x H(t - t_d), so the coefficient dk is the stiffness lost (> 0): a stiffness
    #: that rises in time is no loss but the mark of an amplitude-dependent one
    column_sign, positive = -1.0, True

    def candidates(self, s):
        lo, hi = self._span(s)
        sig = self.base.columns(s.t, s.x, s.v, None, {})[self.base.linear[0]]
        for t_d in np.linspace(lo, hi, self.n_times + 2)[1:-1]:
            col = self.column_sign * sig * (s.t >= t_d)
            yield Candidate(
                self.name, col[:, None], (self.coef,), fixed={"t_d": float(t_d)}, positive=(self.positive,)
            )

    def parameters(self, coef, fixed, nominal):
        k = nominal.get("k", nominal.get("k1", 1.0))
        return {"drop": coef["dk"] / k, "t_d": fixed["t_d"]}

    def from_change(self, fraction, t_change):
        return {"drop": -fraction, "t_d": t_change}  # a loss: the stiffness's fraction is negative

    def storey_trials(self, params, span, drift_peak, k):
        """The same size at every time of a grid over the span (a step's time has no gradient
        where the step is far from it)."""
        lo = span[0] + 0.05 * (span[1] - span[0])
        return [{**params, "t_d": float(t)} for t in np.linspace(lo, span[1], self.storey_times + 2)[1:-1]]

    def term(self, p, s):
        drop = min(max(p["drop"], 0.01), 0.9)
        return StiffnessLoss(drop, p["t_d"], t_min=s["t_min"], t_max=s["t_max"], stiffness=s["stiffness"])

    def _time_of_share(self, s, share: float) -> float:
        """The time by which the stepping force's signal has done ``share`` of its work
        (cumulative energy over the search span): a change drawn there has motion on both
        sides. Damage happens in the shaking; a change before the record's motion starts (the
        structure at rest) leaves no trace in the data, and no method could name it."""
        lo, hi = self._span(s)
        inside = (s.t >= lo) & (s.t <= hi)
        t, e = s.t[inside], getattr(s, self.signal)[inside] ** 2
        cum = np.cumsum(e)
        if len(t) < 2 or cum[-1] <= 0:
            return float(lo + share * (hi - lo))
        return float(np.interp(share * cum[-1], cum, t))

    def sample(self, rng, s, sign=None):
        return {
            "drop": float(rng.uniform(0.15, 0.4)),
            "t_d": self._time_of_share(s, float(rng.uniform(0.2, 0.7))),
        }
