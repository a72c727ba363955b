"""Fixed-step RK4 for many parameter sets at once (SDOF systems).

Output-error fitting, sensitivities for the Cramer-Rao bound and the UKF's sigma points all
simulate the same system under the same excitation with many parameter vectors. Integrating
them as one NumPy batch (shape (P,)) costs about as much as one scalar solve_ivp call. The
excitation is linear between samples, and each sample interval is split into ``substeps``
RK4 steps; with 4 substeps at dt = 0.01 s the error against solve_ivp (rtol 1e-10) is below
1e-6 relative for the shipped systems (see tests).
"""

from __future__ import annotations

import numpy as np

from pidyn.systems.sdof import SDOFSystem


def _deriv(system: SDOFSystem, t, x, v, z, p, fval):
    a = (system.forcing(fval, p) - system.restoring_force(t, x, v, z, p)) / p["m"]
    dz = []
    for term, sl in zip(system.terms, system._latent_slices()):
        if sl is not None:
            dz.append(term.latent_rate(t, x, v, z[..., sl], p))
    dz_arr = np.concatenate(dz, axis=-1) if dz else z
    return v, a, dz_arr


def simulate_batch(
    system: SDOFSystem,
    params: dict[str, np.ndarray],
    t: np.ndarray,
    f: np.ndarray,
    substeps: int = 4,
    state0: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """Simulate P parameter sets; ``params[name]`` has shape (P,) (or scalar).

    Returns ``x``, ``v``, ``a`` of shape (N, P) and ``z`` (N, P, n_latent).
    """
    if not isinstance(system, SDOFSystem):
        raise TypeError("simulate_batch supports single-degree-of-freedom systems")
    P = max(np.size(v) for v in params.values())
    p = {k: np.broadcast_to(np.asarray(v, float), (P,)).copy() for k, v in params.items()}
    nz = system.n_latent
    N = len(t)
    x = np.zeros(P) if state0 is None else state0[0].copy()
    v = np.zeros(P) if state0 is None else state0[1].copy()
    z = np.zeros((P, max(nz, 0))) if state0 is None else state0[2].copy()
    X, V, A = np.empty((N, P)), np.empty((N, P)), np.empty((N, P))
    Z = np.empty((N, P, nz))
    _, a0, _ = _deriv(system, t[0], x, v, z, p, f[0])
    X[0], V[0], A[0] = x, v, a0
    if nz:
        Z[0] = z
    for i in range(N - 1):
        h = (t[i + 1] - t[i]) / substeps
        for s in range(substeps):
            ta = t[i] + s * h
            fa = f[i] + (f[i + 1] - f[i]) * (s / substeps)
            fm = f[i] + (f[i + 1] - f[i]) * ((s + 0.5) / substeps)
            fb = f[i] + (f[i + 1] - f[i]) * ((s + 1) / substeps)
            k1 = _deriv(system, ta, x, v, z, p, fa)
            k2 = _deriv(system, ta + h / 2, x + h / 2 * k1[0], v + h / 2 * k1[1], z + h / 2 * k1[2], p, fm)
            k3 = _deriv(system, ta + h / 2, x + h / 2 * k2[0], v + h / 2 * k2[1], z + h / 2 * k2[2], p, fm)
            k4 = _deriv(system, ta + h, x + h * k3[0], v + h * k3[1], z + h * k3[2], p, fb)
            x = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            if nz:
                z = z + h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        _, a, _ = _deriv(system, t[i + 1], x, v, z, p, f[i + 1])
        X[i + 1], V[i + 1], A[i + 1] = x, v, a
        if nz:
            Z[i + 1] = z
    return {"x": X, "v": V, "a": A, "z": Z}
