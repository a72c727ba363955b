"""Output-error training of a learned force: the network trained on what it is judged by.

PIDynNet trains a learned force f(x, x') pointwise, in the physics loss on its networks'
smoothed motion. That fits the fitting part's force and can still simulate it badly: a small
error of the force near the origin moves the period, and over many cycles of free simulation
the phase walks away (trilinear springs in the diagnosis benchmark: the extended model
simulated even the fitting part worse than the nominal one). Here the network's weights and
the model's physical parameters are trained further on the simulated response itself, in
segments with free starting states (multiple shooting without continuity constraints: each
segment's state is fitted with it), by L-BFGS through a torch RK4 on the system's own
``state_rate``. Its excitation quadrature is that of :func:`pidyn.integrate.rk4` (exact for an
excitation linear between samples), so the NumPy simulation that judges the model integrates
the force it was trained for.

Every measured channel (x, v, a, each floor of a building) enters the loss, each scaled by its
own variance over the fitting part, so an accelerometer record is fitted as well as a
displacement one.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import time
import warnings
from dataclasses import dataclass

import numpy as np
import torch
from scipy.signal import savgol_filter

from pidyn.data.sources import Record
from pidyn.params import ParamSpec, from_raw, to_raw
from pidyn.simulate import input_hold, simulate_states
from pidyn.systems.base import StructuralSystem
from pidyn.systems.terms import LearnedForce

log = logging.getLogger(__name__)

_CHANNELS = ("x", "v", "a")


@dataclass
class LearnedFit:
    """What the output-error training did: the new values (the network's weights are set in
    place), the segment loss before and after, and a sentence for the report."""

    values: dict[str, float]
    loss_before: float
    loss_after: float
    evaluations: int
    segments: int
    segment_seconds: float
    seconds: float

    @property
    def note(self) -> str:
        return (
            f"learned force trained on the simulated response ({self.segments} segments of "
            f"{self.segment_seconds:.3g} s, {self.evaluations} evaluations, {self.seconds:.1f} s): "
            f"loss {self.loss_before:.3g} -> {self.loss_after:.3g}"
        )


def _free_spec(spec: ParamSpec, value: float) -> ParamSpec:
    """The spec re-centred at ``value`` so that its raw coordinate is O(1) (L-BFGS's first step)."""
    if spec.transform == "box":
        return spec
    if spec.transform == "log":
        return dataclasses.replace(spec, init=max(value, 1e-300), scale=max(value, 1e-300))
    return dataclasses.replace(spec, init=value, scale=abs(value) or spec.scale)


def _step_forcing(f: np.ndarray, rows: np.ndarray, stride: int, dt: float) -> tuple[np.ndarray, ...]:
    """The forcing values one RK4 step over ``stride`` samples uses at its start, midpoint and
    end, so that the step integrates the excitation (linear between its samples) exactly: for
    y'' = f(t), RK4 advances y' by h/6 (F_a + 4 F_m + F_b) and y by h^2/6 (F_a + 2 F_m), and
    F_a, F_m are chosen to make those the exact integral and first moment. The samples at the
    ends and middle would make it Simpson's rule, wrong by the second difference, which is as
    large as a rough accelerogram itself. For one sample per step it gives F_a = f_a and F_m
    the linear midpoint, as :func:`pidyn.integrate.rk4` does."""
    h = stride * dt
    start = rows[:-1]
    m0 = np.zeros(start.shape)
    m1 = np.zeros(start.shape)
    for j in range(stride):  # sample interval j of the step: f = f_j + (f_j+1 - f_j) u / dt
        fj, fk = f[start + j], f[start + j + 1]
        H = h - j * dt
        m0 += dt * (fj + fk) / 2
        m1 += H * fj * dt + H * (fk - fj) * dt / 2 - fj * dt**2 / 2 - (fk - fj) * dt**2 / 3
    f_b = f[rows[1:]]
    f_m = (6 * m0 / h - f_b - 6 * m1 / h**2) / 2
    f_a = 6 * m1 / h**2 - 2 * f_m
    return f_a, f_m, f_b


def _learned_terms(system: StructuralSystem) -> list[LearnedForce]:
    """Every learned force of a model: its own terms, or its storeys' (unwrapped)."""
    terms = list(getattr(system, "terms", []))
    for storey in getattr(system, "storeys", []):
        terms += [getattr(t, "term", t) for t in storey]
    return [t for t in terms if isinstance(t, LearnedForce)]


def _starts(
    record: Record,
    system: StructuralSystem,
    values: dict[str, float],
    idx: np.ndarray,
    period: float,
    smoothed: tuple[np.ndarray, np.ndarray] | None,
) -> np.ndarray:
    """Initial states (B, n_state) of the segments starting at samples ``idx``: x and x' from
    ``smoothed`` ((N,) or (N, n_dof), the caller's smoothed motion), else from the measured
    displacement smoothed over a tenth of the period, else from the model's simulation; latent
    states from the model's simulation. They are trained with the rest; this is only where
    they start."""
    n = system.n_dof
    width = max(5, int(round(0.1 * period / record.dt)) | 1)
    measured = record.x is not None and bool(np.all(np.isfinite(record.x))) and width < len(record.t)
    y0 = np.zeros((len(idx), system.n_state))
    if system.n_latent or (smoothed is None and not measured):
        Y, _ = simulate_states(system, values, record.t, record.f, substeps=2, hold=input_hold(record))
        y0 = np.array(Y[idx, :])
    if smoothed is not None:
        y0[:, :n] = np.reshape(smoothed[0], (len(record.t), -1))[idx]
        y0[:, n : 2 * n] = np.reshape(smoothed[1], (len(record.t), -1))[idx]
    elif measured:
        y0[:, :n] = savgol_filter(record.x, width, 3, axis=0)[idx]
        y0[:, n : 2 * n] = savgol_filter(record.x, width, 3, deriv=1, delta=record.dt, axis=0)[idx]
    return np.where(np.isfinite(y0), y0, 0.0)


@dataclass
class _Grid:
    """The segments and the RK4 steps through them: sample ``rows`` (K, B) fitted per segment
    (every ``stride``-th sample from each start), and per step (S, B) its start time and the
    forcing at its start, middle and end; ``per_sample`` steps between fitted samples."""

    idx: np.ndarray
    rows: np.ndarray
    length: int
    h: float
    per_sample: int
    t_a: torch.Tensor
    f_a: torch.Tensor
    f_m: torch.Tensor
    f_b: torch.Tensor


def _grid(
    record: Record, span: tuple[int, int], period: float, periods_per_segment: float, substeps: int
) -> _Grid | None:
    """Segments of ``periods_per_segment`` natural periods covering the samples ``span`` (they
    overlap where the length does not divide it). One RK4 step over 2 m samples where the period
    allows 40 steps of that length (the forcing moment-matched, see _step_forcing), else
    ``substeps`` steps per sample, the excitation linear between samples as in pidyn.integrate.rk4."""
    i0, i1 = span
    half = max(0, int(period / (80.0 * record.dt)))
    stride = 2 * half if half else 1
    length = stride * max(8 // stride + 1, int(round(periods_per_segment * period / (record.dt * stride))))
    if i1 - i0 < length:
        return None
    idx = np.unique(np.round(np.linspace(i0, i1 - length, max(1, -(-(i1 - i0) // length)))).astype(int))
    rows = idx[None, :] + np.arange(0, length + 1, stride)[:, None]
    t = record.t
    if stride > 1:
        per_sample, h = 1, stride * record.dt
        f_a, f_m, f_b = _step_forcing(record.f, rows, stride, record.dt)
        t_a = t[rows[:-1]]
    else:
        per_sample, h = substeps, record.dt / substeps
        frac = np.arange(substeps)[:, None, None] / substeps  # (substeps, 1, 1)
        f0, f1 = record.f[rows[:-1]][None], record.f[rows[1:]][None]
        df = (f1 - f0) / substeps

        def steps(v: np.ndarray) -> np.ndarray:  # (substeps, K-1, B) -> (S, B), in time order
            return v.transpose(1, 0, 2).reshape(-1, len(idx))

        f_a, f_m, f_b = (
            steps(f0 + frac * (f1 - f0)),
            steps(f0 + frac * (f1 - f0) + 0.5 * df),
            steps(f0 + frac * (f1 - f0) + df),
        )
        t_a = steps(t[rows[:-1]][None] + frac * record.dt)
    as_t = lambda v: torch.tensor(v, dtype=torch.float64)  # noqa: E731
    return _Grid(idx, rows, length, h, per_sample, as_t(t_a), as_t(f_a), as_t(f_m), as_t(f_b))


def _targets(record: Record, rows: np.ndarray, span: tuple[int, int]) -> list[tuple]:
    """(kind, values, mask, variance) of every measured channel at ``rows``: (K, B, n_dof), NaN
    (mask 0) where a floor has no such sensor, each floor scaled by its variance over ``span``."""
    out = []
    for kind in _CHANNELS:
        arr = getattr(record, kind)
        if arr is None:
            continue
        seg = arr[rows]
        with warnings.catch_warnings():  # a floor without this sensor: NaN, scaled by 1 below
            warnings.simplefilter("ignore", RuntimeWarning)
            var = np.nanvar(arr[span[0] : span[1] + 1], axis=0)
        var = np.where(np.isfinite(var) & (var > 0), var, 1.0)
        out.append(
            (
                kind,
                torch.tensor(np.nan_to_num(seg), dtype=torch.float64),
                torch.tensor(np.isfinite(seg), dtype=torch.float64),
                torch.tensor(var, dtype=torch.float64),
            )
        )
    return out


def _simulate(rate, y: torch.Tensor, p: dict, g: _Grid) -> torch.Tensor:
    """The states (K, B, n_state) at the fitted samples, by RK4 from ``y`` (B, n_state)."""
    h = g.h
    states = [y]
    for j in range(g.f_a.shape[0]):
        ta = g.t_a[j]
        k1 = rate(ta, y, p, g.f_a[j])
        k2 = rate(ta + 0.5 * h, y + (0.5 * h) * k1, p, g.f_m[j])
        k3 = rate(ta + 0.5 * h, y + (0.5 * h) * k2, p, g.f_m[j])
        k4 = rate(ta + h, y + h * k3, p, g.f_b[j])
        y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        if (j + 1) % g.per_sample == 0:
            states.append(y)
    return torch.stack(states)


def _lbfgs_best(loss_fn, params: list[torch.Tensor], keep, max_evaluations: int) -> tuple[float, int, dict]:
    """L-BFGS on ``loss_fn``; the loss at the start, the evaluations made, and ``keep()`` at the
    lowest loss seen (with ``loss``; empty if none was finite)."""
    opt = torch.optim.LBFGS(
        params,
        lr=1.0,
        max_iter=max_evaluations,
        max_eval=max_evaluations,
        line_search_fn="strong_wolfe",
        tolerance_grad=1e-10,
        tolerance_change=1e-12,
        history_size=20,
    )
    evaluations, best = 0, {}

    def closure() -> torch.Tensor:
        nonlocal evaluations
        opt.zero_grad()
        loss = loss_fn()
        evaluations += 1
        # a step into a blow-up: a large loss, no slope; the line search backs off
        if not torch.isfinite(loss):
            return torch.tensor(1e30, dtype=torch.float64)
        loss.backward()
        value = float(loss.detach())
        if not best or value < best["loss"]:
            best.update(keep(), loss=value)
        return loss

    with torch.no_grad():
        before = float(loss_fn())
    opt.step(closure)
    return before, evaluations, best


def fit_learned_force(
    system: StructuralSystem,
    values: dict[str, float],
    record: Record,
    span: tuple[float, float],
    period: float,
    smoothed: tuple[np.ndarray, np.ndarray] | None = None,
    substeps: int = 2,
    periods_per_segment: float = 3.0,
    max_evaluations: int = 60,
) -> LearnedFit | None:
    """Train ``system``'s learned force(s) and its trainable physical parameters on the
    simulated response over ``span`` (s). The weights are set in place only when the segment
    loss goes down; returns None when the system holds no learned force or the span is too
    short for one segment."""
    terms = _learned_terms(system)
    samples = (
        int(np.searchsorted(record.t, span[0])),
        int(np.searchsorted(record.t, span[1], side="right")) - 1,
    )
    g = None if not terms else _grid(record, samples, period, periods_per_segment, substeps)
    if g is None:
        return None
    start, dtype = time.perf_counter(), torch.float64
    free, fspecs, raw = _free_parameters(system, values, dtype)
    y0 = _starts(record, system, values, g.idx, period, smoothed)
    y_scale = torch.tensor(np.maximum(np.abs(y0).max(0), 1e-12), dtype=dtype)
    y_raw = torch.tensor(y0, dtype=dtype).div(y_scale).requires_grad_(True)
    targets = _targets(record, g.rows, samples)
    f_rows, t_rows = (torch.tensor(v[g.rows], dtype=dtype) for v in (record.f, record.t))
    fixed = {name: float(v) for name, v in values.items() if name not in free}
    originals, copies = [t.net for t in terms], [copy.deepcopy(t.net).to(dtype) for t in terms]

    def loss_fn() -> torch.Tensor:
        p = {**fixed, **{name: from_raw(fspecs[name], raw[i]) for i, name in enumerate(free)}}
        Y = _simulate(system.state_rate, y_raw * y_scale, p, g)  # torch states in, torch rates out
        return _segment_loss(system, Y, p, targets, t_rows, f_rows)

    before, evaluations, best = _train_copies(terms, copies, [raw, y_raw], loss_fn, max_evaluations)
    after = best.get("loss", before)
    out_values = _keep_best(values, free, fspecs, originals, best) if after < before else dict(values)
    result = LearnedFit(
        out_values,
        before,
        min(after, before),
        evaluations,
        len(g.idx),
        g.length * record.dt,
        time.perf_counter() - start,
    )
    log.info("%s", result.note)
    return result


def _train_copies(terms: list, copies: list, tensors: list[torch.Tensor], loss_fn, max_evaluations: int):
    """L-BFGS on ``tensors`` and the copies of the terms' networks (set in the terms while it runs,
    the originals put back after): (loss before, evaluations, the best evaluation's state)."""
    originals = [t.net for t in terms]
    raw = tensors[0]

    def keep() -> dict:
        return {"raw": raw.detach().clone(), "nets": [copy.deepcopy(c.state_dict()) for c in copies]}

    try:
        for t, c in zip(terms, copies):
            t.net = c
        params = list(tensors) + [w for c in copies for w in c.parameters()]
        return _lbfgs_best(loss_fn, params, keep, max_evaluations)
    finally:
        for t, o in zip(terms, originals):
            t.net = o


def _free_parameters(system, values: dict[str, float], dtype) -> tuple[list[str], dict, torch.Tensor]:
    """The trainable parameters with a value, their specs for the segment fit and their raw
    (unconstrained) values as one tensor to train."""
    specs = {s.name: s for s in system.param_specs()}
    free = [name for name, s in specs.items() if s.trainable and name in values]
    fspecs = {name: _free_spec(specs[name], float(values[name])) for name in free}
    raw = torch.tensor(
        [to_raw(fspecs[name], float(values[name])) for name in free], dtype=dtype, requires_grad=True
    )
    return free, fspecs, raw


def _segment_loss(system, Y: torch.Tensor, p: dict, targets: list, t_rows, f_rows) -> torch.Tensor:
    """The segments' simulated response against the measured channels: each channel's mean
    squared error over its variance, summed."""
    nd = system.n_dof
    sim = {"x": Y[..., :nd], "v": Y[..., nd : 2 * nd]}
    if any(kind == "a" for kind, *_ in targets):
        sim["a"] = system.state_rate(t_rows, Y, p, f_rows)[..., nd : 2 * nd]
    total = torch.zeros((), dtype=Y.dtype)
    for kind, target, mask, var in targets:
        total = total + (((sim[kind] - target) ** 2) * mask / var).sum() / mask.sum().clamp_min(1.0)
    return total


def _keep_best(values: dict, free: list[str], fspecs: dict, originals: list, best: dict) -> dict[str, float]:
    """The best evaluation's parameters as values and its weights set in the terms' networks."""
    out_values = dict(values)
    with torch.no_grad():
        for i, name in enumerate(free):
            out_values[name] = float(from_raw(fspecs[name], best["raw"][i]))
        for o, state in zip(originals, best["nets"]):
            for w, (_, trained) in zip(o.parameters(), state.items()):
                w.copy_(trained.to(w.dtype))
    return out_values


__all__ = ["LearnedFit", "fit_learned_force"]
