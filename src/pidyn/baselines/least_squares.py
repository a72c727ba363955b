"""Classical least-squares identification: equation error and output error.

Equation error (EE): differentiate the measurements to get x'' (and x' if not measured),
then solve the motion residual for the parameters it is linear in. Milliseconds; exact on
clean data, biased by noise through the differenced acceleration; not applicable when the
model has unmeasured latent states (Bouc-Wen z).

Output error (OE): simulate the model and fit the simulated channels to the measured ones
with scipy's trust-region least squares; the residuals are those of the refinement stage's
shooting problem with one segment from rest. The estimator a practitioner would try first.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from scipy.optimize import least_squares

from pidyn.baselines.common import BaselineResult, starting_point
from pidyn.baselines.registry import estimator, row
from pidyn.data.sources import Record
from pidyn.notes import note
from pidyn.refine.problem import ShootingProblem, record_channels, segment_bounds
from pidyn.systems.base import Kinematics
from pidyn.systems.lstsq import solve_linear_params


def equation_error(record: Record, system) -> BaselineResult:
    t0 = time.perf_counter()
    if system.n_latent:
        return BaselineResult(
            "equation_error", {}, 0.0, note=note("not_applicable", "not applicable: unmeasured latent state")
        )
    if record.x is None or np.isnan(record.x).any() or (record.v is not None and np.isnan(record.v).any()):
        # no displacement sensor: the accelerations (and the inputs) high-passed and integrated alike
        from pidyn.baselines.data_start import equation_error_integrated

        est = equation_error_integrated(record, system)
        if est is None:
            return BaselineResult(
                "equation_error",
                {},
                0.0,
                note=note("not_applicable", "not applicable: needs a sensor on every degree of freedom"),
            )
        return BaselineResult("equation_error", est.values, time.perf_counter() - t0, note=est.note)
    dt = record.dt
    x = record.x
    v = record.v if record.v is not None else np.gradient(x, dt, axis=0)
    a = record.a if record.a is not None else np.gradient(v, dt, axis=0)
    T = lambda arr: torch.tensor(np.array(arr, dtype=float), dtype=torch.float64)  # noqa: E731
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
    """Single shooting from rest over the whole record (the shooting problem with one segment
    and a fixed initial state), trust-region least squares, forward-difference Jacobian from
    one batched simulation of the parameter set and all its perturbations."""
    t0 = time.perf_counter()
    specs, fixed, th0 = starting_point(system, init)
    problem = ShootingProblem(
        system,
        record.t,
        record.f,
        record_channels(record, system.n_dof),
        segment_bounds(record.t, None),
        substeps,
        fixed_state0=np.zeros(system.n_state),
    )
    for ch in problem.channels:  # residuals relative to each channel's spread, as a practitioner scales them
        ch.sigma = max(float(np.std(ch.data)), 1e-300)
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = th.tobytes()
        if key not in cache:  # residuals and Jacobian come from the same batch: one simulation for both
            cache.clear()
            cache[key] = problem.residuals_and_fd_jacobian(th)
        return cache[key]

    sol = least_squares(
        lambda th: evaluate(th)[0],
        th0,
        jac=lambda th: evaluate(th)[1],
        method="trf",
        max_nfev=max_nfev,
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    est = problem.values(sol.x)
    return BaselineResult(
        "output_error", est, time.perf_counter() - t0, note=f"nfev={sol.nfev}, cost={sol.cost:.3g}"
    )


@estimator("equation_error", equation_error, "EE", parametric=True, order=1)
def _equation_error_row(record, system, settings: dict, noise: float) -> dict:
    return row(equation_error(record, system))


@estimator("output_error", output_error, "OE", parametric=True, order=3)
def _output_error_row(record, system, settings: dict, noise: float) -> dict:
    return row(output_error(record, system, **settings))
