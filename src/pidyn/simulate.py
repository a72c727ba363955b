"""Ground truth by a tightly integrated variable-step scheme, the measurement model, and the one simulator of
identified models (torch-free, any system, fixed-step RK4 of ``pidyn.integrate``: bounded cost):
``simulate_states`` for one model's states, ``simulate_response`` for its response in a record's
convention, ``simulate_batch`` for many parameter sets at once. Train, diagnose, the baselines,
the reports and the API use these."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.integrate import odeint, solve_ivp

from pidyn.compiled import kernel
from pidyn.excitation.ground_motion import GroundMotion, SupportMotions
from pidyn.integrate import input_hold, piece_starts, rk4, stage_excitation
from pidyn.systems.base import StructuralSystem
from pidyn.systems.modal import linear_matrices, state_matrix

if TYPE_CHECKING:
    from pidyn.data.sources import Record


@dataclass
class Trajectory:
    """Sampled response: ``x, v, a`` (N, n_dof) relative to the ground, ``z`` (N, n_latent),
    excitation ``f`` (N,) or (N, n_inputs)."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    f: np.ndarray
    z: np.ndarray | None = None
    meta: dict = field(default_factory=dict)


def simulate(
    system: StructuralSystem,
    params: dict[str, float],
    excitation: Callable[[np.ndarray | float], np.ndarray],
    t_eval: np.ndarray,
    y0: np.ndarray | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_step: float | None = None,
    method: str = "auto",
) -> Trajectory:
    """Integrate the system's right-hand side and sample it at ``t_eval``.

    ``excitation(t)`` returns the ground acceleration or force (linear interpolation of a
    record is the usual choice). ``max_step`` defaults to the sample step so the integrator
    cannot step over the kinks of a piecewise-linear excitation.

    ``method="auto"``: under a record (``GroundMotion``, ``SupportMotions``), Dormand and
    Prince's 5(4) pair in C (``pidyn.compiled.kernel.truth``, every step ending on the record's
    samples: a few ms a record where LSODA calling back for each of its hundred thousand
    evaluations takes half a second; the two agree to their tolerance); elsewhere LSODA.
    LSODA runs through ``odeint``: the same Fortran solver as ``solve_ivp(method="LSODA")``, but
    its steps stay in Fortran instead of returning to Python after each one, 1.3-2.4x faster
    for the same accuracy. Other methods go through ``solve_ivp``.
    """
    n, nz = system.n_dof, system.n_latent
    t_eval = np.asarray(t_eval, dtype=float)
    if t_eval.ndim != 1 or t_eval.size < 2 or np.any(np.diff(t_eval) <= 0):
        raise ValueError("t_eval must be a strictly increasing 1-D array")
    y0 = np.zeros(2 * n + nz) if y0 is None else np.asarray(y0, dtype=float)
    found = None
    columns = _sampled_columns(excitation)
    if method == "auto" and columns is not None and max_step is None:
        # at a hundredth of the tolerance: as close to the exact solution as LSODA at the full one, on
        # every system of the library (a deck on hysteretic supports the hardest), for 20 % more time
        found = kernel.truth(system, params, columns, t_eval, y0, rtol / 100, atol / 100)
    if found is not None:
        y, dy = found  # the rates at the samples come with the states
    else:
        fun = _rate(system, params, excitation)
        step = max_step if max_step is not None else float(np.min(np.diff(t_eval)))
        y = _integrate(
            fun, y0, t_eval, rtol, atol, step, "LSODA" if method == "auto" else method, system.name
        )
        dy = np.array([fun(t, yi) for t, yi in zip(t_eval, y)])
    x, v = y[:, :n], y[:, n : 2 * n]
    a = dy[:, n : 2 * n]
    z = y[:, 2 * n :] if nz else None
    return Trajectory(t=t_eval, x=x, v=v, a=a, f=np.asarray(excitation(t_eval), dtype=float), z=z)


def _rate(system: StructuralSystem, params: dict[str, float], excitation: Callable) -> Callable:
    """The right-hand side ``f(t, y)`` for a variable-step integrator: compiled where it can be (a
    record's samples read in it, as ``GroundMotion`` reads them), else the system's own."""
    if system.n_inputs > 1:  # several inputs: excitation(t) gives one value per input
        f_scalar = lambda t: np.asarray(excitation(t), dtype=float)  # noqa: E731
    else:
        f_scalar = lambda t: float(excitation(t))  # noqa: E731
    sampled = type(excitation) is GroundMotion and system.n_inputs == 1
    compiled = kernel.rate_function(system, params, (excitation.acc, excitation.dt) if sampled else None)
    if compiled is not None and sampled:
        return compiled
    if compiled is not None:
        return lambda t, y: compiled(t, y, f_scalar(t))
    return lambda t, y: system.rhs(t, y, params, f_scalar)


def _sampled_columns(excitation: object) -> tuple[np.ndarray, float, np.ndarray] | None:
    """A record's excitation as the compiled ground truth reads it (columns, dt, hold-after-end),
    or None for an excitation given only as a function."""
    if type(excitation) is GroundMotion:
        return excitation.acc[:, None], excitation.dt, np.zeros(1)
    if type(excitation) is SupportMotions:
        k = excitation.acc.shape[1]  # accelerations zero after the record, velocities held
        return excitation.columns, excitation.dt, np.r_[np.zeros(k), np.ones(k)]
    return None


def _integrate(
    fun, y0: np.ndarray, t_eval: np.ndarray, rtol: float, atol: float, step: float, method: str, name: str
):
    """The states at ``t_eval``: LSODA through ``odeint`` (its steps stay in Fortran), other
    methods through ``solve_ivp``; a failed integration raises, naming the system."""
    if method == "LSODA":
        y, info = odeint(
            fun,
            y0,
            t_eval,
            tfirst=True,
            rtol=rtol,
            atol=atol,
            hmax=step,
            mxstep=1_000_000,
            full_output=True,
        )
        if info["message"] != "Integration successful.":
            raise RuntimeError(f"simulation of {name} failed: {info['message']}")
    else:
        sol = solve_ivp(
            fun,
            (float(t_eval[0]), float(t_eval[-1])),
            y0,
            method=method,
            t_eval=t_eval,
            rtol=rtol,
            atol=atol,
            max_step=step,
        )
        if not sol.success:
            raise RuntimeError(f"simulation of {name} failed: {sol.message}")
        y = sol.y.T
    return y


def add_noise(
    channels: dict[str, np.ndarray], level: float | dict[str, float], seed: int
) -> dict[str, np.ndarray]:
    """Gaussian measurement noise with std = ``level`` x RMS of each channel (column-wise);
    ``level`` is one fraction for all channels or one per channel name.

    One generator seeded by ``seed`` draws every channel in a fixed order (sorted names),
    so a noise realisation is reproducible and independent of the network's seed.
    """
    levels = level if isinstance(level, dict) else {name: level for name in channels}
    if any(v < 0 for v in levels.values()):
        raise ValueError(f"noise level must be >= 0, got {level}")
    rng = np.random.default_rng(seed)
    out = {}
    for name in sorted(channels):
        y = np.asarray(channels[name], dtype=float)
        rms = np.sqrt(np.mean(y**2, axis=0, keepdims=True))
        lv = float(levels[name])
        out[name] = y + lv * rms * rng.standard_normal(y.shape) if lv > 0 else y.copy()
    return out


def simulate_states(
    system: StructuralSystem,
    values: dict[str, float],
    t: np.ndarray,
    f: np.ndarray,
    state0: np.ndarray | None = None,
    substeps: int = 4,
    hold: str = "linear",
    restarts: tuple[int, ...] | list[int] = (),
) -> tuple[np.ndarray, np.ndarray]:
    """One model's states Y (N, n_state) and their rates R (N, n_state) under the excitation ``f``
    (read between samples by ``hold``, see ``pidyn.integrate``) from ``state0`` (the full state,
    default rest), from rest again at each of ``restarts`` (where another record begins); a model
    that blows up gives NaNs."""
    y0 = np.zeros(system.n_state) if state0 is None else np.asarray(state0, float)
    stages = stage_excitation(f, substeps, hold)
    with np.errstate(all="ignore"):
        Y, R = rk4(
            system, dict(values), t, f, y0[None, :], substeps=substeps, stages=stages, restarts=restarts
        )
    return Y[:, 0], R[:, 0]


#: at most this many RK4 steps per sample: a model faster still is refused, not simulated (a
#: storey of a hundredth of a gram under a large dashpot: its rate is no structure's)
MAX_SUBSTEPS = 32


def _rates(system, values: dict[str, float]) -> np.ndarray | None:
    """The eigenvalues of the model's linear part about rest; None for a model without one."""
    try:
        M, C, K = (np.atleast_2d(np.asarray(a, float)) for a in linear_matrices(system, values))
        return np.linalg.eigvals(state_matrix(M, C, K))
    except (ValueError, KeyError, np.linalg.LinAlgError):
        return None


def _stability(lam: np.ndarray, h: float, substeps: int) -> dict:
    if not np.all(np.isfinite(lam)):
        return {"stable": False, "max_abs_lambda_h": float("inf"), "max_amplification": float("inf")}
    z = lam * h
    amp = np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)
    return {
        "stable": bool(np.max(amp) <= 1.0 + 1e-9),
        "max_abs_lambda_h": float(np.max(np.abs(z))),
        "max_amplification": float(np.max(amp)),
        "step_s": h,
        "substeps": int(substeps),
    }


def rk4_stability(
    system, values: dict[str, float], dt: float, substeps: int | None = 4
) -> dict[str, Any] | None:
    """Whether the fixed-step RK4 (``substeps`` steps per sample; None: as many as
    ``stable_substeps`` gives) is stable for the model's linear part about rest: every
    eigenvalue's ``|R(lambda h)|`` at most 1, R the RK4 amplification ``1 + z + z^2/2 + z^3/6 +
    z^4/24``. A storey of tiny mass and large damping has a rate far beyond the step; its
    simulation blows up whatever the data say. None for a model without a linear part about rest."""
    lam = _rates(system, values)
    if lam is None:
        return None
    if substeps is None:  # the simulator's own choice; where none is stable, its limit reported
        found = stable_substeps(system, values, dt, lam=lam)
        out = _stability(lam, float(dt) / found, found)
        return out if out["stable"] else _stability(lam, float(dt) / MAX_SUBSTEPS, MAX_SUBSTEPS)
    return _stability(lam, float(dt) / substeps, substeps)


def stable_substeps(system, values: dict[str, float], dt: float, substeps: int = 4, lam=None) -> int:
    """The fewest RK4 steps per sample, at least ``substeps`` and at most ``MAX_SUBSTEPS``, at which
    the scheme is stable for the model's linear part about rest; ``substeps`` where none is (the
    model is refused as it stands) or the model has no linear part. A storey whose dashpot is
    overdamped on its own has a real rate of a thousand per second: four steps per sample at
    120 Hz cannot follow it, five can, and the model is then judged by its fit, not by the
    integrator's step (the same model by exact exponentials fits its record as well)."""
    lam = _rates(system, values) if lam is None else lam
    if lam is None:
        return substeps
    s = int(substeps)
    while s <= MAX_SUBSTEPS:
        if _stability(lam, float(dt) / s, s)["stable"]:
            return s
        s += max(1, s // 4)
    return int(substeps)


def simulate_response(
    system: StructuralSystem,
    values: dict[str, float],
    record: Record,
    substeps: int = 4,
    state0: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """The identified model's response over the record: ``x, v`` (relative, (N, n_dof)), its
    latent states ``z`` ((N, n_latent)) and ``a`` in the record's convention (relative to the
    one ground; absolute for several inputs) by the fixed-step batched RK4 (bounded cost: a
    model that blows up gives NaNs rather than an adaptive integrator crawling) from
    ``state0`` (the full state, default rest), the excitation read between samples as the
    record says (``meta.input_hold``, default linear). A model whose linear part needs more
    steps per sample than ``substeps`` to be simulated stably gets them (``stable_substeps``)."""
    n = system.n_dof
    if len(record.t) > 1:
        substeps = stable_substeps(system, values, record.dt, substeps)
    Y, R = simulate_states(
        system, values, record.t, record.f, state0, substeps, input_hold(record), piece_starts(record)
    )
    with np.errstate(all="ignore"):
        a = system.acceleration_output(R[:, n : 2 * n], np.asarray(record.f, float), dict(values))
    return {"x": Y[:, :n], "v": Y[:, n : 2 * n], "z": Y[:, 2 * n :], "a": a}


def simulate_batch(
    system: StructuralSystem,
    params: dict[str, np.ndarray],
    t: np.ndarray,
    f: np.ndarray,
    substeps: int = 4,
    state0: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    hold: str = "linear",
) -> dict[str, np.ndarray]:
    """Simulate P parameter sets; ``params[name]`` has shape (P,) (or scalar); the excitation
    read between samples by ``hold``.

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
    ff = np.asarray(f, float)
    stages = stage_excitation(ff, substeps, hold)
    Y, R = rk4(system, p, np.asarray(t, float), ff, y0, substeps=substeps, stages=stages)
    sq = (lambda a: a[..., 0]) if n == 1 else (lambda a: a)
    return {"x": sq(Y[..., :n]), "v": sq(Y[..., n : 2 * n]), "a": sq(R[..., n : 2 * n]), "z": Y[..., 2 * n :]}
