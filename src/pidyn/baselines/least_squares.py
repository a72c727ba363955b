"""Classical least-squares identification: equation error and output error.

Equation error (EE): differentiate the measurements to get x'' (and x' if not measured),
then solve the motion residual for the parameters it is linear in. Milliseconds; exact on
clean data, biased by noise through the differenced acceleration; not applicable when the
model has unmeasured latent states (Bouc-Wen z).

Output error (OE): simulate the model and fit the simulated x (and x') to the measured
ones with scipy's trust-region least squares; the Jacobian comes from one batched
simulation of all perturbed parameter sets. The estimator a practitioner would try first.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from scipy.optimize import least_squares

from pidyn.baselines.common import BaselineResult, from_theta, starting_point
from pidyn.baselines.fastsim import simulate_batch
from pidyn.data.sources import Record
from pidyn.systems.base import Kinematics
from pidyn.systems.lstsq import solve_linear_params


def equation_error(record: Record, system) -> BaselineResult:
    t0 = time.perf_counter()
    if system.n_latent:
        return BaselineResult("equation_error", {}, 0.0, note="not applicable: unmeasured latent state")
    dt = record.dt
    x = record.x
    v = record.v if record.v is not None else np.gradient(x, dt, axis=0)
    a = record.a if record.a is not None else np.gradient(v, dt, axis=0)
    T = lambda arr: torch.as_tensor(np.asarray(arr, float), dtype=torch.float64)  # noqa: E731
    k = Kinematics(T(record.t), T(x), T(v), T(a))
    vals = {s.name: torch.tensor(float(s.init), dtype=torch.float64) for s in system.param_specs()}
    names = system.linear_params()
    est = solve_linear_params(system, k, T(record.f), vals, names)
    return BaselineResult("equation_error", est, time.perf_counter() - t0)


def output_error(
    record: Record,
    system,
    init: dict[str, float] | None = None,
    substeps: int = 4,
    max_nfev: int = 60,
) -> BaselineResult:
    t0 = time.perf_counter()
    specs, fixed, th0 = starting_point(system, init)
    chans = [("x", record.x[:, 0])] + ([("v", record.v[:, 0])] if record.v is not None else [])
    scale = {c: max(float(np.std(y)), 1e-300) for c, y in chans}
    h = 1e-6

    def sims(thetas: np.ndarray) -> dict[str, np.ndarray]:
        p = from_theta(specs, thetas)
        p.update({k: np.full(thetas.shape[1], v) for k, v in fixed.items()})
        return simulate_batch(system, p, record.t, record.f, substeps=substeps)

    def resid_from(out: dict[str, np.ndarray], j: int) -> np.ndarray:
        return np.concatenate([(out[c][:, j] - y) / scale[c] for c, y in chans])

    cache: dict[bytes, np.ndarray] = {}

    def fun(th: np.ndarray) -> np.ndarray:
        key = th.tobytes()
        if key not in cache:
            out = sims(th[:, None])
            r = resid_from(out, 0)
            cache[key] = np.nan_to_num(r, nan=1e6, posinf=1e6, neginf=-1e6)
        return cache[key]

    def jac(th: np.ndarray) -> np.ndarray:
        n = len(th)
        thetas = np.repeat(th[:, None], n + 1, axis=1)
        thetas[np.arange(n), np.arange(1, n + 1)] += h
        out = sims(thetas)
        base = resid_from(out, 0)
        return np.stack([(resid_from(out, j + 1) - base) / h for j in range(n)], axis=1)

    sol = least_squares(fun, th0, jac=jac, method="trf", max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    est = {k: float(v) for k, v in from_theta(specs, sol.x).items()}
    return BaselineResult("output_error", est, time.perf_counter() - t0, note=f"nfev={sol.nfev}, cost={sol.cost:.3g}")
