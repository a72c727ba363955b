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
    G = torch.autograd.functional.jacobian(stacked, raw0)
    sigma2 = (r**2).mean().clamp_min(1e-12)
    return (G.T @ G) / sigma2


class InformationFusion:
    """Running information-weighted estimate over windows (in unconstrained coordinates)."""

    def __init__(self, ridge: float = 1e-9) -> None:
        self.ridge = ridge
        self.info: torch.Tensor | None = None
        self.weighted: torch.Tensor | None = None

    def add(self, theta: torch.Tensor, info: torch.Tensor) -> torch.Tensor:
        info = 0.5 * (info + info.T)
        if self.info is None:
            self.info, self.weighted = info.clone(), info @ theta
        else:
            assert self.weighted is not None
            self.info = self.info + info
            self.weighted = self.weighted + info @ theta
        return self.estimate()

    def estimate(self) -> torch.Tensor:
        assert self.info is not None and self.weighted is not None
        n = self.info.shape[0]
        reg = self.ridge * torch.trace(self.info) / n * torch.eye(n, dtype=self.info.dtype)
        return torch.linalg.solve(self.info + reg, self.weighted)

    def state_dict(self) -> dict:
        return {"info": self.info, "weighted": self.weighted}

    def load_state_dict(self, s: dict) -> None:
        self.info, self.weighted = s.get("info"), s.get("weighted")
