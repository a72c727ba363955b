"""Fixed-step RK4 for a batch of trajectories of one system, on NumPy or dual arrays.

Output error, multiple shooting (one batch member per segment), the Cramer-Rao bound and
the UKF's sigma points all simulate one system under sampled excitation many times over.
Integrating the batch as arrays costs about as much as one scalar solve, and the same loop
run on ``pidyn.autodiff.Dual`` states and parameters returns exact sensitivities of the
discrete scheme. The excitation is linear between samples; each sample interval is split
into ``substeps`` RK4 steps (4 substeps at dt = 0.01 s agree with solve_ivp at rtol 1e-10
to about 1e-6 relative for the shipped systems; see tests).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pidyn.autodiff import Dual
from pidyn.systems.base import StructuralSystem


def _n_dir(p: dict[str, Any], y0: Any) -> int:
    for v in [y0, *p.values()]:
        if isinstance(v, Dual):
            return v.d.shape[-1]
    return 0


def _checked_excitation(system: StructuralSystem, f: np.ndarray) -> tuple[np.ndarray, bool]:
    """The excitation as an array of a shape the system takes, and whether it is per trajectory."""
    ff = np.asarray(f, float)
    multi = system.n_inputs > 1
    if ff.ndim not in ((2, 3) if multi else (1, 2)) or (multi and ff.shape[-1] != system.excitation_width):
        raise ValueError(
            f"{system.name}: excitation of shape {ff.shape} for {system.n_inputs} input(s) "
            f"({system.excitation_width} columns)"
        )
    return ff, ff.ndim == (3 if multi else 2)


def rk4(
    system: StructuralSystem,
    p: dict[str, Any],
    t: np.ndarray,
    f: np.ndarray,
    y0: Any,
    substeps: int = 4,
    t0: np.ndarray | float = 0.0,
) -> tuple[Any, Any]:
    """Integrate ``B`` trajectories over the shared local grid ``t`` (N,).

    Args:
        p: parameter values, scalars or (B,) arrays (plain or dual).
        f: excitation samples, (N,) shared or (N, B) per trajectory; a system with several
            inputs takes (N, W) shared or (N, B, W), W its ``excitation_width``.
        y0: initial states (B, n_state), plain or dual.
        t0: absolute start time of each trajectory (time-dependent terms see t0 + t - t[0]).
    Returns:
        states (N, B, n_state) and their rates (N, B, n_state), dual when any input is.
    """
    N = len(t)
    D = _n_dir(p, y0)
    y = y0 if (D == 0 or isinstance(y0, Dual)) else Dual(y0, np.zeros(np.shape(y0) + (D,)))
    shape = y.shape
    Yv = np.empty((N,) + shape)
    Yd = np.empty((N,) + shape + (D,)) if D else None
    tt = (
        np.asarray(t0, float) + (np.asarray(t, float) - float(t[0]))[:, None]
        if np.ndim(t0)
        else float(t0) + np.asarray(t, float) - float(t[0])
    )
    ff, per_trajectory = _checked_excitation(system, f)

    def store(i: int, yi: Any) -> None:
        if D:
            Yv[i], Yd[i] = yi.v, yi.d  # type: ignore[index]
        else:
            Yv[i] = yi

    store(0, y)
    rate = system.state_rate
    for i in range(N - 1):
        h = (float(t[i + 1]) - float(t[i])) / substeps
        df = (ff[i + 1] - ff[i]) / substeps
        for s in range(substeps):
            ta = tt[i] + s * h
            fa = ff[i] + s * df
            fm = fa + 0.5 * df
            k1 = rate(ta, y, p, fa)
            k2 = rate(ta + 0.5 * h, y + (0.5 * h) * k1, p, fm)
            k3 = rate(ta + 0.5 * h, y + (0.5 * h) * k2, p, fm)
            k4 = rate(ta + h, y + h * k3, p, fa + df)
            y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        store(i + 1, y)
    Y: Any = Dual(Yv, Yd) if D else Yv
    T = tt if np.ndim(tt) == 2 else np.broadcast_to(np.asarray(tt)[:, None], (N, shape[0]))
    F = ff if per_trajectory else np.broadcast_to(ff[:, None], (N, shape[0]) + ff.shape[1:])
    R = rate(T, Y, p, F)
    return Y, R
