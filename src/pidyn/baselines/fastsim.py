"""Many parameter sets of one system under one excitation, as one batch (``pidyn.integrate``).

The UKF's sigma points, the Cramer-Rao sensitivities and the free simulation of an
identified model use this view of the batched integrator: a (P,) array per parameter and
the same excitation for every member.
"""

from __future__ import annotations

import numpy as np

from pidyn.integrate import rk4
from pidyn.systems.base import StructuralSystem


def simulate_batch(
    system: StructuralSystem,
    params: dict[str, np.ndarray],
    t: np.ndarray,
    f: np.ndarray,
    substeps: int = 4,
    state0: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """Simulate P parameter sets; ``params[name]`` has shape (P,) (or scalar).

    ``state0`` = (x0, v0, z0) with shapes (P,) or (P, n_dof), and (P, n_latent).
    Returns ``x``, ``v``, ``a`` of shape (N, P) for one degree of freedom, (N, P, n_dof)
    otherwise, and ``z`` (N, P, n_latent).
    """
    P = max(np.size(v) for v in params.values())
    p = {k: np.broadcast_to(np.asarray(v, float), (P,)).copy() for k, v in params.items()}
    n, nz = system.n_dof, system.n_latent
    y0 = np.zeros((P, system.n_state))
    if state0 is not None:
        y0[:, :n] = np.asarray(state0[0], float).reshape(P, n)
        y0[:, n : 2 * n] = np.asarray(state0[1], float).reshape(P, n)
        if nz:
            y0[:, 2 * n :] = np.asarray(state0[2], float).reshape(P, nz)
    Y, R = rk4(system, p, np.asarray(t, float), np.asarray(f, float), y0, substeps=substeps)
    sq = (lambda a: a[..., 0]) if n == 1 else (lambda a: a)
    return {"x": sq(Y[..., :n]), "v": sq(Y[..., n : 2 * n]), "a": sq(R[..., n : 2 * n]), "z": Y[..., 2 * n :]}
