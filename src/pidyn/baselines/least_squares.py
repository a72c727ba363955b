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

from pidyn.baselines.common import BaselineResult
from pidyn.baselines.integrated import equation_error_integrated
from pidyn.baselines.registry import estimator, row
from pidyn.data.sources import Record
from pidyn.notes import note
from pidyn.refine.output_error import fit_output_error
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
    """Single shooting from rest over the whole record (``pidyn.refine.output_error``), as the
    classical baseline."""
    fit = fit_output_error(record, system, init, substeps, max_nfev)
    return BaselineResult("output_error", fit.params, fit.seconds, note=fit.note)


@estimator("equation_error", equation_error, "EE", parametric=True, order=1)
def _equation_error_row(record, system, settings: dict, noise: float) -> dict:
    return row(equation_error(record, system))


@estimator("output_error", output_error, "OE", parametric=True, order=3)
def _output_error_row(record, system, settings: dict, noise: float) -> dict:
    return row(output_error(record, system, **settings))
