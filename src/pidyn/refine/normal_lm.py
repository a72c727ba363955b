"""Levenberg-Marquardt on the normal equations of a sparse Jacobian.

A multiple-shooting Jacobian is block-sparse: a sample's residual depends on the parameters
and on its own segment's initial state, a continuity defect on the parameters and two
neighbouring segments. MINPACK's LM (scipy's ``method="lm"``) factors the dense matrix by QR
at every step, about 2 M n^2 operations: for several records at once (25,000 rows, 371
unknowns) that is the whole cost of the refinement. Here the step solves
(J^T J + lam D^2) d = -J^T r, with J^T J formed from the sparse J (about M (p + s)^2 operations
for p parameters and s states per segment) and factored by Cholesky (n^3 / 3). Squaring the
condition number is harmless here: the problem is scaled by its columns (MINPACK's
``x_scale="jac"``), the damping keeps the system definite, and the constrained stage that follows
(``pidyn.refine.solve``) takes the last steps on the Jacobian itself.

The damping follows Nielsen's rule (Madsen, Nielsen and Tingleff 2004, "Methods for non-linear
least squares problems", algorithm 3.16); the tests of convergence are MINPACK's (ftol, xtol,
gtol) so that both solvers stop at the same point of the same problem.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp


@dataclass
class LMResult:
    x: np.ndarray
    nfev: int
    njev: int
    status: str  # "ftol", "xtol", "gtol", "max_nfev" or "stalled"


def _normal(r: np.ndarray, J) -> tuple[np.ndarray, np.ndarray]:
    if sp.issparse(J):
        A = (J.T @ J).toarray()
        g = J.T @ r
    else:
        A, g = J.T @ J, J.T @ r
    return np.asarray(A), np.asarray(g).ravel()


def _damped_solve(A: np.ndarray, g: np.ndarray, d2: np.ndarray, lam: float) -> np.ndarray | None:
    try:
        factor = sla.cho_factor(A + lam * np.diag(d2), check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        return None
    step = -sla.cho_solve(factor, g, check_finite=False)
    return step if np.all(np.isfinite(step)) else None


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], object],
    x0: np.ndarray,
    max_nfev: int = 100,
    ftol: float = 1e-12,
    xtol: float = 1e-12,
    gtol: float = 1e-12,
) -> LMResult:
    """min |fun(x)|^2 from ``x0``; ``jac(x)`` returns a scipy sparse matrix or an array."""
    x = np.asarray(x0, float).copy()
    r = fun(x)
    nfev, njev = 1, 0
    cost = float(r @ r)
    d2 = np.zeros(x.size)
    lam, nu = -1.0, 2.0
    while nfev < max_nfev:
        A, g = _normal(r, jac(x))
        njev += 1
        d2 = np.maximum(d2, np.diag(A))  # the columns' scales, never shrinking (MINPACK's mode 1)
        d2 = np.where(d2 > 0, d2, 1.0)
        if cost == 0.0 or np.max(np.abs(g) / np.sqrt(d2)) <= gtol * np.sqrt(cost):
            return LMResult(x, nfev, njev, "gtol")
        if lam < 0:
            lam = 1e-3
        while nfev < max_nfev:
            step = _damped_solve(A, g, d2, lam)
            if step is None:
                lam, nu = lam * nu, nu * 2.0
                if lam > 1e16:
                    return LMResult(x, nfev, njev, "stalled")
                continue
            predicted = -float(step @ g) * 2.0 - float(step @ (A @ step))  # cost falls by this, linearly
            r_new = fun(x + step)
            nfev += 1
            cost_new = float(r_new @ r_new)
            rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
            if rho > 0:
                small_x = np.sqrt(float(np.sum(d2 * step**2))) <= xtol * np.sqrt(float(np.sum(d2 * x**2)))
                small_f = cost - cost_new <= ftol * cost and predicted <= ftol * cost
                x, r, cost = x + step, r_new, cost_new
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                if small_f:
                    return LMResult(x, nfev, njev, "ftol")
                if small_x:
                    return LMResult(x, nfev, njev, "xtol")
                break
            lam, nu = lam * nu, nu * 2.0
            if lam > 1e16:
                return LMResult(x, nfev, njev, "stalled")
    return LMResult(x, nfev, njev, "max_nfev")
