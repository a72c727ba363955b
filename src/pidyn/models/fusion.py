"""Combining per-window estimates by the information each window carries.

Windows of an earthquake record differ by 100x in how much they say about a parameter
(large nonlinear excursions vs the quiet tail). Each window's estimate theta_w comes with
the Fisher information J_w of its physics residual with respect to the (unconstrained)
parameters, evaluated at the end of the window. The running estimate is the Gaussian
product theta = (sum J_w)^-1 sum J_w theta_w: a window that carries little information
barely moves it, which is what stops the drift in the quiet tail of a record.
"""

from __future__ import annotations

import torch

from pidyn.data.windows import Window
from pidyn.models.pidynnet import PIDynNet
from pidyn.systems.lstsq import forward_jacobian


def residual_information(net: PIDynNet, w: Window) -> torch.Tensor:
    """J = G^T G / mean(r^2) for the stacked normalised physics residuals r(theta_raw)."""
    names = net.params.trainable_names
    raw0 = net.params.raw_vector(names).detach()
    t, f = w.t_pool, w.f_pool
    with torch.no_grad():
        k = net.kinematics(t, f, w.q_pool, w.qd_pool)
    from pidyn.params import from_raw

    specs = [net.params.spec(n) for n in names]
    fixed = {n: v.detach() for n, v in net.params.values().items()}

    def stacked(raw: torch.Tensor) -> torch.Tensor:
        p = dict(fixed)
        p.update({n: from_raw(s, raw[i]) for i, (n, s) in enumerate(zip(names, specs))})
        res = net.system.residual(k, f, p)
        parts = [(res.pop("motion") / net.scale_f).reshape(-1)]
        parts += [(r / net.scale_v[0]).reshape(-1) for r in res.values()]
        return torch.cat(parts)

    r = stacked(raw0).detach()
    G = forward_jacobian(stacked, raw0)
    sigma2 = (r**2).mean().clamp_min(1e-12)
    return (G.T @ G) / sigma2


class InformationFusion:
    """Running information-weighted estimate over windows (in unconstrained coordinates).

    The Gaussian product (sum J_w)^-1 sum J_w theta_w is a matrix-weighted average: when the
    windows' information matrices are ill-conditioned and differently oriented (Bouc-Wen's
    beta, gamma, n), it can land outside every window's estimate (beta 0.513 and 0.543 fused
    to 0.283). Such an extrapolation is not information, so it is rejected: a component
    outside the range of the windows' estimates (plus ``margin`` of that range) switches the
    fusion to weights by each window's marginal precision 1 / (J_w^-1)_ii, a convex
    combination per parameter, which a window that pins a parameter only in combination with
    others barely moves.
    """

    def __init__(self, ridge: float = 1e-9, margin: float = 0.1) -> None:
        self.ridge = ridge
        self.margin = margin
        self.info: torch.Tensor | None = None
        self.weighted: torch.Tensor | None = None
        self.thetas: list[torch.Tensor] = []
        self.infos: list[torch.Tensor] = []
        self.fallback = False  # the last estimate used marginal weights

    def add(self, theta: torch.Tensor, info: torch.Tensor) -> torch.Tensor:
        info = 0.5 * (info + info.T)
        self.thetas.append(theta.detach().clone())
        self.infos.append(info.detach().clone())
        if self.info is None:
            self.info, self.weighted = info.clone(), info @ theta
        else:
            assert self.weighted is not None
            self.info = self.info + info
            self.weighted = self.weighted + info @ theta
        return self.estimate()

    def _ridge(self, info: torch.Tensor) -> torch.Tensor:
        n = info.shape[0]
        tiny = torch.finfo(info.dtype).tiny
        return (self.ridge * torch.trace(info) / n).clamp_min(tiny ** 0.5) * torch.eye(n, dtype=info.dtype)

    def _solve(self, info: torch.Tensor, rhs: torch.Tensor, prior: torch.Tensor) -> torch.Tensor:
        """(info + R)^-1 (rhs + R prior): the ridge pulls a direction no window informs (a
        damage time before the damage) to the windows' mean estimate, not to raw zero."""
        reg = self._ridge(info)
        return torch.linalg.solve(info + reg, rhs + reg @ prior)

    def estimate(self) -> torch.Tensor:
        assert self.info is not None and self.weighted is not None
        joint = self._solve(self.info, self.weighted, torch.stack(self.thetas).mean(0))
        if len(self.thetas) < 2:
            self.fallback = False
            return joint
        T = torch.stack(self.thetas)
        lo, hi = T.min(0).values, T.max(0).values
        pad = self.margin * (hi - lo)
        if bool(((joint >= lo - pad) & (joint <= hi + pad)).all()):
            self.fallback = False
            return joint
        self.fallback = True
        # marginal precision 1 / (J_w + R_w)^-1_ii: a window with no information on a parameter
        # has ~0 weight for it (a pseudo-inverse would give it an infinite one)
        prec = torch.stack([1.0 / torch.diagonal(torch.linalg.inv(J + self._ridge(J))) for J in self.infos])
        return (prec * T).sum(0) / prec.sum(0)

    def state_dict(self) -> dict:
        return {"info": self.info, "weighted": self.weighted, "thetas": self.thetas, "infos": self.infos}

    def load_state_dict(self, s: dict) -> None:
        self.info, self.weighted = s.get("info"), s.get("weighted")
        self.thetas, self.infos = list(s.get("thetas") or []), list(s.get("infos") or [])
