"""Fixed-step RK4 for a batch of trajectories of one system, on NumPy or dual arrays.

Output error, multiple shooting (one batch member per segment), the Cramer-Rao bound and
the UKF's sigma points all simulate one system under sampled excitation many times over.
Integrating the batch as arrays costs about as much as one scalar solve, and the same loop
run on ``pidyn.autodiff.Dual`` states and parameters returns exact sensitivities of the
discrete scheme. Each sample interval is split into ``substeps`` RK4 steps (4 substeps at
dt = 0.01 s agree with solve_ivp at rtol 1e-10 to about 1e-6 relative for the shipped systems;
see tests). Between samples the excitation is linear (``hold="linear"``, what the project's own
simulated records are made of) or band-limited (``hold="bandlimited"``, for a measured record
whose input was low-pass filtered before sampling). A record sampled a few times per period of
the dynamics needs the second: the linear hold passes a tone at frequency f with the gain
sinc(f/fs)^2, 0.96 at the Silverbox circuit's resonance (9 samples a period), and a fit
absorbs that 4 % into the mass. A linear time-invariant system under the linear hold is
stepped by the same scheme's one-sample map (``pidyn.integrate_linear``) where the loop is not
compiled. The loop itself runs compiled (``pidyn.compiled``) wherever a C compiler is found and
the system's state rate can be recorded, which is every system and term of the library.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.signal import resample_poly

from pidyn import integrate_linear
from pidyn.autodiff import Dual
from pidyn.compiled import kernel
from pidyn.systems.base import StructuralSystem

#: how the excitation is read between its samples
HOLDS = ("linear", "bandlimited")


def input_hold(record: Any) -> str:
    """How a record's excitation is read between samples: ``meta.input_hold``, else linear."""
    return str(record.meta.input_hold or "linear")


def piece_starts(record: Any) -> list[int]:
    """Sample indices where another record of a record made of several begins (``meta.pieces``,
    see ``pidyn.data.multi``): a free run restarts from rest there."""
    return [piece.i0 for piece in record.meta.pieces or [] if piece.i0 > 0]


def stage_excitation(f: np.ndarray, substeps: int, hold: str = "linear") -> np.ndarray | None:
    """The excitation at every RK4 stage time, (N-1, 2*substeps+1, ...) for N samples: entry
    [i, q] is at t_i + q*h/2 with h = dt/substeps. ``None`` for the linear hold, which ``rk4``
    computes on the fly. The band-limited values come from a polyphase (Kaiser-windowed sinc)
    interpolation of the whole record, so segments cut from it afterwards share them."""
    if hold not in HOLDS:
        raise ValueError(f"unknown excitation hold '{hold}' (choose from {', '.join(HOLDS)})")
    if hold == "linear":
        return None

    ff = np.asarray(f, float)
    up = 2 * int(substeps)
    pad = np.concatenate([ff, ff[-1:]], axis=0)  # the last sample held, so the fine grid ends at it
    fine = resample_poly(pad, up, 1, axis=0)[: (len(ff) - 1) * up + 1]
    idx = np.arange(len(ff) - 1)[:, None] * up + np.arange(up + 1)[None, :]
    return fine[idx]


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


def _stage_inputs(ff: np.ndarray, stages: np.ndarray | None, i: int, s: int, substeps: int) -> tuple:
    """The excitation at the start, middle and end of substep ``s`` of sample interval ``i``."""
    if stages is not None:
        return stages[i, 2 * s], stages[i, 2 * s + 1], stages[i, 2 * s + 2]
    df = (ff[i + 1] - ff[i]) / substeps
    fa = ff[i] + s * df
    return fa, fa + 0.5 * df, fa + df


def rk4(
    system: StructuralSystem,
    p: dict[str, Any],
    t: np.ndarray,
    f: np.ndarray,
    y0: Any,
    substeps: int = 4,
    t0: np.ndarray | float = 0.0,
    stages: np.ndarray | None = None,
    restarts: Sequence[int] = (),
) -> tuple[Any, Any]:
    """Integrate ``B`` trajectories over the shared local grid ``t`` (N,).

    Args:
        p: parameter values, scalars or (B,) arrays (plain or dual).
        f: excitation samples, (N,) shared or (N, B) per trajectory; a system with several
            inputs takes (N, W) shared or (N, B, W), W its ``excitation_width``.
        y0: initial states (B, n_state), plain or dual.
        t0: absolute start time of each trajectory (time-dependent terms see t0 + t - t[0]).
        stages: the excitation at the stage times (``stage_excitation``; (N-1, 2*substeps+1)
            followed by f's trailing axes), instead of linear between samples.
        restarts: sample indices (0 < i < N) where another record begins: the state there is
            rest, not the previous sample's state stepped on (``pidyn.data.multi``).
    Returns:
        states (N, B, n_state) and their rates (N, B, n_state), dual when any input is.
    """
    cuts = sorted({int(i) for i in restarts if 0 < int(i) < len(t)})
    if cuts:
        return _pieces(system, p, t, f, y0, substeps, t0, stages, cuts)
    N = len(t)
    D = _n_dir(p, y0)
    tt = (
        np.asarray(t0, float) + (np.asarray(t, float) - float(t[0]))[:, None]
        if np.ndim(t0)
        else float(t0) + np.asarray(t, float) - float(t[0])
    )
    ff, per_trajectory = _checked_excitation(system, f)

    def loop(
        tl: np.ndarray, fl: np.ndarray, yl: Any, pl: dict[str, Any]
    ) -> tuple[np.ndarray, np.ndarray | None]:
        return _steps(system, pl, tl, tl - tl[0], fl, None, yl, substeps, D)

    done = kernel.steps(system, p, t, tt, ff, stages, y0, substeps, D)  # compiled: any system, fastest
    if done is not None:
        Yv, Yd = done
    elif stages is None and integrate_linear.applies(system, p, t, y0):
        Yv, Yd = integrate_linear.propagate(system, np.asarray(t, float), ff, per_trajectory, y0, p, loop)
    else:
        Yv, Yd = _steps(system, p, t, tt, ff, stages, y0, substeps, D)
    shape = Yv.shape[1:]
    Y: Any = Dual(Yv, Yd) if Yd is not None else Yv
    T = tt if np.ndim(tt) == 2 else np.broadcast_to(np.asarray(tt)[:, None], (N, shape[0]))
    F = ff if per_trajectory else np.broadcast_to(ff[:, None], (N, shape[0]) + ff.shape[1:])
    R = system.state_rate(T, Y, p, F)
    return Y, R


def _pieces(
    system: StructuralSystem,
    p: dict[str, Any],
    t: np.ndarray,
    f: np.ndarray,
    y0: Any,
    substeps: int,
    t0: np.ndarray | float,
    stages: np.ndarray | None,
    cuts: list[int],
) -> tuple[Any, Any]:
    """``rk4`` record by record: the first from ``y0``, every later one from rest."""
    t = np.asarray(t, float)
    edges = [0, *cuts, len(t)]
    rest = Dual(np.zeros_like(y0.v), np.zeros_like(y0.d)) if isinstance(y0, Dual) else np.zeros(np.shape(y0))
    Ys, Rs = [], []
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        start = np.asarray(t0, float) + (t[a] - t[0])
        piece_stages = None if stages is None else stages[a : max(a, b - 1)]
        Y, R = rk4(
            system, p, t[a:b], np.asarray(f)[a:b], y0 if k == 0 else rest, substeps, start, piece_stages
        )
        Ys.append(Y)
        Rs.append(R)
    if any(isinstance(Y, Dual) for Y in Ys):
        D = _n_dir(p, y0)
        as_dual = [Y if isinstance(Y, Dual) else Dual(Y, np.zeros(np.shape(Y) + (D,))) for Y in Ys]
        rates = [R if isinstance(R, Dual) else Dual(R, np.zeros(np.shape(R) + (D,))) for R in Rs]
        return (
            Dual(np.concatenate([Y.v for Y in as_dual]), np.concatenate([Y.d for Y in as_dual])),
            Dual(np.concatenate([R.v for R in rates]), np.concatenate([R.d for R in rates])),
        )
    return np.concatenate(Ys), np.concatenate(Rs)


def _steps(
    system: StructuralSystem,
    p: dict[str, Any],
    t: np.ndarray,
    tt: np.ndarray,
    ff: np.ndarray,
    stages: np.ndarray | None,
    y0: Any,
    substeps: int,
    D: int,
) -> tuple[np.ndarray, np.ndarray | None]:
    """The RK4 loop: states (N, B, n_state) and their derivatives (None without directions)."""
    N = len(t)
    y = y0 if (D == 0 or isinstance(y0, Dual)) else Dual(y0, np.zeros(np.shape(y0) + (D,)))
    shape = y.shape
    Yv = np.empty((N,) + shape)
    Yd = np.empty((N,) + shape + (D,)) if D else None

    def store(i: int, yi: Any) -> None:
        if D:
            Yv[i], Yd[i] = yi.v, yi.d  # type: ignore[index]
        else:
            Yv[i] = yi

    store(0, y)
    rate = system.state_rate
    for i in range(N - 1):
        h = (float(t[i + 1]) - float(t[i])) / substeps
        for s in range(substeps):
            ta = tt[i] + s * h
            fa, fm, fb = _stage_inputs(ff, stages, i, s, substeps)
            k1 = rate(ta, y, p, fa)
            k2 = rate(ta + 0.5 * h, y + (0.5 * h) * k1, p, fm)
            k3 = rate(ta + 0.5 * h, y + (0.5 * h) * k2, p, fm)
            k4 = rate(ta + h, y + h * k3, p, fb)
            y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        store(i + 1, y)
    return Yv, Yd
