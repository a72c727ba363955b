"""The score test of adding a term to a model, shared by the places a cause can sit at (a
building's storeys, a deck's supports): how the measured channels move with the model's own
parameters (their span, profiled out), and how much of the misfit one linearised step along a
candidate's change of the channels removes."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pidyn.discrepancy.effects import EFFECTS
from pidyn.systems.places import storey_param


def profiled_basis(
    simulate: Callable[[list[dict[str, float]]], np.ndarray],
    system,
    values: dict[str, float],
    rows: int,
    scale: np.ndarray | None = None,
) -> np.ndarray:
    """An orthonormal basis (rows, k) of how the channels move with the model's trainable
    parameters, by central differences. ``simulate(sets)`` gives the channels of each parameter
    set, (P, rows); ``scale`` (rows,) divides the derivatives (noise units), where ``simulate``
    does not already."""
    names = [s.name for s in system.param_specs() if s.trainable and s.name in values]
    sets, steps = [], []
    for n in names:
        h = 1e-6 * max(abs(float(values[n])), 1e-12)
        sets += [{**values, n: values[n] + h}, {**values, n: values[n] - h}]
        steps.append(2 * h)
    if not sets:
        return np.zeros((rows, 0))
    sim = simulate(sets)
    jac = ((sim[0::2] - sim[1::2]) / np.array(steps)[:, None]).T
    if scale is not None:
        jac = jac / scale[:, None]
    jac = jac[:, np.all(np.isfinite(jac), axis=0)]
    q, r = np.linalg.qr(jac)
    keep = np.abs(np.diag(r)) > 1e-10 * max(np.abs(np.diag(r)).max(initial=0.0), 1e-300)
    return q[:, keep]


def linearised_chi2(
    d: np.ndarray, q: np.ndarray, r: np.ndarray, signed: bool
) -> tuple[float, np.ndarray] | None:
    """The misfit one step along a candidate's change ``d`` removes from the residual ``r`` (both
    in noise units, ``r`` with the basis ``q`` profiled out), and that direction with ``q``
    profiled out; a step of the wrong sign counts only for a ``signed`` effect. None where the
    candidate blew up or changes nothing the model's own parameters could not."""
    if not np.all(np.isfinite(d)):
        return None
    pd_ = d - q @ (q.T @ d)
    dd = float(pd_ @ pd_)
    if dd <= 0:
        return None
    step = float(r @ pd_) / dd
    chi2 = step * float(r @ pd_) if (step > 0 or signed) else 0.0
    return chi2, pd_


def terms_at_places(found: list[tuple[str, int, dict, dict]], start: dict[str, float]) -> dict[int, list]:
    """The force terms of found effects, ``(effect, place, params, ctx)``, by place (1-based), each
    reading its place's own spring and dashpot (``k<j>``, ``c<j>``); their starting values are
    written into ``start`` under the place's names (``kh2``)."""
    terms: dict[int, list] = {}
    for effect, place, params, ctx in found:
        term = EFFECTS[effect].term(params, {**ctx, "stiffness": f"k{place}", "damping": f"c{place}"})
        terms.setdefault(place, []).append(term)
        for s in term.specs():
            start[storey_param(s.name, place)] = float(s.init)
    return terms
