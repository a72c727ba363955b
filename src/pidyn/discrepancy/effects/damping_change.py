"""A damping that changes by a fraction at an unknown time."""

from __future__ import annotations

from pidyn.discrepancy.effects.stiffness_loss import Damage
from pidyn.systems.terms import DampingChange, ViscousDamping

#: the largest relative damping change the library names (the damping ten times its value)
MAX_DAMPING_CHANGE = 9.0


class DampChange(Damage):
    """The damping changes by a fraction at an unknown time (grid over the time)."""

    name, key, tolerance = "damping_change", "change", 0.35
    order = 7
    signed = True
    changes = "damping"
    signal, coef = "v", "dc"
    base = ViscousDamping(1.0)
    column_sign, positive = 1.0, False  # damping may rise or fall

    def parameters(self, coef, fixed, nominal):
        return {"change": coef["dc"] / nominal.get("c", 1.0), "t_d": fixed["t_d"]}

    def admissible(self, params, nominal):
        # the damping stays positive on both sides of the step: a "change" to no damping or less
        # is the refitted damping taking up a force the model's columns get wrong on one side
        # (dry friction near rest, where the velocity is mostly noise), not a change of the structure
        # ... and no more than the term can represent (a tenfold damping): beyond it the located
        # step is a force of another shape (dry friction in a quiet tail reads as a huge damping)
        return nominal.get("c", 1.0) > 0 and -1.0 < params["change"] <= MAX_DAMPING_CHANGE

    def from_change(self, fraction, t_change):
        return {"change": fraction, "t_d": t_change}

    def term(self, p, s):
        change = min(max(p["change"], -0.9), MAX_DAMPING_CHANGE)
        return DampingChange(
            change, p["t_d"], t_min=s["t_min"], t_max=s["t_max"], damping=s.get("damping", "c")
        )

    def sample(self, rng, s, sign=None):
        # damage raises the dissipation: the damping doubles to triples; sign -1: it falls by a third to a half
        return {
            "change": float(rng.uniform(1.0, 2.0))
            if sign is None or sign > 0
            else -float(rng.uniform(0.33, 0.5)),
            "t_d": self._time_of_share(s, float(rng.uniform(0.2, 0.6))),
        }
