"""A peer's state-space realization mapped onto the package's models: a start for the refinement.

An order-2N realization of one output, its poles in N oscillatory pairs, is exactly the class of
N modes on the supports (``pidyn.systems.modes``; N = 1: a single degree of freedom on them).
Continuous time through the first-order hold, the input linear between samples as the
package's integrator takes it: A_c = log(A) / dt, and B_c, D_c from inverting the hold's
B = (P1 - P2 + A P2) B_c, D = D_c + C P2 B_c (P1, P2 the hold's integrals of exp(A_c s)). With
A_c = V diag(lambda) V^-1, each pole pair lambda, conj(lambda) and its residue rho_j =
(C V)_i (V^-1 B_c)_ij add (alpha_j s + beta_j) / (s^2 + c s + k) to input j's transfer function
to the absolute acceleration, with c = -2 Re lambda, k = |lambda|^2, alpha_j = 2 Re rho_j and
beta_j = -2 Re(rho_j conj(lambda)); the model's mode adds ((g_j + r_j c) s + r_j k) / (...), and
D_c is what the sensor reads of each support directly (e_j). One to one.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm, logm

from pidyn.systems.modal import damping_params, stiffness_params
from pidyn.systems.modes import ModesOnSupports
from pidyn.systems.sdof import feedthrough_name, influence_name, support_damping_name


def hold_integrals(Ac: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The first-order hold's integrals of exp(A_c s) over a step (scipy's ``cont2discrete``
    'foh' blocks with B = I): P1 = int_0^dt exp(A_c s) ds, P2 its ramp-weighted part."""
    n = Ac.shape[0]
    em = np.zeros((3 * n, 3 * n))
    em[:n, :n], em[:n, n : 2 * n], em[n : 2 * n, 2 * n :] = Ac * dt, np.eye(n) * dt, np.eye(n)
    ms = expm(em)
    return ms[:n, n : 2 * n], ms[:n, 2 * n :]


def continuous_modes(realization: tuple, dt: float) -> tuple[list[dict], np.ndarray] | None:
    """The realization's modes in continuous time, longest period first: each ``{c, k, alpha,
    beta}`` (alpha, beta per input), and D_c. None when a pole is real, the log of A is not
    real, or a mode is not a damped oscillator."""
    A, B, C, D = (np.atleast_2d(np.asarray(x, float)) for x in realization)
    if A.shape[0] % 2 or C.shape[0] != 1 or np.any(np.abs(np.linalg.eigvals(A).imag) < 1e-12):
        return None
    Ac = logm(A)
    if np.max(np.abs(np.imag(Ac))) > 1e-8 * max(1.0, np.max(np.abs(Ac))):
        return None
    Ac = np.real(Ac) / dt
    P1, P2 = hold_integrals(Ac, dt)
    Bc = np.linalg.solve(P1 - P2 + A @ P2, B)
    Dc = (D - C @ P2 @ Bc)[0]
    lam, V = np.linalg.eig(Ac)
    left = np.linalg.solve(V, Bc.astype(complex))
    out = []
    for i in np.flatnonzero(lam.imag > 0):
        rho = (C[0] @ V[:, i]) * left[i]
        c, k = float(-2 * lam[i].real), float(abs(lam[i]) ** 2)
        if not (c > 0 and k > 0):
            return None
        out.append({"c": c, "k": k, "alpha": 2 * rho.real, "beta": -2 * (rho * np.conj(lam[i])).real})
    return sorted(out, key=lambda m: m["k"]), Dc


def realization_params(system, realization: tuple, dt: float) -> dict[str, float]:
    """A realization of one output mapped onto ``system``'s parameters (empty when it does not
    map: another order than twice the model's modes, a real pole pair, a negative stiffness).
    A single degree of freedom with one input keeps only c and k (its input terms are fixed)."""
    modal = isinstance(system, ModesOnSupports)
    if not modal and not _plain_sdof(system):
        return {}
    if np.atleast_2d(np.asarray(realization[0])).shape[0] != 2 * system.n_dof:
        return {}
    found = continuous_modes(realization, dt)
    if found is None:
        return {}
    modes, Dc = found
    inputs = list(getattr(system, "inputs", []) or [])
    if modal:
        return _modes_params(system, modes, Dc, inputs)
    return _sdof_params(system, modes[0], Dc, inputs)


def _plain_sdof(system) -> bool:

    return len(stiffness_params(system)) == 1 and len(damping_params(system)) == 1


def _sdof_params(system, mode: dict, Dc: np.ndarray, inputs: list[str]) -> dict[str, float]:

    m = next((s.init for s in system.param_specs() if s.name == "m"), 1.0)
    c, k = mode["c"], mode["k"]
    out = {damping_params(system)[0]: m * c, stiffness_params(system)[0]: m * k}
    if len(inputs) != len(Dc):
        return out
    for j, name in enumerate(inputs):
        r = float(mode["beta"][j]) / k
        out[feedthrough_name(name)] = float(Dc[j])
        out[influence_name(name)] = r
        out[support_damping_name(name)] = m * (float(mode["alpha"][j]) - r * c)
    return out


def _modes_params(system, modes: list[dict], Dc: np.ndarray, inputs: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for r, mode in enumerate(modes, 1):
        c, k = mode["c"], mode["k"]
        out[f"c{r}"], out[f"k{r}"] = c, k
        if not inputs:  # a relative record: -r s^2 / (s^2 + c s + k) = -r + (r c s + r k) / (...)
            out[f"r{r}"] = float(mode["beta"][0]) / k
            continue
        for j, name in enumerate(inputs):
            rj = float(mode["beta"][j]) / k
            out[f"r{r}_{name}"] = rj
            out[f"g{r}_{name}"] = float(mode["alpha"][j]) - rj * c
    if inputs and len(inputs) == len(Dc):
        for j, name in enumerate(inputs):
            out[system.feedthrough(1, name)] = float(Dc[j])
    return out
