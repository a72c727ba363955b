"""The refinement stage: multiple shooting from PIDynNet's estimate and networks.

PIDynNet's windows are shooting segments, and its networks give the full state (x, x', and
the latent z) at every segment start: exactly what multiple shooting needs and what a
single-shooting fit lacks. The stage takes those states and PIDynNet's parameters (or a
classical estimate, when that one simulates the record better), solves the shooting
problem to exact continuity (``pidyn.refine.solve``), estimates the noise from the
residuals, and returns every parameter with its 95 % interval.

    result = refine(system, record, start={"pidynnet": values}, network_states=states)
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from typing import Literal

import numpy as np

from pidyn.refine.problem import ShootingProblem, record_channels, segment_bounds
from pidyn.refine.solve import solve, solve_constrained
from pidyn.refine.uncertainty import (
    bound_notes,
    correlation,
    covariance,
    estimate_noise,
    identifiability_notes,
    intervals,
    set_noise,
)

log = logging.getLogger(__name__)

StateSource = Literal["networks", "measured", "simulated"]


@dataclass
class RefineSettings:
    """How the shooting problem is set up and solved (``conf/model/refine/multiple_shooting.yaml``)."""

    segment_length: float = 1.0  # s; shorter segments give a smoother cost (Ribeiro et al. 2020)
    states: StateSource = "networks"  # where segment initial states start: networks | measured | simulated
    substeps: int = 4  # RK4 steps per sample interval
    free_initial_state: bool = True  # the record's initial state is an unknown too
    penalty_start: float = 100.0  # first continuity weight, relative to a segment's data term
    penalty_tol: float = 1e-6  # stage 1 ends when every continuity defect is below this (state scales)
    max_nfev: int = 100  # Levenberg-Marquardt evaluations per penalty round
    gn_steps: int = 12  # constrained Gauss-Newton steps (stage 2)
    reweight: bool = True  # weight each channel by its estimated noise and finish again

    def __post_init__(self) -> None:
        if self.states not in ("networks", "measured", "simulated"):
            raise ValueError(f"refine.states must be networks, measured or simulated; got '{self.states}'")
        if self.segment_length is not None and self.segment_length <= 0:
            raise ValueError(f"refine.segment_length must be > 0 s, got {self.segment_length}")


@dataclass
class RefineResult:
    params: dict[str, float]
    intervals: dict[str, dict]  # name -> value, std, ci95 [lo, hi], rel_std_pct
    correlation: list[list[float]]
    names: list[str]
    noise_std: dict[str, float]  # per channel, estimated from the residuals
    notes: list[str]  # identifiability, in words
    start: str  # which starting estimate the solution came from
    start_costs: dict[str, float]  # free-simulation cost of each candidate start (noise units)
    initial_state: list[float]
    cost: float
    max_defect: float
    segments: int
    condition_number: float
    converged: bool
    seconds: float
    state_source: str
    history: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


def _lookup(network_states: np.ndarray | None, t: float, tol: float) -> np.ndarray | None:
    if network_states is None or not len(network_states):
        return None
    i = int(np.argmin(np.abs(network_states[:, 0] - t)))
    return network_states[i, 1:] if abs(network_states[i, 0] - t) <= tol else None


def initial_states(problem: ShootingProblem, theta: np.ndarray, source: StateSource,
                   network_states: np.ndarray | None = None) -> np.ndarray:
    """Segment initial states (S, n_state): from the networks or the measured x, x' where they
    exist, otherwise carried from the previous segment's simulated end (at ``theta``)."""
    n, ns = problem.system.n_dof, problem.ns
    t = problem.t
    tol = 0.5 * float(t[1] - t[0])
    measured = {(ch.kind, ch.dof): ch.data for ch in problem.channels if ch.kind in ("x", "v")}
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
            y = _run(problem, theta, y, i, int(problem.bounds[s + 1]))[0][-1]
    return states


def _measured_state(y: np.ndarray, measured: dict, i: int, n: int) -> np.ndarray:
    y = y.copy()
    for d in range(n):
        if ("x", d) in measured:
            y[d] = measured[("x", d)][i]
        if ("v", d) in measured:
            y[n + d] = measured[("v", d)][i]
    return y


def _run(problem: ShootingProblem, theta: np.ndarray, y0: np.ndarray, i: int, j: int):
    from pidyn.integrate import rk4

    p = problem._params(np.asarray(theta, float), False)
    with np.errstate(all="ignore"):
        Y, R = rk4(problem.system, p, problem.t[i:j + 1], problem.f[i:j + 1], np.asarray(y0, float)[None, :],
                   problem.substeps, t0=float(problem.t[i]))
    Y = np.nan_to_num(Y[:, 0], nan=0.0, posinf=0.0, neginf=0.0)
    return Y, R[:, 0]


def build_problem(system, record, settings: RefineSettings, t_start: float | None = None,
                  t_end: float | None = None) -> ShootingProblem:
    channels = record_channels(record, system.n_dof)
    bounds = segment_bounds(record.t, settings.segment_length, t_start, t_end)
    state0 = None if settings.free_initial_state else np.zeros(system.n_state)
    return ShootingProblem(system, record.t, record.f, channels, bounds, settings.substeps, fixed_state0=state0)


def _state_scale(problem: ShootingProblem, states: np.ndarray) -> np.ndarray:
    n = problem.system.n_dof
    ref = {(ch.kind, ch.dof): float(np.std(ch.data)) for ch in problem.channels}
    scale = np.std(states, axis=0)
    for d in range(n):
        scale[d] = max(scale[d], ref.get(("x", d), 0.0))
        scale[n + d] = max(scale[n + d], ref.get(("v", d), 0.0))
    floor = max(float(np.max(scale[:n])), 1e-12)
    return np.where(scale > 1e-9 * floor, scale, floor)


def refine(system, record, start: dict[str, dict[str, float]], settings: RefineSettings | None = None,
           network_states: np.ndarray | None = None, t_start: float | None = None,
           t_end: float | None = None, prefer: str = "pidynnet") -> RefineResult:
    """Refine the best of the ``start`` estimates (label -> parameter values) by multiple shooting.

    Every candidate is scored by a free simulation of the span from the same initial state;
    the best one starts the refinement. When ``prefer`` (PIDynNet) is not the best, the log
    says so. A candidate that still simulates better than the refined estimate is refined as
    well, and the lower cost wins.
    """
    settings = settings or RefineSettings()
    t_wall = time.perf_counter()
    problem = build_problem(system, record, settings, t_start, t_end)
    names = problem.names
    cands = {k: v for k, v in start.items() if v and all(n in v and np.isfinite(v[n]) for n in names)}
    if not cands:
        raise ValueError(f"refinement: no starting estimate has every parameter {names}")
    from pidyn.params import to_theta

    thetas = {k: to_theta(problem.specs, v) for k, v in cands.items()}
    first = prefer if prefer in thetas else next(iter(thetas))
    states0 = initial_states(problem, thetas[first], settings.states, network_states)
    problem.state_scale = _state_scale(problem, states0)
    y0 = states0[0]
    costs = {k: problem.free_run_cost(th, y0) for k, th in thetas.items()}
    order = sorted(costs, key=lambda k: costs[k])
    best = order[0]
    start_notes = []
    if prefer in costs and best != prefer:
        start_notes.append(f"PIDynNet's estimate simulates the record worse than {best}'s (cost {costs[prefer]:.4g} "
                           f"against {costs[best]:.4g}); the refinement started from {best}")
        log.warning(start_notes[-1])

    def run_from(label: str):
        st = states0 if label == first else initial_states(problem, thetas[label], settings.states, network_states)
        rep = solve(problem, problem.pack(cands[label], st), settings.penalty_tol, settings.max_nfev,
                    settings.gn_steps, settings.penalty_start)
        return rep

    rep = run_from(best)
    used = best
    for other in order[1:]:
        if costs[other] < rep.cost * (1 - 1e-6):
            log.warning("%s's estimate simulates better (%.4g) than the refined one (%.4g): refining it too",
                        other, costs[other], rep.cost)
            alt = run_from(other)
            if alt.cost < rep.cost:
                rep, used = alt, other
    u = rep.u
    converged = rep.converged
    if settings.reweight:
        r, _ = problem.residuals(u)
        set_noise(problem, estimate_noise(problem, r))
        u, _, converged = solve_constrained(problem, u, max_steps=settings.gn_steps, history=rep.history)
    r, J, c, C = problem.linearize(u)
    noise = estimate_noise(problem, r)
    cov, cond = covariance(problem, J, C)
    # the residuals are in units of the noise the weights assumed; rescale to the estimate
    scale2 = float(r @ r) / max(len(r) - (problem.n_theta + problem.ns), 1)
    cov = cov * scale2
    theta, states = problem.unpack(u)
    ints = intervals(problem.specs, theta, cov)
    corr = correlation(cov)
    notes = start_notes + bound_notes(problem.specs, theta) + identifiability_notes(names, ints, corr, cond)
    for n_ in notes[len(start_notes):]:
        log.warning("identifiability: %s", n_)
    return RefineResult(
        params=problem.values(theta), intervals=ints, correlation=corr.tolist(), names=names, noise_std=noise,
        notes=notes, start=used, start_costs=costs, initial_state=states[0].tolist(), cost=float(r @ r),
        max_defect=float(np.max(np.abs(c))) if c.size else 0.0, segments=problem.S, condition_number=cond,
        converged=bool(converged), seconds=time.perf_counter() - t_wall, state_source=settings.states,
        history=rep.history,
    )
