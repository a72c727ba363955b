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

#: integrates (t, excitation per trajectory, initial states, parameters) by the general scheme;
#: (values, derivatives or None)
Loop = Callable[[np.ndarray, np.ndarray, Any, dict[str, Any]], tuple[np.ndarray, np.ndarray | None]]


def _values(v: Any) -> Any:
    return v.v if isinstance(v, Dual) else v


def applies(system: StructuralSystem, p: dict[str, Any], t: np.ndarray, y0: Any) -> bool:
    """Whether the one-sample map stands for the scheme: a linear time-invariant system, each
    parameter one value or one per trajectory, a uniform grid and a batch of states."""
    shape = y0.shape if isinstance(y0, Dual) else np.shape(y0)
    if not getattr(system, "linear_time_invariant", False) or len(t) < 3 or len(shape) != 2:
        return False
    if any(np.shape(_values(v)) not in ((), shape[:1]) for v in p.values()):
        return False
    dt = np.diff(np.asarray(t, float))
    return bool(dt[0] > 0 and np.all(np.abs(dt - dt[0]) <= 1e-9 * dt[0]))


def _unit_probes(system: StructuralSystem, n: int, copies: int) -> tuple[np.ndarray, np.ndarray]:
    """Initial states and two-sample excitations, one trajectory each, ``copies`` times over:
    rest, every unit state, every unit sample at the interval's start, every one at its end."""
    w = system.excitation_width
    k = 1 + n + 2 * w
    y0 = np.zeros((k, n))
    y0[1 : 1 + n] = np.eye(n)
    f = np.zeros((2, k, w))
    f[0, 1 + n : 1 + n + w] = np.eye(w)
    f[1, 1 + n + w :] = np.eye(w)
    y0, f = np.tile(y0, (copies, 1)), np.tile(f, (1, copies, 1))
    return y0, (f[..., 0] if system.n_inputs == 1 else f)


def _repeated(p: dict[str, Any], each: int) -> dict[str, Any]:
    """Per-trajectory parameters, each value repeated for ``each`` probes in a row."""
    out = {}
    for name, v in p.items():
        if np.shape(_values(v)) == ():
            out[name] = v
        elif isinstance(v, Dual):
            out[name] = Dual(np.repeat(v.v, each), np.repeat(v.d, each, axis=0))
        else:
            out[name] = np.repeat(np.asarray(v), each)
    return out


def sample_map(
    system: StructuralSystem, t: np.ndarray, loop: Loop, p: dict[str, Any], n: int, batch: int
) -> tuple[Any, ...]:
    """(M, G0, G1, g), each with a leading axis of one entry or one per trajectory (``batch``
    with per-trajectory parameters), and with dual parameters their derivatives (a trailing
    axis of directions; None without): the one-interval response to the unit probes."""
    per = any(np.shape(_values(v)) != () for v in p.values())
    copies = batch if per else 1
    k = 1 + n + 2 * system.excitation_width
    y0, f = _unit_probes(system, n, copies)
    v, d = loop(np.asarray(t[:2], float), f, y0, _repeated(p, k) if per else p)
    maps = _columns(v[1].reshape(copies, k, n), n)
    if d is None:
        return maps + (None,) * 4
    return maps + _columns(d[1].reshape(copies, k, n, -1), n)


def _columns(end: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    """(M, G0, G1, g) from the probes' states at the interval's end, (copies, probes, n, ...):
    column j of M is the response to unit state j less the response at rest."""
    rest = end[:, :1]
    less = end - rest
    w = (end.shape[1] - 1 - n) // 2
    parts = (less[:, 1 : 1 + n], less[:, 1 + n : 1 + n + w], less[:, 1 + n + w :])
    return tuple(np.swapaxes(x, 1, 2) for x in parts) + (rest[:, 0],)


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
    p: dict[str, Any],
    loop: Loop,
) -> tuple[np.ndarray, np.ndarray | None]:
    """States (N, B, n) and, with dual parameters or states, their derivatives (N, B, n, D)."""
    y0v = y0.v if isinstance(y0, Dual) else np.asarray(y0, float)
    n = y0v.shape[-1]
    m, g0, g1, g, dm, dg0, dg1, dg = sample_map(system, t, loop, p, n, y0v.shape[0])
    f = _as_columns(system, ff, per_trajectory)
    u = _apply(g0, f[:-1]) + _apply(g1, f[1:]) + g
    yv = np.empty((len(t),) + y0v.shape)
    yv[0] = y0v
    for i in range(len(t) - 1):
        yv[i + 1] = _apply(m, yv[i]) + u[i]
    if dm is None:  # the loop carries directions whenever the parameters or the start have them
        return yv, None
    yd = np.empty(yv.shape + dm.shape[-1:])
    yd[0] = y0.d if isinstance(y0, Dual) else 0.0
    force = np.einsum("...ijd,...j->...id", dm, yv[:-1])
    force += np.einsum("...iwd,...w->...id", dg0, f[:-1]) + np.einsum("...iwd,...w->...id", dg1, f[1:])
    force += dg
    for i in range(len(t) - 1):
        yd[i + 1] = np.matmul(m, yd[i]) + force[i]
    return yv, yd


def _apply(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """a (B|1, n, k) applied to x (..., B|1, k): (..., B, n)."""
    return np.matmul(a, x[..., None])[..., 0]
