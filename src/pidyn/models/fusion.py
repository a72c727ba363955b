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
from pidyn.params import from_raw
from pidyn.systems.lstsq import forward_jacobian


def residual_information(net: PIDynNet, w: Window) -> torch.Tensor:
    """J = G^T G / mean(r^2) for the stacked normalised physics residuals r(theta_raw)."""
    names = net.params.trainable_names
    raw0 = net.params.raw_vector(names).detach()
    t, f = w.t_pool, w.f_pool
    with torch.no_grad():
        k = net.kinematics(t, f, w.q_pool, w.qd_pool)

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
        # in float64: a window's information spans eight decades and more (a 5-storey building),
        # where a float32 inverse has negative or zero diagonals; the estimate comes back in theta's dtype
        dtype = theta.dtype
        theta, info = theta.detach().double(), info.detach().double()
        info = 0.5 * (info + info.T)
        self.thetas.append(theta.clone())
        self.infos.append(info.clone())
        if self.info is None:
            self.info, self.weighted = info.clone(), info @ theta
        else:
            assert self.weighted is not None
            self.info = self.info + info
            self.weighted = self.weighted + info @ theta
        return self.estimate().to(dtype)

    def _floored(self, info: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Eigenvalues of ``info`` raised to at least the ridge (``ridge`` x the mean positive
        eigenvalue; round-off leaves small negative ones), with the eigenvectors and the floor."""
        w, V = torch.linalg.eigh(info)
        tiny = torch.finfo(info.dtype).tiny
        floor = (self.ridge * w.clamp_min(0).sum() / w.numel()).clamp_min(tiny**0.5)
        return w.clamp_min(floor), V, floor

    def _solve(self, info: torch.Tensor, rhs: torch.Tensor, prior: torch.Tensor) -> torch.Tensor:
        """(info + R)^-1 (rhs + R prior), R = the floor: it pulls a direction no window informs
        (a damage time before the damage) to the windows' mean estimate, not to raw zero."""
        w, V, floor = self._floored(info)
        return V @ ((V.T @ (rhs + floor * prior)) / (w + floor))

    def _marginal_precision(self, info: torch.Tensor) -> torch.Tensor:
        """1 / (J + R)^-1_ii, positive and finite: a window with no information on a parameter
        has ~0 weight for it (a pseudo-inverse would give it an infinite one)."""
        w, V, floor = self._floored(info)
        return 1.0 / ((V**2) / (w + floor)).sum(1)

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
        prec = torch.stack([self._marginal_precision(J) for J in self.infos])
        prec = torch.where(torch.isfinite(prec) & (prec > 0), prec, torch.zeros_like(prec))
        total = prec.sum(0)
        fused = (prec * T).sum(0) / total.clamp_min(torch.finfo(T.dtype).tiny)
        # a parameter no window's information weighs (all weights zero) keeps the latest estimate
        return torch.where((total > 0) & torch.isfinite(fused), fused, T[-1])

    def state_dict(self) -> dict:
        return {"info": self.info, "weighted": self.weighted, "thetas": self.thetas, "infos": self.infos}

    def load_state_dict(self, s: dict) -> None:
        d = lambda a: None if a is None else a.double()  # noqa: E731  (states saved in float32 before)
        self.info, self.weighted = d(s.get("info")), d(s.get("weighted"))
        self.thetas = [t.double() for t in s.get("thetas") or []]
        self.infos = [J.double() for J in s.get("infos") or []]


def posterior_std(info: torch.Tensor | None, names: list[str]) -> dict[str, float] | None:
    """Marginal posterior std of each unconstrained parameter from an information matrix: a
    direction the window does not inform comes out large (a pseudo-inverse would hide it)."""
    if info is None:
        return None
    info = info.detach()  # numbers from here on (a learned force's weights leave it in the graph)
    n = info.shape[0]
    ridge = 1e-12 * float(torch.trace(info).abs()) / max(n, 1) + 1e-30
    cov = torch.linalg.inv(info.double() + ridge * torch.eye(n, dtype=torch.float64))
    d = torch.diagonal(cov).clamp_min(0.0).sqrt()
    return {nm: float(d[i]) for i, nm in enumerate(names)}
