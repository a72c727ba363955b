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
from pidyn.baselines.registry import estimator, row
from pidyn.data.sources import Record
from pidyn.notes import note
from pidyn.signals import dominant_period, fundamental, integrate
from pidyn.systems.terms import (
    CoulombFriction,
    CubicStiffness,
    ForceTerm,
    LinearStiffness,
    Monomial,
    QuadraticDamping,
    QuadraticStiffness,
    ViscousDamping,
)
from pidyn.weak_form import WeakForm, smooth_signals


def library(v: np.ndarray) -> list[ForceTerm]:
    """The candidate terms, in the library's order: each gives its column by its own force
    (``ForceTerm.columns``) and its name by its ``symbol``. The smoothed sign is 2 % of the
    velocity's standard deviation wide."""
    return [
        LinearStiffness(param="k"),
        ViscousDamping(),
        QuadraticStiffness(),
        Monomial(1, 1),
        Monomial(0, 2),
        CubicStiffness(signed=True),
        Monomial(2, 1),
        Monomial(1, 2),
        Monomial(0, 3),
        QuadraticDamping(),
        CoulombFriction(eps=max(0.02 * float(np.std(v)), 1e-300)),
    ]


def param_terms(system) -> dict[str, str]:
    """Which library term each of the system's parameters multiplies: its own term's symbol
    (c: x', k or k1: x, k3: x^3)."""
    return {name: term.symbol for term in getattr(system, "terms", []) if term.symbol for name in term.linear}


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


def _not_applicable(record: Record, system) -> str | None:
    """Why the library cannot describe this system on this record, or None."""
    if system.n_latent:
        return "not applicable: unmeasured latent state"
    if getattr(system, "n_dof", 1) != 1:
        return "single-degree-of-freedom systems only"
    if record.n_inputs > 1:
        return (
            "not applicable: several inputs whose influence is unknown (the "
            "relative motion the library needs depends on it)"
        )
    return None


def _motion(record: Record) -> tuple | str:
    """(t, x, measured x' or None, excitation): the measured displacement, or the accelerations
    integrated (high-passed at a fifth of the resonance, the excitation filtered alike); why not
    when the record has neither or shows no resonance."""
    t = record.t
    excitation = np.asarray(record.f, float)
    if record.x is not None and not np.isnan(record.x[:, 0]).any():
        return t, record.x[:, 0], None if record.v is None else record.v[:, 0], excitation
    if record.a is None or np.isnan(record.a[:, 0]).any():
        return "not applicable: needs a displacement or acceleration channel"

    peak = fundamental(record)
    if peak is None:
        return "not applicable: the record shows no resonance"
    corner = max(peak[0] / 5.0, 2.0 / float(t[-1] - t[0]))
    x, v_meas = (
        integrate(record.a[:, 0], record.dt, 2, corner),
        integrate(record.a[:, 0], record.dt, 1, corner),
    )
    return t, x, v_meas, integrate(excitation, record.dt, 0, corner)


def weak_sindy(record: Record, system, threshold: float = 0.01) -> BaselineResult:
    t0 = time.perf_counter()
    why = _not_applicable(record, system)
    signals = why or _motion(record)
    if isinstance(signals, str):
        return BaselineResult("sindy", {}, 0.0, note=note("not_applicable", signals))
    t, x, v_meas, excitation = signals
    period = dominant_period(t, x)
    xs, vs = smooth_signals(t, x, v_meas, period)
    weak = WeakForm.for_record(t, period)
    m = system.nominal_mass()
    forcing = -m * excitation if system.excitation == "ground" else excitation
    y = weak.project(forcing)[:, 0] - weak.inertia(x, m)
    terms = library(vs)
    names = [term.symbol for term in terms]
    A = weak.project(np.stack([term.columns(t, xs, vs, None, {})[term.linear[0]] for term in terms], axis=1))
    coef = stlsq(A, y, threshold)
    selected = {n: float(c) for n, c in zip(names, coef) if c != 0.0}
    trainable = [s.name for s in system.param_specs() if s.trainable and s.name != "m"]
    own = param_terms(system)
    params = {p: selected.get(own[p], 0.0) for p in trainable if p in own}
    extra = sorted(set(selected) - {own[p] for p in params})
    text = "selected: " + ", ".join(f"{n}={c:.4g}" for n, c in selected.items())
    if extra:
        text += f"; terms outside the model: {extra}"
    return BaselineResult("sindy", params, time.perf_counter() - t0, note=text)


@estimator("sindy", weak_sindy, "SINDy", parametric=True, order=2)
def _sindy_row(record, system, settings: dict, noise: float) -> dict:
    return row(weak_sindy(record, system, **settings))
