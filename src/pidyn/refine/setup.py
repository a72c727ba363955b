"""The shooting problem set up from a record: the refinement's settings, the segments (ending
where a record begins, at most ``MAX_SEGMENTS`` of them) and their starting states (from the
networks, the measurements, the integrated accelerations or a start's own simulation)."""

from __future__ import annotations

import logging

import numpy as np

from pidyn.integrate import input_hold, piece_starts
from pidyn.refine.problem import ShootingProblem, record_channels, segment_bounds
from pidyn.refine.settings import RefineSettings, StateSource

log = logging.getLogger(__name__)


def _lookup(network_states: np.ndarray | None, t: float, tol: float) -> np.ndarray | None:
    if network_states is None or not len(network_states):
        return None
    i = int(np.argmin(np.abs(network_states[:, 0] - t)))
    return network_states[i, 1:] if abs(network_states[i, 0] - t) <= tol else None


def initial_states(
    problem: ShootingProblem, theta: np.ndarray, source: StateSource, network_states: np.ndarray | None = None
) -> np.ndarray:
    """Segment initial states (S, n_state): from the networks, the measured x, x' or the
    integrated measurements where they exist, otherwise carried from the previous segment's
    simulated end (at ``theta``)."""
    n, ns = problem.system.n_dof, problem.ns
    t = problem.t
    tol = 0.5 * float(t[1] - t[0])
    measured = {(ch.kind, ch.dof): ch.data for ch in problem.channels if ch.kind in ("x", "v")}
    if source == "integrated":
        measured = integrated_states(problem)
        source = "measured"
    states = np.zeros((problem.S, ns))
    y = np.zeros(ns)
    for s in range(problem.S):
        i = int(problem.bounds[s])
        got = _lookup(network_states, float(t[i]), tol) if source == "networks" else None
        if got is not None and got.size == ns:
            y = got.copy()
        elif source == "measured" or s == 0:
            y = _measured_state(y, measured, i, n)
        states[s] = y
        if s + 1 < problem.S:
            end = problem.free_run(theta, y, i, int(problem.bounds[s + 1]))[0][-1]
            y = np.nan_to_num(end, nan=0.0, posinf=0.0, neginf=0.0)
    return states


def integrated_states(problem: ShootingProblem) -> dict[tuple[str, int], np.ndarray]:
    """x and x' of every floor with a sensor, as a practitioner gets them from accelerometers:
    the acceleration integrated (trapezoidal rule) with a linear baseline correction of the
    velocity and of the displacement; a measured velocity or displacement is used as it is.
    This is the refinement's start without networks (integration drifts, see docs/buildings.md)."""
    t = problem.t
    by = {(ch.kind, ch.dof): ch.data for ch in problem.channels}
    out: dict[tuple[str, int], np.ndarray] = {}

    def integral(y: np.ndarray) -> np.ndarray:
        z = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])
        return z - np.polyval(np.polyfit(t, z, 1), t)

    for d in range(problem.system.n_dof):
        v = by.get(("v", d))
        if v is None and ("a", d) in by:
            v = integral(by[("a", d)])
        x = by.get(("x", d))
        if x is None and v is not None:
            x = integral(v)
        if x is not None:
            out[("x", d)] = x
        if v is not None:
            out[("v", d)] = v
    return out


def _measured_state(y: np.ndarray, measured: dict, i: int, n: int) -> np.ndarray:
    y = y.copy()
    for d in range(n):
        if ("x", d) in measured:
            y[d] = measured[("x", d)][i]
        if ("v", d) in measured:
            y[n + d] = measured[("v", d)][i]
    return y


def build_problem(
    system, record, settings: RefineSettings, t_start: float | None = None, t_end: float | None = None
) -> ShootingProblem:
    channels = record_channels(record, system.n_dof)
    starts = piece_starts(record)
    bounds = segment_bounds(
        record.t, _segment_length(record, settings, t_start, t_end), t_start, t_end, starts
    )
    state0 = np.zeros(system.n_state) if settings.initial_state == "rest" else None
    return ShootingProblem(
        system,
        record.t,
        record.f,
        channels,
        bounds,
        settings.substeps,
        fixed_state0=state0,
        hold=input_hold(record),
        restarts=starts,
    )


#: at most this many shooting segments: the Jacobian is dense in the segments' states, so its size
#: grows with the record's length times their number (several records of a structure laid end to
#: end would otherwise give thousands); a longer record gets longer segments
MAX_SEGMENTS = 120


def _segment_length(
    record, settings: RefineSettings, t_start: float | None, t_end: float | None
) -> float | None:
    length = settings.segment_length
    if length is None:
        return None
    span = (record.t[-1] if t_end is None else min(t_end, record.t[-1])) - (
        record.t[0] if t_start is None else t_start
    )
    if span / length > MAX_SEGMENTS:
        longer = span / MAX_SEGMENTS
        log.info(
            "shooting segments of %.3g s, not %.3g s: at most %d over %.4g s",
            longer,
            length,
            MAX_SEGMENTS,
            span,
        )
        return longer
    return length


def state_scale(problem: ShootingProblem, states: np.ndarray) -> np.ndarray:
    n = problem.system.n_dof
    ref = {(ch.kind, ch.dof): float(np.std(ch.data)) for ch in problem.channels}
    scale = np.std(states, axis=0)
    for d in range(n):
        scale[d] = max(scale[d], ref.get(("x", d), 0.0))
        scale[n + d] = max(scale[n + d], ref.get(("v", d), 0.0))
    floor = max(float(np.max(scale[:n])), 1e-12)
    return np.where(scale > 1e-9 * floor, scale, floor)
