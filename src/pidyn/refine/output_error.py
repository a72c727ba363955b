"""Output error: the shooting problem with one segment and the initial state held at rest.

Single shooting from rest over the whole record, trust-region least squares, forward-difference
Jacobian from one batched simulation of the parameter set and all its perturbations. The
classical baseline (``pidyn.baselines.least_squares.output_error``) and the diagnosis's
confirmation of an effect (``pidyn.discrepancy.confirm``) both run it."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pidyn.compiled.kernel import tapes_kept
from pidyn.params import to_theta, trainable_specs
from pidyn.refine.problem import ShootingProblem

log = logging.getLogger(__name__)

#: seconds between the progress lines of a long fit
PROGRESS_EVERY_S = 30.0


@dataclass
class OutputErrorFit:
    """The parameters that simulate the record best from rest, and what the solver did."""

    params: dict[str, float]
    seconds: float
    nfev: int
    cost: float

    @property
    def note(self) -> str:
        return f"nfev={self.nfev}, cost={self.cost:.3g}"


@tapes_kept()  # one system, hundreds of simulations: its tape recorded once
def fit_output_error(
    record,
    system,
    init: dict[str, float] | None = None,
    substeps: int = 4,
    max_nfev: int = 60,
    tol: float = 1e-12,
    weights: np.ndarray | None = None,
) -> OutputErrorFit:
    """The trainable parameters (from their specs' starts, overridden by ``init``) fitted to the
    record's channels simulated from rest, each channel's residual relative to its spread.
    ``tol``: stop when a step that the local model predicted well lowers the cost by less than
    this share, or when the trust region has shrunk below this share of the parameters (the
    default runs the whole budget; a model choice needs far less, see
    ``DiagnosisSettings.polish_tol``). ``weights`` (N,): every channel's residual at each sample
    times it (``pidyn.discrepancy.heteroscedastic``); the cost is then the weighted one."""
    t0 = time.perf_counter()
    problem, th0 = output_error_problem(record, system, init, substeps)
    if weights is not None:
        _weigh(problem, np.asarray(weights, float))
    fun, jac = problem.fd_fun_and_jac()
    sol = least_squares(
        _with_progress(fun, system, t0),
        th0,
        jac=jac,
        method="trf",
        max_nfev=max_nfev,
        xtol=tol,
        ftol=tol,
        gtol=1e-12,
    )
    return OutputErrorFit(problem.values(sol.x), time.perf_counter() - t0, int(sol.nfev), float(sol.cost))


def _weigh(problem: ShootingProblem, weights: np.ndarray) -> None:
    """Each channel's residual at sample i times ``weights[i]``, on top of the record's own weight
    where several records are joined (``Channel.weight``: one weighting, read by every residual)."""
    n = len(problem.t)
    if len(weights) != n:
        raise ValueError(f"output error: {len(weights)} weights for a record of {n} samples")
    for ch in problem.channels:
        ch.weight = weights if ch.weight is None else ch.weight * weights


def _with_progress(fun, system, t0: float):
    """``fun`` that says, every ``PROGRESS_EVERY_S`` seconds, how far a long fit has come (a
    model with a learned force can take minutes on a long record)."""
    state = {"n": 0, "next": t0 + PROGRESS_EVERY_S}

    def wrapped(theta: np.ndarray) -> np.ndarray:
        r = fun(theta)
        state["n"] += 1
        now = time.perf_counter()
        if now >= state["next"]:
            state["next"] = now + PROGRESS_EVERY_S
            log.info(
                "output error of %s: %d evaluations, cost %.4g, %.0f s",
                getattr(system, "name", "the model"),
                state["n"],
                0.5 * float(np.sum(np.square(r))),
                now - t0,
            )
        return r

    return wrapped


def output_error_cost(record, system, values: dict[str, float], substeps: int = 4) -> float:
    """``fit_output_error``'s cost at ``values`` (no fit): how well a start simulates the record
    from rest, on the same scale as the fit's own cost; inf where the simulation is not finite."""
    return float(output_error_costs(record, system, [values], substeps)[0])


def output_error_costs(record, system, starts: list[dict[str, float]], substeps: int = 4) -> np.ndarray:
    """``output_error_cost`` of every start in ``starts`` (values of ``system``'s trainable
    parameters), all from one batched simulation; inf where one is not finite."""
    problem, _ = output_error_problem(record, system, starts[0], substeps)
    specs = trainable_specs(system)
    us = np.stack([_problem_theta(specs, start) for start in starts], axis=1)
    res = problem.batch_residuals(us)
    costs = np.array([0.5 * float(r @ r) for r in res])
    return np.where(np.isfinite(costs), costs, np.inf)


def _problem_theta(specs, values: dict[str, float]) -> np.ndarray:
    """The trainable parameters' unconstrained vector: ``values`` where given, the specs' starts elsewhere."""
    return to_theta(specs, {s.name: values.get(s.name, s.init) for s in specs})


def output_error_problem(
    record, system, init: dict[str, float] | None, substeps: int
) -> tuple[ShootingProblem, np.ndarray]:
    """The single-shooting problem from rest, each channel's residual relative to its spread (as a
    practitioner scales them), and the trainable parameters' start (their specs', overridden by ``init``)."""
    problem = ShootingProblem.from_rest(system, record, substeps)
    for ch in problem.channels:
        ch.sigma = max(float(np.std(ch.data)), 1e-300)
    return problem, _problem_theta(trainable_specs(system), init or {})
