"""Weak-form sparse regression (SINDy, Brunton et al. 2016; weak form: Messenger and Bortz 2021).

The practitioner's equation-discovery baseline: the restoring force is a sparse combination
of a candidate library (polynomials in x and x' up to degree three, x'|x'|, sign x'), fitted
by sequentially thresholded least squares to the weak form of the equation of motion (no
derivative of noisy data). It reports the terms it selected; the system's parameters are
read off the terms they multiply (c: x', k or k1: x, k3: x^3). Not applicable to models
with unmeasured latent states (Bouc-Wen z): their force is not a function of x and x'.
"""

from __future__ import annotations

import time

import numpy as np

from pidyn.baselines.common import BaselineResult
from pidyn.data.sources import Record
from pidyn.signals import dominant_period
from pidyn.weak_form import WeakForm, smooth_signals

#: the library: name -> force per unit coefficient
LIBRARY = {
    "x": lambda x, v: x,
    "x'": lambda x, v: v,
    "x^2": lambda x, v: x**2,
    "x x'": lambda x, v: x * v,
    "x'^2": lambda x, v: v**2,
    "x^3": lambda x, v: x**3,
    "x^2 x'": lambda x, v: x**2 * v,
    "x x'^2": lambda x, v: x * v**2,
    "x'^3": lambda x, v: v**3,
    "x'|x'|": lambda x, v: v * np.abs(v),
    "sign x'": lambda x, v: np.tanh(v / (0.02 * np.std(v))),
}
#: which system parameter multiplies which library term
PARAM_TERMS = {"c": "x'", "k": "x", "k1": "x", "k3": "x^3", "k2": "x^2", "c2": "x'|x'|", "Fc": "sign x'"}


def stlsq(A: np.ndarray, y: np.ndarray, threshold: float, max_iter: int = 20) -> np.ndarray:
    """Sequentially thresholded least squares on columns scaled to unit norm.

    A term is dropped when its share of the fitted force (|coef| x column norm over the norm
    of y) falls below ``threshold``; the rest are refitted until nothing changes.
    """
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0] = 1.0
    An = A / norms
    yn = np.linalg.norm(y) or 1.0
    active = np.ones(A.shape[1], bool)
    coef = np.zeros(A.shape[1])
    for _ in range(max_iter):
        coef[:] = 0.0
        if active.any():
            coef[active] = np.linalg.lstsq(An[:, active], y, rcond=None)[0]
        keep = np.abs(coef) / yn >= threshold
        if np.array_equal(keep, active):
            break
        active = keep
    return coef / norms


def weak_sindy(record: Record, system, threshold: float = 0.01) -> BaselineResult:
    t0 = time.perf_counter()
    if system.n_latent:
        return BaselineResult("sindy", {}, 0.0, note="not applicable: unmeasured latent state")
    if getattr(system, "n_dof", 1) != 1:
        return BaselineResult("sindy", {}, 0.0, note="single-degree-of-freedom systems only")
    if record.n_inputs > 1:
        return BaselineResult(
            "sindy",
            {},
            0.0,
            note="not applicable: several inputs whose influence is unknown (the "
            "relative motion the library needs depends on it)",
        )
    t = record.t
    excitation = np.asarray(record.f, float)
    if record.x is not None and not np.isnan(record.x[:, 0]).any():
        x = record.x[:, 0]
        v_meas = None if record.v is None else record.v[:, 0]
    elif record.a is not None and not np.isnan(record.a[:, 0]).any():  # accelerometers: integrate, all alike
        from pidyn.baselines.data_start import fundamental
        from pidyn.signals import integrate

        peak = fundamental(record)
        if peak is None:
            return BaselineResult("sindy", {}, 0.0, note="not applicable: the record shows no resonance")
        corner = max(peak[0] / 5.0, 2.0 / float(t[-1] - t[0]))
        x, v_meas = (
            integrate(record.a[:, 0], record.dt, 2, corner),
            integrate(record.a[:, 0], record.dt, 1, corner),
        )
        excitation = integrate(excitation, record.dt, 0, corner)
    else:
        return BaselineResult(
            "sindy", {}, 0.0, note="not applicable: needs a displacement or acceleration channel"
        )
    period = dominant_period(t, x)
    xs, vs = smooth_signals(t, x, v_meas, period)
    weak = WeakForm.for_record(t, period)
    m = system.nominal_mass()
    forcing = -m * excitation if system.excitation == "ground" else excitation
    y = weak.project(forcing)[:, 0] - weak.inertia(x, m)
    names = list(LIBRARY)
    A = weak.project(np.stack([LIBRARY[n](xs, vs) for n in names], axis=1))
    coef = stlsq(A, y, threshold)
    selected = {n: float(c) for n, c in zip(names, coef) if c != 0.0}
    trainable = [s.name for s in system.param_specs() if s.trainable and s.name != "m"]
    params = {p: selected.get(PARAM_TERMS[p], 0.0) for p in trainable if p in PARAM_TERMS}
    extra = sorted(set(selected) - {PARAM_TERMS[p] for p in params})
    note = "selected: " + ", ".join(f"{n}={c:.4g}" for n, c in selected.items())
    if extra:
        note += f"; terms outside the model: {extra}"
    return BaselineResult("sindy", params, time.perf_counter() - t0, note=note)
