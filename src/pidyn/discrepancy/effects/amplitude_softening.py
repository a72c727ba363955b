"""A stiffness and damping that follow the response's recent amplitude (tried where the period moves)."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.systems.terms import AmplitudeSoftening, latent_path


class Amplitude(Effect):
    """A stiffness and a damping that follow the response's recent amplitude (a latent envelope
    with its time constant, ``AmplitudeSoftening``): a period that lengthens in strong shaking and
    recovers in the coda. Not screened by default: tried where the running period moves beyond
    its windows' intervals (``subjects.single_dof``), or when ``diagnosis.effects`` lists it."""

    name, key, tolerance = "amplitude_softening", "soft", 0.3
    order = 9
    tried_where_period_moves = True
    n_grid = 1
    library = False
    taus = (0.5, 1.0, 2.0, 4.0, 8.0)

    def candidates(self, s):
        ctx = s.context()
        for tau in self.taus:
            term = AmplitudeSoftening(0.0, 0.0, tau, a_ref=ctx["x_scale"], w0=ctx["w0"])
            e = latent_path(term, s.t, s.x, None, {"tau": tau})[:, 0]
            cols = np.stack([-s.k_nominal * e * s.x, e * s.v], axis=1)
            yield Candidate(self.name, cols, ("soft", "gain_c"), fixed={"tau": tau})

    def parameters(self, coef, fixed, nominal):
        c = float(nominal.get("c", 0.0))
        gain = coef.get("gain_c", 0.0) / c if c > 0 else 0.0
        return {"soft": coef.get("soft", 0.0), "gain": float(gain), **fixed}

    def term(self, p, s):
        return AmplitudeSoftening(
            p.get("soft", 0.1),
            p.get("gain", 0.1),
            p.get("tau", 1.0),
            a_ref=float(s.get("x_scale", 1.0)) or 1.0,
            w0=float(s.get("w0", 1.0)),
            stiffness=s.get("stiffness", "k"),
            damping=s.get("damping", "c"),
        )

    def sample(self, rng, s, sign=None):
        return {
            "soft": float(rng.uniform(0.25, 0.45)),
            "gain": float(rng.uniform(0.3, 1.0)),
            "tau": float(rng.uniform(1.0, 3.0)),
        }
