"""Least squares for the parameters a residual is linear in.

r(p) = r(0) + J p exactly for those parameters, so one linear solve gives the best values
for a given response estimate. Used to initialise PIDynNet from its pretrained networks
and, with differenced measurements, as the equation-error baseline.
"""

from __future__ import annotations

import torch

from pidyn.systems.base import Kinematics, StructuralSystem


def forward_jacobian(fn, u: torch.Tensor) -> torch.Tensor:
    """d fn / d u, (len(fn(u)), len(u)), exact, one forward-mode product per unknown.

    A residual over a window has thousands of entries and a handful of unknowns: reverse mode
    (one backward pass per entry) took 10 s on a 5-storey window, vectorised forward mode
    3 s, this loop 0.35 s."""
    from torch.func import jvp  # lazy: the NumPy core (simulation, refinement) runs without loading torch

    eye = torch.eye(u.numel(), dtype=u.dtype)
    if not u.numel():
        return torch.zeros(fn(u).numel(), 0, dtype=u.dtype)
    return torch.stack([jvp(fn, (u,), (eye[i],))[1] for i in range(u.numel())], dim=1)


def lstsq(J: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """min |J x - b| by the SVD (LAPACK's gelsd). torch's default driver on the CPU, gelsy, gives
    answers that differ in their last bits with where J happens to lie in memory: a run's
    least-squares start, and so its whole PIDynNet estimate, changed from run to run. Every linear
    least-squares solve in torch goes through here."""
    return torch.linalg.lstsq(J, b[:, None], driver="gelsd").solution[:, 0]


def solve_linear_params(
    system: StructuralSystem,
    k: Kinematics,
    f: torch.Tensor,
    values: dict[str, torch.Tensor],
    names: list[str],
    residual: str = "motion",
    std: dict[str, float] | None = None,
) -> dict[str, float]:
    """Least-squares values of ``names`` (others fixed at ``values``) for one named residual.
    ``std``: filled with each value's standard error (residual variance times (J^T J)^-1)."""
    vals = {n: v.detach() for n, v in values.items()}
    theta0 = torch.zeros(len(names), dtype=f.dtype)

    def r(th: torch.Tensor) -> torch.Tensor:
        p = dict(vals)
        p.update({n: th[i] for i, n in enumerate(names)})
        return system.residual(k, f, p)[residual].reshape(-1)

    r0 = r(theta0).detach()
    J = forward_jacobian(r, theta0)
    sol = lstsq(J, -r0)
    if std is not None:
        # in float64 on unit-norm columns: x^3 beside x can be 1e-4 of its size, and a float32
        # pseudo-inverse would drop that direction and call it exactly determined
        Jd, res = J.double(), (r0 + J @ sol).double()
        scale = Jd.norm(dim=0).clamp_min(1e-300)
        dof = max(J.shape[0] - J.shape[1], 1)
        cov = torch.linalg.pinv((Jd / scale).T @ (Jd / scale), hermitian=True) * float(res @ res) / dof
        var = torch.diagonal(cov) / scale**2
        std.update({n: float(var[i].clamp_min(0).sqrt()) for i, n in enumerate(names)})
    return {n: float(sol[i]) for i, n in enumerate(names)}
