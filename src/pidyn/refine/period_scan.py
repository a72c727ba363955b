"""A scan of the period: does another basin of the cost fit the record better?

A local solver ends in the basin its start lies in. On a weak record the cost can be nearly flat
in the period over a wide range, with a lower basin a long way off: on Painter Street's
21 May 2023 longitudinal record the refinement, started from SRIM's model (0.27 s), ended at
0.287 s, where the fitting part's output-error cost is 38.2, while near the transfer function's
0.18 s it is 32.2. No start offered lay in that basin.

The scan holds the model's stiffnesses at the estimate's times lam^2 for a grid of frequency
factors lam (every natural period times 1 / lam, damping ratios kept: dampers times lam, from
``StructuralSystem.period_scaling``), fits the other parameters by output error at each point
(the profile of the cost along that family; for one degree of freedom, the profile in the
period itself), and, where a point fits clearly better than the estimate's own point, frees
every parameter from it. The refinement then solves again from that start and keeps the lower
cost. Linear models only: their simulation is the one-sample map, so the whole scan takes a few
seconds."""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import least_squares

from pidyn.compiled.kernel import tapes_kept
from pidyn.parallel import map_ordered
from pidyn.params import to_theta, trainable_specs
from pidyn.refine.output_error import output_error_problem
from pidyn.refine.problem import ShootingProblem

log = logging.getLogger(__name__)

#: period ratios (scanned period / the estimate's) of the grid: a factor of two either way, 6 % apart
#: (a basin of a mode damped 3 % of critical is about that wide)
PERIOD_RATIOS = tuple(float(r) for r in np.geomspace(0.5, 2.0, 25))


@dataclass
class PeriodScan:
    """The profile of the output-error cost along the period family, and what it found."""

    period_ratios: list[float]  # scanned period / estimate's period
    costs: list[
        float
    ]  # output-error cost with the stiffnesses held there (inf, in JSON null: did not simulate)
    estimate_cost: float  # the same fit at ratio 1
    best_ratio: float
    values: dict[str, float] | None = None  # the free fit from the best point, when that is clearly lower
    cost: float | None = None  # its cost
    seconds: float = 0.0
    held: list[str] = field(default_factory=list)  # the stiffnesses held along the profile

    def to_dict(self) -> dict:
        """For ``refinement.json``: a point that did not simulate is null (plain JSON has no inf)."""
        out = asdict(self)
        out["costs"] = [c if np.isfinite(c) else None for c in self.costs]
        out["estimate_cost"] = self.estimate_cost if np.isfinite(self.estimate_cost) else None
        return out


def scaled(values: dict[str, float], powers: dict[str, float], lam: float) -> dict[str, float]:
    """``values`` with every parameter in ``powers`` times ``lam ** power``."""
    return {k: v * lam ** powers[k] if k in powers else v for k, v in values.items()}


@tapes_kept()  # one system, hundreds of simulations: its tape recorded once
def scan_period(
    system,
    record,
    values: dict[str, float],
    ratios: tuple[float, ...] = PERIOD_RATIOS,
    substeps: int = 4,
    margin: float = 0.01,
    profile_nfev: int = 15,
    free_nfev: int = 60,
) -> PeriodScan | None:
    """The scan over ``record`` (the span the estimate was fitted to) from the estimate ``values``;
    None where the system declares no period family (a nonlinear model). ``margin``: the best
    point frees its parameters only when its cost is below the estimate's by this share."""
    powers = {k: p for k, p in system.period_scaling().items() if k in values}
    held = [k for k, p in powers.items() if p == 2.0]
    if not held:
        return None
    t0 = time.perf_counter()
    problem, _ = output_error_problem(record, system, values, substeps)
    specs = trainable_specs(system)
    free = np.array([s.name not in held for s in specs])
    grid = sorted({1.0, *ratios})
    warm(problem, to_theta(specs, values))
    points = map_ordered(
        lambda ratio: profile_point(
            problem, to_theta(specs, scaled(values, powers, 1.0 / ratio)), free, profile_nfev
        ),
        grid,
    )
    thetas, costs = [p[0] for p in points], [p[1] for p in points]
    i_est, i_best = grid.index(1.0), int(np.argmin(costs))
    out = PeriodScan(grid, costs, costs[i_est], grid[i_best], held=held)
    if np.isfinite(costs[i_best]) and costs[i_best] < costs[i_est] * (1.0 - margin):
        fun, jac = problem.fd_fun_and_jac()
        with np.errstate(all="ignore"):
            sol = least_squares(fun, thetas[i_best], jac=jac, method="trf", max_nfev=free_nfev)
        if np.all(np.isfinite(sol.fun)):
            out.values, out.cost = problem.values(sol.x), float(sol.cost)
    out.seconds = time.perf_counter() - t0
    log.info(
        "period scan: cost %.4g at the estimate, %.4g at %.3g times its period (%.1f s)",
        out.estimate_cost,
        costs[i_best],
        out.best_ratio,
        out.seconds,
    )
    return out


def warm(problem: ShootingProblem, theta: np.ndarray) -> None:
    """One simulation before the points are shared among processes: the system's tape is then
    recorded (and its kernel built) once, here, and every worker inherits it."""
    with np.errstate(all="ignore"):
        problem.residuals_and_fd_jacobian(theta, columns=np.array([], int))


@tapes_kept()  # one system, hundreds of simulations: its tape recorded once
def profile_point(
    problem: ShootingProblem, theta0: np.ndarray, free: np.ndarray, max_nfev: int
) -> tuple[np.ndarray, float]:
    """The parameters marked ``free`` fitted with the others held at ``theta0``; inf where the
    held point does not simulate."""
    fun, jac = problem.fd_fun_and_jac(columns=np.nonzero(free)[0])  # the held columns are not needed

    def full(sub: np.ndarray) -> np.ndarray:
        theta = theta0.copy()
        theta[free] = sub
        return theta

    with np.errstate(all="ignore"):
        r0 = fun(theta0)
        if not np.all(np.isfinite(r0)):
            return theta0, float("inf")
        if not free.any():
            return theta0, 0.5 * float(r0 @ r0)
        sol = least_squares(
            lambda s: fun(full(s)),
            theta0[free],
            jac=lambda s: jac(full(s)),
            method="trf",
            max_nfev=max_nfev,
        )
    cost = float(sol.cost) if np.all(np.isfinite(sol.fun)) else float("inf")
    return full(sol.x), cost
