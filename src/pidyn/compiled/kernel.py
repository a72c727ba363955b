"""The RK4 loop of ``pidyn.integrate`` at compiled speed, for any system whose state rate a tape
can record (``pidyn.compiled.tape``): every system and force term of the library, a learned
force's network included; a term that branches on a value in Python stays in Python.

``steps`` takes what ``pidyn.integrate._steps`` takes and returns the same arrays, or None
where it does not apply (a state rate it cannot record, no C compiler, ``PIDYN_COMPILED=0``,
a run of a few samples, as the UKF's one-sample predictions, where Python is as quick).
"""

from __future__ import annotations

import contextlib
import contextvars
import ctypes
import logging
import os
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from pidyn.autodiff import Dual
from pidyn.compiled import build, codegen
from pidyn.compiled.tape import Tape, record, record_latent
from pidyn.cores import threads

log = logging.getLogger(__name__)

#: fewer sample intervals than this are integrated in Python (tracing and packing cost more)
MIN_INTERVALS = 8
#: the ground truth gives up after this many evaluations of the state rate (LSODA's mxstep, 1e6 steps)
MAX_EVALS = 6_000_000
_KERNELS: dict[tuple, tuple[Any, np.ndarray] | None] = {}
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
#: RK4 substeps (trajectories x substeps a trajectory) below which a call stays in one thread:
#: about 0.2 ms of a small system's arithmetic, a few times what handing a range to a thread costs
MIN_SPLIT_WORK = 20_000
_POOL: tuple[ThreadPoolExecutor, int] | None = None  # the pool and its number of threads
#: within ``tapes_kept``: (id(system), parameter names) -> (the system, its library or None)
_KEPT: contextvars.ContextVar[dict | None] = contextvars.ContextVar("pidyn_kept_tapes", default=None)


def enabled() -> bool:
    return os.environ.get("PIDYN_COMPILED", "1") != "0"


def _kernel(
    tape: Tape, n_param: int, n_state: int, n_input: int, along: bool = False
) -> tuple[Any, np.ndarray] | None:
    """The compiled library of a tape and its constants, built once per tape shape (``along``: a
    latent rate along a given motion, ``codegen.source``)."""
    key = (tuple(tape.nodes), tuple(tape.outputs), n_param, n_state, n_input, along)
    if key not in _KERNELS:
        lib = build.load(codegen.source(tape, n_param, n_state, n_input, along))
        if lib is not None:
            for name in ("run", "run_d", "heun" if along else "truth"):
                getattr(lib, name).restype = ctypes.c_int
        _KERNELS[key] = None if lib is None else (lib, np.array(codegen.plan(tape).constants + [0.0]))
    return _KERNELS[key]


@contextlib.contextmanager
def tapes_kept() -> Iterator[None]:
    """Within the block a system's state rate is recorded once per parameter list, not at every
    simulation: for a fit, whose hundreds of simulations change parameter values and nothing of
    the system itself (recording a tape costs about what a short simulation does). Only around
    code that changes no system it simulates (a learned force's weights are its tape's constants)."""
    if _KEPT.get() is not None:  # an outer block keeps them
        yield
        return
    token = _KEPT.set({})
    try:
        yield
    finally:
        _KEPT.reset(token)


def _library(system: Any, names: list[str]) -> tuple[Any, np.ndarray] | None:
    """The compiled library of ``system``'s state rate with parameters ``names`` and its constants,
    or None where there is none (code a tape cannot follow, no C compiler)."""
    kept = _KEPT.get()
    if kept is None:
        return _recorded(system, names)
    key = (id(system), tuple(names))
    if key not in kept:  # the system is held with it: its id is not another's while the block lasts
        kept[key] = (system, _recorded(system, names))
    return kept[key][1]


def _recorded(system: Any, names: list[str]) -> tuple[Any, np.ndarray] | None:
    try:
        tape = record(system, names, system.excitation_width)
    except Exception as exc:  # noqa: BLE001 - any code a tape cannot follow is integrated in Python
        log.debug("%s: not compiled (%s)", system.name, exc)
        return None
    return _kernel(tape, len(names), system.n_state, system.excitation_width)


def rate_function(
    system: Any, params: dict[str, float], sampled: tuple[np.ndarray, float] | None = None
) -> Any:
    """``f(t, y, excitation) -> dy/dt`` for one plain state, compiled, or None: what a variable-step
    integrator (LSODA, where the ground truth is asked of it) calls tens of thousands of times per record. With
    ``sampled`` = (samples, dt) of a system's one input, ``f(t, y)`` reads the excitation itself,
    linear between samples and zero outside them, as ``np.interp`` reads it (``GroundMotion``)."""
    if sampled is not None and system.excitation_width != 1:
        raise ValueError(f"{system.name}: sampled excitation is for a system of one input")
    names = list(params)
    found = _library(system, names) if enabled() else None
    if found is None:
        return None
    lib, K = found
    P = np.array([float(params[n]) for n in names])
    inv = np.empty(max(int(lib.n_invariants()), 1))
    lib.invariants(_ptr(P), _ptr(K), _ptr(inv))
    out = np.empty(system.n_state)
    tail = (P.ctypes.data, inv.ctypes.data, K.ctypes.data, out.ctypes.data)
    if sampled is not None:
        acc = np.ascontiguousarray(sampled[0], dtype=float)
        call = lib.rhs_sampled
        call.argtypes = [ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_double]
        call.argtypes += [ctypes.c_void_p] * 4
        call.restype = None
        head = (acc.ctypes.data, ctypes.c_int(len(acc)), ctypes.c_double(float(sampled[1])))

        def rate(t: float, y: np.ndarray) -> np.ndarray:
            call(t, (y if y.flags.c_contiguous else np.ascontiguousarray(y)).ctypes.data, *head, *tail)
            return out.copy()

        rate.keep = (P, inv, out, K, acc, lib)  # type: ignore[attr-defined]  # what the pointers point into
        return rate
    fbuf = np.empty(system.excitation_width)
    call = lib.rhs
    call.argtypes = [ctypes.c_double] + [ctypes.c_void_p] * 6
    call.restype = None

    def rate_at(t: float, y: np.ndarray, f: Any) -> np.ndarray:
        fbuf[:] = f
        call(t, (y if y.flags.c_contiguous else np.ascontiguousarray(y)).ctypes.data, fbuf.ctypes.data, *tail)
        return out.copy()

    rate_at.keep = (P, inv, out, K, fbuf, lib)  # type: ignore[attr-defined]
    return rate_at


def _ptr(a: np.ndarray | None) -> Any:
    return None if a is None else a.ctypes.data_as(_DOUBLE_P)


def _params(p: dict[str, Any], names: list[str], B: int, D: int) -> tuple[np.ndarray, np.ndarray | None]:
    """(B, NP) values and (B, NP, D) derivatives of the parameters, broadcast to the trajectories."""
    P = np.empty((B, len(names)))
    dP = np.zeros((B, len(names), D)) if D else None
    for j, name in enumerate(names):
        value = p[name]
        if isinstance(value, Dual):
            P[:, j] = np.broadcast_to(value.v, (B,))
            if dP is not None:
                dP[:, j, :] = np.broadcast_to(value.d, (B, D))
        else:
            P[:, j] = np.broadcast_to(np.asarray(value, float), (B,))
    return P, dP


def _inputs(ff: np.ndarray, per_trajectory: bool, multi: bool) -> np.ndarray:
    """The excitation samples as (N, B, W), or (N, 1, W) where every trajectory reads the same:
    the loop reads that one copy (a band-limited record's stage inputs, copied for each of a
    Jacobian's trajectories, cost more than integrating them)."""
    f = ff if multi else ff[..., None]
    if not per_trajectory:
        f = f[:, None, :]
    return np.ascontiguousarray(f, dtype=float)


def _stages(stages: np.ndarray, per_trajectory: bool, multi: bool) -> np.ndarray:
    """The stage inputs as (N-1, 2S+1, B, W), or with 1 for B (as ``_inputs``)."""
    s = stages if multi else stages[..., None]
    if not per_trajectory:
        s = s[:, :, None, :]
    return np.ascontiguousarray(s, dtype=float)


def steps(
    system: Any,
    p: dict[str, Any],
    t: np.ndarray,
    tt: np.ndarray,
    ff: np.ndarray,
    stages: np.ndarray | None,
    y0: Any,
    substeps: int,
    D: int,
) -> tuple[np.ndarray, np.ndarray | None] | None:
    """``pidyn.integrate._steps`` compiled: states (N, B, n_state) and their derivatives."""
    N = len(t)
    if N - 1 < MIN_INTERVALS or not enabled():
        return None
    multi = system.n_inputs > 1
    per_trajectory = ff.ndim == (3 if multi else 2)
    names = list(p)
    found = _library(system, names)
    if found is None:
        return None
    lib, K = found
    Y0v = np.ascontiguousarray(y0.v if isinstance(y0, Dual) else y0, dtype=float)
    B = Y0v.shape[0]
    P, dP = _params(p, names, B, D)
    TT = np.ascontiguousarray(np.broadcast_to(tt if np.ndim(tt) == 2 else np.asarray(tt)[:, None], (N, B)))
    F = _inputs(ff, per_trajectory, multi)
    ST = None if stages is None else _stages(stages, per_trajectory, multi)
    FB = F.shape[1]
    if FB not in (1, B) or (ST is not None and ST.shape[2] != FB):
        raise ValueError(f"{system.name}: excitation for {FB} trajectories, states for {B}")
    tl = np.ascontiguousarray(t, dtype=float)
    Yv = np.empty((N, B, system.n_state))
    work = (N - 1) * int(substeps) * (1 + D)
    if not D:
        tail = tuple(map(_ptr, (tl, TT, F, ST, P, K, Y0v, Yv)))
        rc = _in_threads(lambda b0, b1: lib.run(N, B, b0, b1, int(substeps), FB, *tail), B, work)
        return (Yv, None) if rc == 0 else None
    dY0 = np.zeros((B, system.n_state, D))
    if isinstance(y0, Dual):
        dY0[...] = y0.d
    Yd = np.empty((N, B, system.n_state, D))
    tail = tuple(map(_ptr, (tl, TT, F, ST, P, dP, K, Y0v, dY0, Yv, Yd)))
    rc = _in_threads(lambda b0, b1: lib.run_d(N, B, b0, b1, int(substeps), FB, D, *tail), B, work)
    return (Yv, Yd) if rc == 0 else None


def _in_threads(call: Any, B: int, work: int) -> int:
    """``call(b0, b1)`` over the B trajectories, split into contiguous ranges run side by side
    (ctypes lets go of the GIL in the call); the first range runs in this thread. Each trajectory is
    integrated by itself, so the split changes no bit. ``work``: RK4 substeps a trajectory, a split
    pays where there are at least ``MIN_SPLIT_WORK`` of them in a range. Returns the worst status."""
    n = min(B, B * work // MIN_SPLIT_WORK)  # most calls are small: the environment is read only for the rest
    if n > 1:
        n = min(n, threads())
    if n <= 1:
        return int(call(0, B))
    edges = [B * k // n for k in range(n + 1)]
    pool = _pool(n - 1)
    pending = [pool.submit(call, edges[k], edges[k + 1]) for k in range(1, n)]
    rc = int(call(edges[0], edges[1]))
    return max([rc] + [int(f.result()) for f in pending])


def _pool(workers: int) -> ThreadPoolExecutor:
    """The threads of ``_in_threads``, started once and kept (a new thread a call costs more than
    a short integration); more are started when more are asked for."""
    global _POOL
    if _POOL is None or _POOL[1] < workers:
        if _POOL is not None:
            _POOL[0].shutdown(wait=False)
        _POOL = (ThreadPoolExecutor(max_workers=workers, thread_name_prefix="pidyn-kernel"), workers)
    return _POOL[0]


def _forget_pool() -> None:
    """In a forked child (a process pool's worker) the parent's threads do not exist: a task handed
    to its pool would wait for ever. The child starts its own."""
    global _POOL
    _POOL = None


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def truth(
    system: Any,
    params: dict[str, float],
    sampled: tuple[np.ndarray, float, np.ndarray],
    t_eval: np.ndarray,
    y0: np.ndarray,
    rtol: float,
    atol: float,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The ground truth's states at ``t_eval`` and their rates there (N, n_state) twice, integrated
    in C by Dormand and Prince's 5(4) pair (``pidyn.compiled.dopri_template``; the rate at an
    output time is the pair's last stage, no extra evaluation), or None where there is no compiled
    library.
    ``sampled`` = (columns (n, W), dt, hold (W,)): the excitation's samples, one column per
    excitation entry, each linear between samples, zero before the record, and after it zero or
    (``hold``) its last value. A failed integration raises, naming the system."""
    cols = np.ascontiguousarray(sampled[0], dtype=float)
    if cols.ndim != 2 or cols.shape[1] != system.excitation_width or not enabled():
        return None
    names = list(params)
    found = _library(system, names)
    if found is None:
        return None
    lib, K = found
    P = np.array([float(params[n]) for n in names])
    T = np.ascontiguousarray(t_eval, dtype=float)
    hold = np.ascontiguousarray(sampled[2], dtype=np.intc)
    Y0 = np.ascontiguousarray(y0, dtype=float)
    Y, DY = np.empty((len(T), system.n_state)), np.empty((len(T), system.n_state))
    rc = lib.truth(
        ctypes.c_int(len(T)),
        _ptr(T),
        _ptr(cols),
        ctypes.c_int(len(cols)),
        ctypes.c_double(float(sampled[1])),
        hold.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
        _ptr(P),
        _ptr(K),
        _ptr(Y0),
        ctypes.c_double(rtol),
        ctypes.c_double(atol),
        ctypes.c_long(max(MAX_EVALS, 5000 * len(T))),
        _ptr(Y),
        _ptr(DY),
    )
    if rc != 0:
        why = "too many steps" if rc == -1 else "a value that is not finite"
        raise RuntimeError(f"simulation of {system.name} failed: {why}")
    return Y, DY


def latent_path(
    term: Any, t: np.ndarray, x: np.ndarray, v: np.ndarray | None, values: dict[str, Any], substeps: int
) -> np.ndarray | None:
    """``pidyn.systems.terms.base.latent_path`` in C for one motion (x of shape (N,)): z (N, P,
    n_latent) for (P,) parameter arrays, (N, n_latent) for scalars; None where it does not apply
    (a motion of several columns, a rate a tape cannot follow, no C compiler)."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if not enabled() or x.ndim != 1 or len(t) < MIN_INTERVALS or (v is not None and np.ndim(v) != 1):
        return None
    shapes = [np.shape(val) for val in values.values()]
    if not shapes or any(len(s) > 1 for s in shapes):
        return None
    names = list(values)
    try:  # a tape of a few hundred nodes, recorded again each call; its library is kept by its nodes
        tape = record_latent(term, names)
    except Exception as exc:  # noqa: BLE001 - a rate a tape cannot follow stays in Python
        log.debug("%s: latent path not compiled (%s)", type(term).__name__, exc)
        return None
    found = _kernel(tape, len(names), term.n_latent, 2, along=True)
    if found is None:
        return None
    lib, K = found
    B = int(max((s[0] for s in shapes if s), default=1))
    P = np.ascontiguousarray(
        np.column_stack([np.broadcast_to(np.asarray(values[n], float), (B,)) for n in names])
    )
    nz = term.n_latent
    Z = np.empty((len(t), B, nz))
    V = np.ascontiguousarray(x if v is None else v, dtype=float)
    lib.heun(
        ctypes.c_int(len(t)),
        ctypes.c_int(B),
        ctypes.c_int(int(substeps)),
        ctypes.c_int(1 if v is None else 0),
        *map(_ptr, (np.ascontiguousarray(t), np.ascontiguousarray(x), V, P, K, np.zeros((B, nz)), Z)),
    )
    return Z if any(shapes) else Z[:, 0, :]
