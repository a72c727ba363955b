"""Bouc-Wen hysteresis beside the elastic spring (a latent state, on a grid of loop shapes)."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import BoucWenHysteresis, latent_path


class Hysteresis(Effect):
    """Bouc-Wen hysteresis kh z beside the elastic k x (a latent state: the LNN learns z)."""

    name, key, tolerance = "hysteresis", "kh", 0.3
    order = 5
    #: one hysteretic spring in a model: another would share its loop's parameters
    exclusive_group = "hysteretic spring"
    n_grid = 2
    spring_at_rest = True
    yield_shares = (0.15, 0.3, 0.6)  # z's ceiling (beta + gamma)^(-1/n) over the peak |x|
    shapes = (0.5, 0.75)  # gamma / (beta + gamma)
    exponents = (1.0, 2.0)

    def _grid(self, s):
        rows = []
        for n in self.exponents:
            for share in self.yield_shares:
                total = (share * s.x_peak) ** (-n)
                for g in self.shapes:
                    rows.append((total * (1 - g), total * g, n))
        return np.array(rows)

    def candidates(self, s):
        grid = self._grid(s)
        term = BoucWenHysteresis(1.0, param="kh")
        # rate independent: z along the displacement path alone (a smoothed velocity drifts from it)
        z = latent_path(term, s.t, s.x, None, {"beta": grid[:, 0], "gamma": grid[:, 1], "n": grid[:, 2]})
        for j, (beta, gamma, n) in enumerate(grid):
            yield Candidate(
                self.name,
                term.columns(s.t, s.x, s.v, z[:, j], {})["kh"][:, None],
                ("kh",),
                fixed={"beta": beta, "gamma": gamma, "n": n},
                positive=(True,),
            )

    def shape_trials(self, params, s):
        """Every loop shape of the grid at the sampled size: a Bouc-Wen fitted from one typical
        shape ended in a poor optimum on simulated decks (named on 1 of 6)."""
        return [{**params, "beta": b, "gamma": g, "n": n} for b, g, n in self._grid(s)]

    def parameters(self, coef, fixed, nominal):
        out = {**coef, **fixed}
        out["z_max"] = float((fixed["beta"] + fixed["gamma"]) ** (-1.0 / fixed["n"]))
        return out

    def term(self, p, s):
        # beta and gamma with either sign: which loop shape (softening, hardening) is a finding
        S = max(abs(p["beta"]) + abs(p["gamma"]), 1e-12) / 2
        return BoucWenHysteresis(
            p["kh"],
            p["beta"],
            p["gamma"],
            p["n"],
            param="kh",
            shape_scale=S,
            gamma_lower=-10.0 * S,
            beta_lower=-10.0 * S,
        )

    def sample(self, rng, s, sign=None):
        n = float(rng.choice([1.0, 2.0]))
        share = float(rng.uniform(0.2, 0.5))
        total = (share * s.x_peak) ** (-n)
        g = float(rng.uniform(0.5, 0.8))
        # kh z_max sized like the other effects' peak force
        kh = self._size(rng, s, 0.1, 0.25) / (share * s.x_peak)
        return {"kh": kh, "beta": total * (1 - g), "gamma": total * g, "n": n}
