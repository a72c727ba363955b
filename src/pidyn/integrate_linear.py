"""The RK4 scheme of a linear time-invariant system as its one-sample map.

For y' = A y + B f + c with the excitation linear between samples, every RK4 substep is an
affine map of the state and of the two samples around it, so one sample interval of
``substeps`` substeps is

    y[i+1] = M y[i] + G0 f[i] + G1 f[i+1] + g.

M, G0, G1 and g are read off the integrator itself, one interval integrated from the unit
states and unit samples (with dual parameters their derivatives come along), and the whole
record is then that recursion: the same discrete scheme and the same sensitivities, to
rounding, at a small fraction of the per-stage cost. The nominal models of an identification
and of a diagnosis (viscous damping, linear springs, supports, modes) are such systems, and
their output-error fits simulate them hundreds of times.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pidyn.autodiff import Dual
from pidyn.systems.base import StructuralSystem

#: integrates (t, excitation per trajectory, initial states) by the general scheme; (values, derivatives)
Loop = Callable[[np.ndarray, np.ndarray, Any], tuple[np.ndarray, np.ndarray | None]]


def applies(system: StructuralSystem, p: dict[str, Any], t: np.ndarray, y0: Any) -> bool:
    """Whether the one-sample map stands for the scheme: a linear time-invariant system, one
    value per parameter (not one per trajectory), a uniform grid and a batch of states."""
    shape = y0.shape if isinstance(y0, Dual) else np.shape(y0)
    if not getattr(system, "linear_time_invariant", False) or len(t) < 3 or len(shape) != 2:
        return False
    for v in p.values():
        if np.shape(v.v if isinstance(v, Dual) else v) != ():
            return False
    dt = np.diff(np.asarray(t, float))
    return bool(dt[0] > 0 and np.all(np.abs(dt - dt[0]) <= 1e-9 * dt[0]))


def _unit_probes(system: StructuralSystem, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Initial states and two-sample excitations, one trajectory each: rest, every unit state,
    every unit sample at the interval's start, every unit sample at its end."""
    w = system.excitation_width
    k = 1 + n + 2 * w
    y0 = np.zeros((k, n))
    y0[1 : 1 + n] = np.eye(n)
    f = np.zeros((2, k, w))
    f[0, 1 + n : 1 + n + w] = np.eye(w)
    f[1, 1 + n + w :] = np.eye(w)
    return y0, (f[..., 0] if system.n_inputs == 1 else f)


def sample_map(system: StructuralSystem, t: np.ndarray, loop: Loop, n: int) -> tuple[np.ndarray, ...]:
    """(M, G0, G1, g) and, with dual parameters, their derivatives (each with a trailing axis
    of directions; None without): the columns of the one-interval response to the probes."""
    y0, f = _unit_probes(system, n)
    v, d = loop(np.asarray(t[:2], float), f, y0)
    w = system.excitation_width
    end = v[1] - v[1][0]
    maps = (end[1 : 1 + n].T, end[1 + n : 1 + n + w].T, end[1 + n + w :].T, v[1][0])
    if d is None:
        return maps + (None,) * 4
    dend = d[1] - d[1][0]
    dmaps = tuple(
        np.transpose(x, (1, 0, 2)) for x in (dend[1 : 1 + n], dend[1 + n : 1 + n + w], dend[1 + n + w :])
    )
    return maps + dmaps + (d[1][0],)


def _as_columns(system: StructuralSystem, ff: np.ndarray, per_trajectory: bool) -> np.ndarray:
    """The excitation as (N, B or 1, W)."""
    if system.n_inputs == 1:
        return ff[:, :, None] if per_trajectory else ff[:, None, None]
    return ff if per_trajectory else ff[:, None, :]


def propagate(
    system: StructuralSystem,
    t: np.ndarray,
    ff: np.ndarray,
    per_trajectory: bool,
    y0: Any,
    loop: Loop,
) -> tuple[np.ndarray, np.ndarray | None]:
    """States (N, B, n) and, with dual parameters or states, their derivatives (N, B, n, D)."""
    n = y0.shape[-1] if isinstance(y0, Dual) else np.shape(y0)[-1]
    m, g0, g1, g, dm, dg0, dg1, dg = sample_map(system, t, loop, n)
    f = _as_columns(system, ff, per_trajectory)
    u = f[:-1] @ g0.T + f[1:] @ g1.T + g
    y0v = y0.v if isinstance(y0, Dual) else np.asarray(y0, float)
    yv = np.empty((len(t),) + y0v.shape)
    yv[0] = y0v
    mt = np.ascontiguousarray(m.T)
    for i in range(len(t) - 1):
        yv[i + 1] = yv[i] @ mt + u[i]
    if dm is None and not isinstance(y0, Dual):
        return yv, None
    n_dir = dm.shape[-1] if dm is not None else y0.d.shape[-1]
    yd = np.empty(yv.shape + (n_dir,))
    yd[0] = y0.d if isinstance(y0, Dual) else 0.0
    if dm is None:
        force = np.zeros((len(t) - 1,) + yv.shape[1:] + (n_dir,))
    else:
        force = np.einsum("ijd,nbj->nbid", dm, yv[:-1])
        force += np.einsum("nbw,iwd->nbid", f[:-1], dg0) + np.einsum("nbw,iwd->nbid", f[1:], dg1) + dg
    for i in range(len(t) - 1):
        yd[i + 1] = np.matmul(m, yd[i]) + force[i]
    return yv, yd
