"""A yielding member beside the elastic structure: the bilinear hysteretic spring of structural
engineering (an elastoplastic element in parallel with the elastic stiffness)."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects.base import Candidate, Effect
from pidyn.discrepancy.effects.hysteresis import Hysteresis
from pidyn.systems.terms import BoucWenHysteresis, latent_path


class BilinearElastoplastic(Effect):
    """kp z beside the elastic k x, z elastoplastic with yield displacement x_y: the stiffness is
    k + kp until the member yields, k beyond (the post-yield ratio k / (k + kp)), and k + kp again
    on unloading, a bilinear loop (a steel brace, a yielding damper, a column's plastic hinge).

    z follows the smooth elastoplastic law z' = x' (1 - [x' z > 0] |z / x_y|^n), which is Bouc-Wen
    with beta = gamma = 1 / (2 x_y^n): n = 5 rounds the bilinear loop's corners over a few per cent
    of x_y. The grid runs over the yield displacement. Not screened by default, beside the
    library's general Bouc-Wen loop: named where ``diagnosis.effects`` lists it."""

    name, key, tolerance = "bilinear_elastoplastic", "kp", 0.3
    order = 10
    n_grid = 1
    library = False
    spring_at_rest = True  # below yield z = x: a spring beside the storey's own
    exclusive_group = Hysteresis.exclusive_group  # its loop's parameters are Bouc-Wen's
    sharpness = 5.0  # n: within the term's bounds (0.5-6)
    yield_shares = tuple(np.linspace(0.15, 0.8, 14))  # x_y over the peak |x|

    def _shape(self, x_y: float) -> dict[str, float]:
        b = 0.5 * float(x_y) ** (-self.sharpness)
        return {"beta": b, "gamma": b, "n": self.sharpness}

    def candidates(self, s):
        shapes = [self._shape(share * s.x_peak) for share in self.yield_shares]
        term = BoucWenHysteresis(1.0, param="kp")
        grid = {k: np.array([sh[k] for sh in shapes]) for k in ("beta", "gamma", "n")}
        z = latent_path(term, s.t, s.x, None, grid)  # rate independent: along the displacement path
        for j, (share, shape) in enumerate(zip(self.yield_shares, shapes)):
            yield Candidate(
                self.name,
                term.columns(s.t, s.x, s.v, z[:, j], {})["kp"][:, None],
                ("kp",),
                fixed={"x_y": float(share * s.x_peak), **shape},
                positive=(True,),
            )

    def parameters(self, coef, fixed, nominal):
        return {**coef, **fixed}

    def term(self, p, s):
        shape = self._shape(p["x_y"]) if "x_y" in p else p
        S = shape["beta"]
        return BoucWenHysteresis(
            p["kp"], shape["beta"], shape["gamma"], shape["n"], param="kp", shape_scale=S, gamma_lower=0.0
        )

    def sample(self, rng, s, sign=None):
        x_y = float(rng.uniform(0.3, 0.6)) * s.x_peak
        kp = float(rng.uniform(0.5, 1.5)) * s.k_nominal  # yield force kp x_y: a share of the peak force
        return {"kp": kp, "x_y": x_y, **self._shape(x_y)}
