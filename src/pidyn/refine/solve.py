"""Solving a shooting problem: Levenberg-Marquardt with a continuity penalty driven to
exactness, then constrained Gauss-Newton steps that close the defects to round-off.

Stage 1 (scipy ``least_squares``, method ``lm``): minimise |r|^2 + mu |c|^2 for a rising
penalty weight mu, until the largest continuity defect is below ``penalty_tol`` (in state
scales). Stage 2: Gauss-Newton on min |r|^2 subject to c = 0, each step solving the
linearised constraint exactly (null-space method), so at convergence the segments join
into one trajectory of the model and the estimate is the output-error estimate of the
whole span. Stage 2 damps its steps Levenberg-Marquardt style in the null space of the
continuity: a Gauss-Newton step with step halving crawls along a curved, nearly flat valley
(Bouc-Wen's beta, gamma and n under a weak record), a damped one does not. The intervals
come from this stage's Jacobian (``pidyn.refine.uncertainty``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import null_space
from scipy.optimize import least_squares
from scipy.sparse import vstack as sparse_vstack

from pidyn.compiled.kernel import tapes_kept
from pidyn.refine.normal_lm import levenberg_marquardt
from pidyn.refine.problem import ShootingProblem

log = logging.getLogger(__name__)


@dataclass
class SolveReport:
    u: np.ndarray
    cost: float  # sum of squared channel residuals (noise units) at the solution
    max_defect: float  # largest continuity defect, in state scales
    nfev: int
    njev: int
    gn_steps: int
    seconds: float
    converged: bool
    history: list[dict] = field(default_factory=list)


def _penalised(problem: ShootingProblem, mu: float, sparse: bool = False):
    sq = np.sqrt(mu)

    def fun(u: np.ndarray) -> np.ndarray:
        r, c = problem.residuals(u)
        return np.concatenate([r, sq * c])

    def jac(u: np.ndarray):
        r, J, c, C = problem.linearize(u, sparse=sparse)
        return sparse_vstack([J, sq * C], format="csr") if sparse else np.vstack([J, sq * C])

    return fun, jac


#: above this many operations of a dense QR of the penalised Jacobian (rows x unknowns^2),
#: stage 1 solves the sparse normal equations (``pidyn.refine.normal_lm``): several records
#: at once, a long building record. Below it MINPACK's LM, whose QR costs little there.
DENSE_QR_LIMIT = 1e9


@tapes_kept()  # one system, hundreds of simulations: its tape recorded once
def _least_squares(fun, jac, u: np.ndarray, max_nfev: int, big: bool) -> tuple[np.ndarray, int, int]:
    if big:
        out = levenberg_marquardt(fun, jac, u, max_nfev=max_nfev)
        return out.x, out.nfev, out.njev
    sol = least_squares(
        fun, u, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=max_nfev, x_scale="jac"
    )
    return sol.x, int(sol.nfev), int(sol.njev or 0)


def is_big(problem: ShootingProblem) -> bool:
    """Is a dense QR of the problem's Jacobian the refinement's main cost?"""
    rows = len(problem.sel_s) * len(problem.channels)
    return rows * float(problem.n_unknowns) ** 2 > DENSE_QR_LIMIT


def solve_penalty(
    problem: ShootingProblem,
    u0: np.ndarray,
    mu0: float = 100.0,
    growth: float = 100.0,
    penalty_tol: float = 1e-6,
    max_rounds: int = 6,
    max_nfev: int = 100,
    history: list[dict] | None = None,
) -> tuple[np.ndarray, int, int]:
    """Stage 1. The penalty weight is relative to the mean data term per sample."""
    u = np.asarray(u0, float).copy()
    nfev = njev = 0
    per_sample = max(len(problem.sel_s), 1) / max(problem.S, 1)  # samples per segment
    big = is_big(problem)
    for k in range(max_rounds):
        mu = mu0 * per_sample * growth**k
        fun, jac = _penalised(problem, mu, sparse=big)
        u, nf, nj = _least_squares(fun, jac, u, max_nfev, big)
        nfev += nf
        njev += nj
        r, c = problem.residuals(u)
        dmax = float(np.max(np.abs(c))) if c.size else 0.0
        if history is not None:
            history.append(
                {
                    "stage": "penalty",
                    "mu": mu,
                    "cost": float(r @ r),
                    "max_defect": dmax,
                    "nfev": nf,
                }
            )
        log.debug("penalty mu=%.3g: cost %.6g, max defect %.3g (%d evaluations)", mu, r @ r, dmax, nf)
        if dmax < penalty_tol:
            break
    return u, nfev, njev


def _max_abs(a: np.ndarray) -> float:
    return float(np.max(np.abs(a))) if a.size else 0.0


def _damped_step(
    problem: ShootingProblem, u: np.ndarray, lin: tuple, lam: float, rho: float, defect_slack: float
) -> tuple[np.ndarray | None, float]:
    """One accepted step d of stage 2 from ``u`` (None when no damping up to 1e12 gives one),
    and the damping it took. ``lin`` = (r, J, c, C) at ``u``."""
    r, J, c, C = lin
    if C.shape[0]:  # restore the linearised continuity exactly, move within its null space
        dp = np.linalg.lstsq(C, -c, rcond=None)[0]
        N = null_space(C)
    else:
        dp, N = np.zeros(u.size), np.eye(u.size)
    A = J @ N
    g = A.T @ (r + J @ dp)
    H = A.T @ A
    D = np.diag(np.maximum(np.diag(H), 1e-12 * max(float(np.max(np.diag(H), initial=0.0)), 1e-300)))
    cost0, merit0 = float(r @ r), float(r @ r) + rho * float(c @ c)
    slack = max(defect_slack, _max_abs(c))

    def acceptable(v: np.ndarray) -> tuple[bool, np.ndarray]:
        # the merit falls, or (filter) the misfit falls while the defects stay within the
        # slack that the next step's restoration closes
        rn, cn = problem.residuals(v)
        ok = float(rn @ rn) + rho * float(cn @ cn) <= merit0 * (1 + 1e-12) or (
            float(rn @ rn) <= cost0 * (1 + 1e-12) and _max_abs(cn) <= slack
        )
        return ok, cn

    while lam <= 1e12:
        try:
            xi = np.linalg.solve(H + lam * D, -g)
        except np.linalg.LinAlgError:
            xi = np.linalg.lstsq(H + lam * D, -g, rcond=None)[0]
        d = dp + N @ xi
        ok, cn = acceptable(u + d)
        if ok:
            return d, lam
        if C.shape[0]:  # second-order correction: the step's own curvature reopens the defects
            d = d + np.linalg.lstsq(C, -cn, rcond=None)[0]
            if acceptable(u + d)[0]:
                return d, lam
        lam *= 4.0
    return None, lam


def solve_constrained(
    problem: ShootingProblem,
    u0: np.ndarray,
    max_steps: int = 40,
    step_tol: float = 1e-10,
    defect_tol: float = 1e-8,
    defect_slack: float = 1e-7,
    history: list[dict] | None = None,
) -> tuple[np.ndarray, int, bool]:
    """Stage 2: min |r|^2 subject to c = 0. Each step restores the linearised continuity
    exactly (minimum-norm correction) and takes a Levenberg-Marquardt step within its null
    space, accepted when the merit |r|^2 + rho |c|^2 falls (rho far above any stage-1 weight).
    Such a merit rejects good steps whose own curvature reopens the defects (the Maratos
    effect): a trial step also counts when the misfit falls and the defects stay below
    ``defect_slack`` (the next restoration closes them), and a rejected one gets a
    second-order correction before the damping grows."""
    u = np.asarray(u0, float).copy()
    rho = 1e12 * max(len(problem.sel_s) / max(problem.S, 1), 1.0)
    lam, converged, steps = 1e-6, False, 0
    lin = problem.linearize(u)
    for steps in range(1, max_steps + 1):  # noqa: B007 (the count is returned)
        r, J, c, _ = lin
        d, lam = _damped_step(problem, u, lin, lam, rho, defect_slack)
        if d is None:  # no damping lowers the merit: stay, converged if only round-off is left to gain
            converged = _max_abs(c) < defect_tol
            if history is not None:
                history.append(
                    {
                        "stage": "constrained",
                        "cost": float(r @ r),
                        "max_defect": _max_abs(c),
                        "step": 0.0,
                        "lam": lam,
                    }
                )
            break
        with np.errstate(over="ignore", invalid="ignore"):  # a step from a diverging start may overflow
            rp = r + J @ d
            decrease = float(r @ r - rp @ rp)  # the model's predicted decrease of the misfit
        u = u + d
        lam = max(lam / 3.0, 1e-12)
        lin = problem.linearize(u)
        r, c = lin[0], lin[2]
        if history is not None:
            history.append(
                {
                    "stage": "constrained",
                    "cost": float(r @ r),
                    "max_defect": _max_abs(c),
                    "step": _max_abs(d),
                    "lam": lam,
                }
            )
        small = _max_abs(d) < step_tol * max(1.0, _max_abs(u))
        if (small or abs(decrease) < 1e-10 * (1.0 + float(r @ r))) and _max_abs(c) < defect_tol:
            converged = True
            break
    return u, steps, converged


def solve(
    problem: ShootingProblem,
    u0: np.ndarray,
    penalty_tol: float = 1e-6,
    max_nfev: int = 100,
    gn_steps: int = 40,
    penalty_start: float = 100.0,
) -> SolveReport:
    """Both stages from ``u0``."""
    t0 = time.perf_counter()
    hist: list[dict] = []
    u, nfev, njev = (
        solve_penalty(
            problem, u0, mu0=penalty_start, penalty_tol=penalty_tol, max_nfev=max_nfev, history=hist
        )
        if problem.S > 1
        else _single(problem, u0, max_nfev, hist)
    )
    u, steps, ok = solve_constrained(problem, u, max_steps=gn_steps, history=hist)
    r, c = problem.residuals(u)
    return SolveReport(
        u=u,
        cost=float(r @ r),
        max_defect=float(np.max(np.abs(c))) if c.size else 0.0,
        nfev=nfev,
        njev=njev + steps,
        gn_steps=steps,
        seconds=time.perf_counter() - t0,
        converged=ok,
        history=hist,
    )


def _single(
    problem: ShootingProblem, u0: np.ndarray, max_nfev: int, hist: list[dict]
) -> tuple[np.ndarray, int, int]:
    fun, jac = _penalised(problem, 0.0)
    sol = least_squares(
        fun, u0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=max_nfev, x_scale="jac"
    )
    hist.append({"stage": "single", "cost": float(2 * sol.cost), "nfev": int(sol.nfev)})
    return sol.x, int(sol.nfev), int(sol.njev or 0)
