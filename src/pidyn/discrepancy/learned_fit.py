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
from dataclasses import dataclass

import numpy as np
import torch
from scipy.signal import savgol_filter

from pidyn.data.sources import Record
from pidyn.params import ParamSpec, from_raw, to_raw
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
        return (f"learned force trained on the simulated response ({self.segments} segments of "
                f"{self.segment_seconds:.3g} s, {self.evaluations} evaluations, {self.seconds:.1f} s): "
                f"loss {self.loss_before:.3g} -> {self.loss_after:.3g}")


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


def _starts(record: Record, system: StructuralSystem, values: dict[str, float], idx: np.ndarray, period: float,
            smoothed: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Initial states (B, n_state) of the segments starting at samples ``idx``: x and x' from
    ``smoothed`` ((N,) or (N, n_dof), the caller's smoothed motion), else from the measured
    displacement smoothed over a tenth of the period, else from the model's simulation; latent
    states from the model's simulation. They are trained with the rest; this is only where
    they start."""
    from pidyn.integrate import rk4

    n = system.n_dof
    width = max(5, int(round(0.1 * period / record.dt)) | 1)
    measured = record.x is not None and bool(np.all(np.isfinite(record.x))) and width < len(record.t)
    y0 = np.zeros((len(idx), system.n_state))
    if system.n_latent or (smoothed is None and not measured):
        with np.errstate(all="ignore"):
            Y, _ = rk4(system, dict(values), record.t, record.f, np.zeros((1, system.n_state)), substeps=2)
        y0 = np.array(Y[idx, 0, :])
    if smoothed is not None:
        y0[:, :n] = np.reshape(smoothed[0], (len(record.t), -1))[idx]
        y0[:, n:2 * n] = np.reshape(smoothed[1], (len(record.t), -1))[idx]
    elif measured:
        y0[:, :n] = savgol_filter(record.x, width, 3, axis=0)[idx]
        y0[:, n:2 * n] = savgol_filter(record.x, width, 3, deriv=1, delta=record.dt, axis=0)[idx]
    return np.where(np.isfinite(y0), y0, 0.0)


def fit_learned_force(system: StructuralSystem, values: dict[str, float], record: Record, span: tuple[float, float],
                      period: float, smoothed: tuple[np.ndarray, np.ndarray] | None = None, substeps: int = 2,
                      periods_per_segment: float = 3.0, max_evaluations: int = 60) -> LearnedFit | None:
    """Train ``system``'s learned force(s) and its trainable physical parameters on the
    simulated response over ``span`` (s). The weights are set in place only when the segment
    loss goes down; returns None when the system holds no learned force or the span is too
    short for one segment."""
    terms = _learned_terms(system)
    if not terms:
        return None
    nd = system.n_dof
    t_all = record.t
    i0, i1 = int(np.searchsorted(t_all, span[0])), int(np.searchsorted(t_all, span[1], side="right")) - 1
    # one RK4 step over 2 m samples where the period allows 40 steps of that length (the forcing
    # moment-matched, see _step_forcing), else ``substeps`` steps per sample, the excitation linear
    # between samples as in pidyn.integrate.rk4
    half = max(0, int(period / (80.0 * record.dt)))
    stride = 2 * half if half else 1
    L = stride * max(8 // stride + 1, int(round(periods_per_segment * period / (record.dt * stride))))
    if i1 - i0 < L:
        return None
    n_seg = max(1, -(-(i1 - i0) // L))  # cover the span, the segments overlapping where L does not divide it
    idx = np.unique(np.round(np.linspace(i0, i1 - L, n_seg)).astype(int))
    start = time.perf_counter()
    dtype = torch.float64
    specs = {s.name: s for s in system.param_specs()}
    free = [n for n, s in specs.items() if s.trainable and n in values]
    fspecs = {n: _free_spec(specs[n], float(values[n])) for n in free}
    raw = torch.tensor([to_raw(fspecs[n], float(values[n])) for n in free], dtype=dtype, requires_grad=True)

    y0_np = _starts(record, system, values, idx, period, smoothed)
    y_scale = np.maximum(np.abs(y0_np).max(0), 1e-12)
    y_raw = torch.tensor(y0_np / y_scale, dtype=dtype, requires_grad=True)
    y_scale_t = torch.tensor(y_scale, dtype=dtype)

    rows = idx[None, :] + np.arange(0, L + 1, stride)[:, None]  # (L / stride + 1, B) fitted samples per segment
    targets = []
    for kind in _CHANNELS:
        arr = getattr(record, kind)
        if arr is None:
            continue
        seg = arr[rows]  # (L / stride + 1, B, n_dof), NaN where a floor has no such sensor
        var = np.nanvar(arr[i0:i1 + 1], axis=0)  # each floor's channel scaled by its own variance
        var = np.where(np.isfinite(var) & (var > 0), var, 1.0)
        targets.append((kind, torch.tensor(np.nan_to_num(seg), dtype=dtype),
                        torch.tensor(np.isfinite(seg), dtype=dtype), torch.tensor(var, dtype=dtype)))
    if stride > 1:
        per_sample, h = 1, stride * record.dt
        f_a, f_m, f_b = _step_forcing(record.f, rows, stride, record.dt)
        t_a = t_all[rows[:-1]]
    else:
        per_sample, h = substeps, record.dt / substeps
        frac = np.arange(substeps)[:, None, None] / substeps  # (substeps, 1, 1)
        f0, f1 = record.f[rows[:-1]][None], record.f[rows[1:]][None]
        df = (f1 - f0) / substeps
        f_a = (f0 + frac * (f1 - f0)).transpose(1, 0, 2).reshape(-1, len(idx))
        f_m = (f0 + frac * (f1 - f0) + 0.5 * df).transpose(1, 0, 2).reshape(-1, len(idx))
        f_b = (f0 + frac * (f1 - f0) + df).transpose(1, 0, 2).reshape(-1, len(idx))
        t_a = (t_all[rows[:-1]][None] + frac * record.dt).transpose(1, 0, 2).reshape(-1, len(idx))
    f_a, f_m, f_b, t_a = (torch.tensor(v, dtype=dtype) for v in (f_a, f_m, f_b, t_a))
    f_rows = torch.tensor(record.f[rows], dtype=dtype)
    t_rows = torch.tensor(t_all[rows], dtype=dtype)
    want_a = any(k == "a" for k, *_ in targets)

    originals = [t.net for t in terms]
    copies = [copy.deepcopy(t.net).to(dtype) for t in terms]
    rate = system.state_rate  # torch states in, torch rates out
    fixed = {n: float(v) for n, v in values.items() if n not in free}

    def loss_fn() -> torch.Tensor:
        p = {**fixed, **{n: from_raw(fspecs[n], raw[i]) for i, n in enumerate(free)}}
        y = y_raw * y_scale_t
        states = [y]
        for j in range(f_a.shape[0]):
            ta = t_a[j]
            k1 = rate(ta, y, p, f_a[j])
            k2 = rate(ta + 0.5 * h, y + (0.5 * h) * k1, p, f_m[j])
            k3 = rate(ta + 0.5 * h, y + (0.5 * h) * k2, p, f_m[j])
            k4 = rate(ta + h, y + h * k3, p, f_b[j])
            y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            if (j + 1) % per_sample == 0:
                states.append(y)
        Y = torch.stack(states)  # (L / stride + 1, B, n_state)
        sim = {"x": Y[..., :nd], "v": Y[..., nd:2 * nd]}
        if want_a:
            sim["a"] = rate(t_rows, Y, p, f_rows)[..., nd:2 * nd]
        total = torch.zeros((), dtype=dtype)
        for kind, target, mask, var in targets:
            total = total + (((sim[kind] - target) ** 2) * mask / var).sum() / mask.sum().clamp_min(1.0)
        return total

    params = [raw, y_raw] + [w for c in copies for w in c.parameters()]
    opt = torch.optim.LBFGS(params, lr=1.0, max_iter=max_evaluations, max_eval=max_evaluations,
                            line_search_fn="strong_wolfe", tolerance_grad=1e-10, tolerance_change=1e-12,
                            history_size=20)
    evaluations = 0
    best: dict = {}

    def closure() -> torch.Tensor:
        nonlocal evaluations
        opt.zero_grad()
        loss = loss_fn()
        evaluations += 1
        if not torch.isfinite(loss):  # a step into a blow-up: a large loss, no slope; the line search backs off
            return torch.tensor(1e30, dtype=dtype)
        loss.backward()
        value = float(loss.detach())
        if not best or value < best["loss"]:
            best.update(loss=value, raw=raw.detach().clone(),
                        nets=[copy.deepcopy(c.state_dict()) for c in copies])
        return loss

    try:
        for t, c in zip(terms, copies):
            t.net = c
        with torch.no_grad():
            before = float(loss_fn())
        opt.step(closure)
    finally:
        for t, o in zip(terms, originals):
            t.net = o
    after = best.get("loss", before)
    out_values = dict(values)
    if after < before:
        with torch.no_grad():
            for i, name in enumerate(free):
                out_values[name] = float(from_raw(fspecs[name], best["raw"][i]))
            for o, state in zip(originals, best["nets"]):
                for w, (_, trained) in zip(o.parameters(), state.items()):
                    w.copy_(trained.to(w.dtype))
    result = LearnedFit(out_values, before, min(after, before), evaluations, len(idx), L * record.dt,
                        time.perf_counter() - start)
    log.info("%s", result.note)
    return result


__all__ = ["LearnedFit", "fit_learned_force"]
