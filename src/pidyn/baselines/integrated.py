"""Equation error on integrated signals: a linear model's parameters from accelerations alone.

Accelerations (and the inputs) are high-passed and integrated spectrally with one filter
(``pidyn.signals.integrate``), so a linear model holds exactly for the filtered signals, and
the parameters the motion residual is linear in are solved by least squares. With several
inputs the residual is bilinear in the influence coefficients and the rest (relative motion =
absolute minus the weighted supports'), solved by Gauss-Newton from equal shares. Milliseconds;
it applies when every degree of freedom carries a sensor and the model has no unmeasured
latent state. The equation-error baseline uses it on records without a displacement sensor, and
the data's start (``pidyn.starts``) tries it first.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import torch

from pidyn.params import in_range
from pidyn.signals import fundamental, integrate
from pidyn.systems.base import Kinematics
from pidyn.systems.lstsq import forward_jacobian, lstsq, solve_linear_params
from pidyn.systems.modal import damping_params, scaled_to
from pidyn.systems.sdof import feedthrough_name, influence_name, support_damping_name

log = logging.getLogger(__name__)


@dataclass
class IntegratedFit:
    """The parameters the equation error solved, and how the signals were prepared."""

    values: dict[str, float]
    note: str


def corner_of(record, fn: float) -> float:
    """The high-pass corner (Hz): a fifth of the fundamental, at least two cycles of the record."""
    return max(fn / 5.0, 2.0 / max(float(record.t[-1] - record.t[0]), 1e-9))


def equation_error_integrated(record, system) -> IntegratedFit | None:
    """Equation error on the high-passed integrated signals alone (None where it does not apply:
    floors without a sensor, an unmeasured latent state, no resonance, a fit out of range)."""
    peak = fundamental(record)
    if peak is None or not integrated_applies(record, system):
        return None
    return fit_integrated(record, system, corner_of(record, peak[0]), *peak)


def integrated_applies(record, system) -> bool:
    """Every degree of freedom carries a sensor, none is missing a sample, and the model has no
    unmeasured latent state and some parameters its motion residual is linear in."""
    if system.n_latent or not system.linear_params():
        return False
    sensors = record.sensors()
    floors = set().union(*[set(v) for v in sensors.values()]) if sensors else set()
    return floors == set(range(1, system.n_dof + 1)) and not any(
        np.isnan(getattr(record, k)[:, [j - 1 for j in v]]).any() for k, v in sensors.items()
    )


def fit_integrated(record, system, corner: float, fn: float, zeta: float) -> IntegratedFit | None:
    """Equation error on the record's signals high-passed at ``corner`` (Hz) and integrated alike;
    ``fn``, ``zeta``: the fundamental's frequency (Hz: how much of each end rings and is cut) and
    damping ratio (the dampers' values where the fit puts them out of range)."""
    dt = record.dt
    ch = _filtered_channels(record, corner)
    f = np.asarray(record.f, float)
    F = integrate(f, dt, 0, corner)
    edge = max(1, int(round(2.0 / fn / dt)))  # the filter's and the integration's ends ring
    keep = slice(edge, len(record.t) - edge)
    T = lambda a: torch.as_tensor(np.asarray(a, float)[keep], dtype=torch.float64)  # noqa: E731
    values = {s.name: torch.tensor(float(s.init), dtype=torch.float64) for s in system.param_specs()}
    names = list(system.linear_params())
    r_names = [
        fn(i) for fn in (influence_name, support_damping_name, feedthrough_name) for i in system.inputs
    ]
    t = T(record.t)
    if not r_names:
        k = Kinematics(t, T(ch["x"]), T(ch["v"]), T(ch["a"]))
        est = solve_linear_params(system, k, T(F), values, names)
    else:  # absolute signals; relative = absolute - the supports' motion weighted by r (bilinear)
        est = _bilinear_fit(system, values, names, r_names, record, ch, corner, T)
    specs = {s.name: s for s in system.param_specs()}
    bad = _out_of_range(est, specs)
    note = f"integrated signals high-passed at {corner:.3g} Hz, {edge} samples cut at each end"
    if bad and not r_names and set(bad) <= _damping_names(system):
        # dampers are the least determined (a sensor's timing shifts the phase that holds them):
        # fixed at the transmissibility's damping, stiffness-proportional, the rest solved again
        fixed = scaled_to(system, fn, zeta)
        held = {n: fixed[n] for n in _damping_names(system) if n in fixed and n in names}
        values.update({n: torch.tensor(v, dtype=torch.float64) for n, v in held.items()})
        est = {
            **solve_linear_params(
                system,
                Kinematics(t, T(ch["x"]), T(ch["v"]), T(ch["a"])),
                T(F),
                values,
                [n for n in names if n not in held],
            ),
            **held,
        }
        note += f"; dampers {sorted(held)} came out {bad}: held at the transmissibility's damping"
        bad = _out_of_range(est, specs)
    if bad:
        log.info("equation-error start outside the parameters' ranges: %s", bad)
        return None
    return IntegratedFit(est, note)


def _bilinear_fit(
    system, values: dict, names: list[str], r_names: list[str], record, ch: dict, corner: float, T
):
    """Several supports: the linear parameters and the supports' influence, feedthrough and
    damping together (the relative motion is the absolute minus the supports' motion weighted by
    their influence: bilinear), by Gauss-Newton from the linear fit at the config's influence."""
    t, f, dt = T(record.t), np.asarray(record.f, float), record.dt
    F, FV, FD = (integrate(f, dt, k, corner) for k in (0, 1, 2))
    Ft, FVt, FDt = T(F), T(FV), T(FD)
    xa, va, aa = T(ch["x"]), T(ch["v"]), T(ch["a"])

    def kin(p: dict) -> Kinematics:  # relative = absolute - what the sensor reads of the supports
        g = lambda q: system.acceleration_output(torch.zeros_like(xa), q, p)  # noqa: E731
        return Kinematics(t, xa - g(FDt), va - g(FVt), aa - g(Ft))

    est = solve_linear_params(system, kin(values), Ft, values, names)
    u = torch.tensor([est[n] for n in names] + [float(values[n]) for n in r_names], dtype=torch.float64)
    all_names = names + r_names

    def residual(q: torch.Tensor) -> torch.Tensor:
        p = dict(values)
        p.update({n: q[i] for i, n in enumerate(all_names)})
        return system.residual(kin(p), Ft, p)["motion"].reshape(-1)

    for _ in range(30):
        J = forward_jacobian(residual, u)
        step = lstsq(J, -residual(u))
        u = u + step
        if float(step.abs().max() / u.abs().clamp_min(1e-12).max()) < 1e-10:
            break
    est = {n: float(u[i]) for i, n in enumerate(all_names)}
    return est


def _filtered_channels(record, corner: float) -> dict[str, np.ndarray]:
    """x, v, a per degree of freedom (as the record holds them) high-passed alike, each from its
    own sensor where there is one, else integrated from a higher derivative, else differentiated
    from a lower one."""
    dt = record.dt
    have = {k: getattr(record, k) for k in ("x", "v", "a") if getattr(record, k) is not None}
    order = {"x": 0, "v": 1, "a": 2}
    out: dict[str, np.ndarray] = {}
    for kind in ("x", "v", "a"):
        if kind in have:
            out[kind] = integrate(have[kind], dt, 0, corner)
            continue
        above = [k for k in ("v", "a") if k in have and order[k] > order[kind]]
        if above:
            out[kind] = integrate(have[above[0]], dt, order[above[0]] - order[kind], corner)
        else:
            below = max((k for k in have if order[k] < order[kind]), key=lambda k: order[k])
            out[kind] = _differentiate(integrate(have[below], dt, 0, corner), dt, order[kind] - order[below])
    return out


def _differentiate(y: np.ndarray, dt: float, times: int) -> np.ndarray:
    n = y.shape[0]
    Y = np.fft.rfft(y, 2 * n, axis=0)
    w = 2j * np.pi * np.fft.rfftfreq(2 * n, dt)
    return np.fft.irfft(Y * (w**times).reshape((-1,) + (1,) * (y.ndim - 1)), 2 * n, axis=0)[:n]


def _out_of_range(est: dict[str, float], specs: dict) -> dict[str, float]:
    return {n: v for n, v in est.items() if not np.isfinite(v) or not in_range(specs[n], v)}


def _damping_names(system) -> set[str]:
    """The viscous dampers' parameters (a building's storeys, or a single degree of freedom's)."""
    if hasattr(system, "terms") and hasattr(system, "storeys"):
        return {t.damping_param for t in system.terms if t.damping_param}
    return set(damping_params(system))
