"""What the data say about the estimate: noise level, covariance, intervals, and plain words
when a parameter is not determined.

At the solution of a shooting problem the Gauss-Newton (Laplace) covariance of the
unknowns is N (N^T J^T J N)^-1 N^T, with J the Jacobian of the channel residuals in noise
units and N a basis of the directions that keep the segments continuous (the single-
shooting parametrisation by theta and y_0). The parameters' block is in their unconstrained
coordinates (log for positive quantities, logit for bounded ones), so the 95 % interval is
taken there and mapped back: it never crosses a physical bound.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import null_space

from pidyn.notes import note
from pidyn.params import ParamSpec, dvalue_draw, from_raw
from pidyn.refine.problem import ShootingProblem

Z95 = 1.959963984540054


def estimate_noise(problem: ShootingProblem, r: np.ndarray) -> dict[str, float]:
    """Per-channel noise std from the residuals (r in the channels' current units), corrected
    for the degrees of freedom the fit used."""
    free = problem.n_theta + (problem.ns if problem.free_state0 else 0)
    m_total = len(r)
    out = {}
    for ch, sl in zip(problem.channels, problem.channel_slices()):
        e = r[sl] * ch.sigma
        dof = max(len(e) - free * len(e) / m_total, 1.0)
        out[ch.name] = float(np.sqrt(np.sum(e**2) / dof))
    return out


def set_noise(problem: ShootingProblem, sigma: dict[str, float], floor_rel: float = 1e-9) -> None:
    for ch in problem.channels:
        ch.sigma = max(sigma[ch.name], floor_rel * float(np.std(ch.data)) + 1e-300)


def covariance(
    problem: ShootingProblem, J: np.ndarray, C: np.ndarray, r: np.ndarray | None = None, lags: int = 0
) -> tuple[np.ndarray, float]:
    """Covariance of the parameters' unconstrained coordinates, and the condition number of
    the information matrix (continuity eliminated). With the residuals ``r`` and ``lags`` > 0 it
    is the sandwich for correlated residuals (``sandwich``), in the residuals' own units; else
    the inverse information in noise units. A Jacobian with non-finite entries (a trajectory that
    blows up next to the solution) gives no covariance: NaN, and an infinite condition number."""
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(C))):
        return np.full((problem.n_theta, problem.n_theta), np.nan), float("inf")
    N = null_space(C) if C.shape[0] else np.eye(J.shape[1])
    JN = J @ N
    info = JN.T @ JN
    w = np.linalg.eigvalsh(info)
    cond = float(w[-1] / max(w[0], 1e-300)) if w[-1] > 0 else float("inf")
    cov_red = np.linalg.pinv(info, rcond=1e-15, hermitian=True)
    nt = problem.n_theta
    floor = variance_floor(N[:nt], info)
    if r is not None and lags > 0:
        cov_red = cov_red @ sandwich(JN, r, problem.channel_slices(), lags) @ cov_red
        floor = floor * float(r @ r) / max(len(r), 1)  # the sandwich is in the residuals' units
    cov = (N @ cov_red @ N.T)[:nt, :nt]
    idx = np.arange(nt)
    cov[idx, idx] = np.maximum(np.diag(cov), floor)
    return cov, cond


def variance_floor(rows: np.ndarray, info: np.ndarray) -> np.ndarray:
    """A lower bound on each parameter's variance that a singular information matrix cannot hide.

    The pseudo-inverse gives a direction the record does not inform no variance at all, so a
    parameter along it got an interval of zero width: a certainty no record gives. With the
    parameter theta_i = n_i . z in the reduced coordinates z, Cauchy-Schwarz gives
    Var(theta_i) >= (n_i . n_i)^2 / (n_i' I n_i) for any information I; infinite where I does
    not see n_i at all."""
    out = np.empty(len(rows))
    for i, n_i in enumerate(rows):
        seen = float(n_i @ info @ n_i)
        norm2 = float(n_i @ n_i)
        out[i] = 0.0 if norm2 == 0 else (norm2**2 / seen if seen > 0 else np.inf)
    return out


def sandwich(JN: np.ndarray, r: np.ndarray, slices: list[slice], lags: int) -> np.ndarray:
    """The score's long-run covariance, sum over |l| <= lags of (1 - |l| / (lags + 1)) G_l with
    G_l = sum_t g_t g_(t+l)^T (Newey and West 1987), where g_t sums every channel's J_t r_t at
    sample t. Residuals that are a model's smooth error rather than white noise are correlated
    over several periods; the inverse information then understates the spread of the estimate,
    and this is what it leaves out. For white residuals it equals r^T r / n times the information."""
    g = sum(JN[sl] * r[sl, None] for sl in slices)  # (M, p): the channels share the samples
    B = g.T @ g
    for lag in range(1, min(lags, len(g) - 1) + 1):
        G = g[:-lag].T @ g[lag:]
        B += (1.0 - lag / (lags + 1.0)) * (G + G.T)
    return B


def bandwidth(rho: float, n: int) -> int:
    """Lags of the sandwich for residuals of lag-1 correlation ``rho`` over ``n`` samples: the
    plug-in rule for an AR(1) (Andrews 1991, Bartlett kernel), at most n / 4; 0 where the
    residuals are white within their sampling spread (|rho| below 3 / sqrt(n)), so a record
    with white noise keeps the inverse information."""
    if n < 8 or rho <= 3.0 / np.sqrt(n):
        return 0
    rho = min(rho, 0.99)
    alpha = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    return int(min(np.ceil(1.1447 * (alpha * n) ** (1 / 3)), n // 4))


def intervals(specs: list[ParamSpec], theta: np.ndarray, cov: np.ndarray) -> dict[str, dict]:
    """Value, std (delta method), 95 % interval (mapped from the unconstrained coordinates)."""
    import torch  # lazy: the NumPy core (simulation, refinement) runs without loading torch

    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out = {}
    for i, s in enumerate(specs):
        to_v = lambda x: float(from_raw(s, torch.tensor(float(x), dtype=torch.float64)))  # noqa: E731
        value = to_v(theta[i])
        std = abs(dvalue_draw(s, float(theta[i]))) * sd[i]
        lo, hi = sorted((to_v(theta[i] - Z95 * sd[i]), to_v(theta[i] + Z95 * sd[i])))
        out[s.name] = {
            "value": value,
            "std": float(std),
            "ci95": [lo, hi],
            "rel_std_pct": float(100 * std / abs(value)) if value != 0 else None,
        }
    return out


def correlation(cov: np.ndarray) -> np.ndarray:
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    # a near-singular information matrix (a parameter on its bound) leaves a covariance whose
    # round-off is not positive definite: a correlation is never beyond +-1
    with np.errstate(invalid="ignore"):  # a blown-up fit's covariance: NaN correlations, said elsewhere
        return np.clip(cov / np.outer(sd, sd), -1.0, 1.0)


#: the one-sided 95 % point of the standard normal: a parameter on its bound has the likelihood
#: ratio of a 50:50 mixture of chi-square with 0 and 1 degree of freedom (Self and Liang 1987)
Z95_ONE_SIDED = 1.6448536269514722


def at_bound(specs: list[ParamSpec], theta: np.ndarray, edge: float = 12.0) -> dict[int, str]:
    """Index -> ``lower`` / ``upper`` for parameters whose transform ran to a bound (a
    log-parameter towards 0, a boxed one to an end)."""
    out = {}
    for i, (s, th) in enumerate(zip(specs, theta)):
        if s.transform == "log" and th < -edge:
            out[i] = "lower"
        elif s.transform == "box" and abs(th) > edge:
            out[i] = "lower" if th < 0 else "upper"
    return out


def one_sided_intervals(
    problem: ShootingProblem,
    ints: dict[str, dict],
    theta: np.ndarray,
    r: np.ndarray,
    J: np.ndarray,
    C: np.ndarray,
) -> None:
    """Replace the interval of every parameter on its bound by a one-sided one, in place.

    In its unconstrained coordinate such a parameter has no curvature left (the Laplace interval
    shrinks to its value: zero width, a certainty no record gives). In the value's own coordinate
    the information is finite: the unknowns are rescaled by d value / d raw, the covariance taken
    there, and the interval runs from the bound to 1.645 standard deviations inside it."""
    bound = at_bound(problem.specs, theta)
    if not bound:
        return
    scale = np.ones(J.shape[1])
    for i in bound:
        scale[i] = dvalue_draw(problem.specs[i], float(theta[i]))
    # the covariance's variance floor (``variance_floor``) keeps an uninformed direction wide here too
    cov_v = residual_covariance(problem, r, J / scale, C / scale if C.shape[0] else C)[0]
    for i, side in bound.items():
        s = problem.specs[i]
        sd = float(np.sqrt(max(cov_v[i, i], 0.0)))
        end = 0.0 if s.transform == "log" else float(s.lower if side == "lower" else s.upper)
        reach = Z95_ONE_SIDED * sd
        if s.transform == "box":
            reach = min(reach, float(s.upper) - float(s.lower))
        lo, hi = (end, end + reach) if side == "lower" else (end - reach, end)
        ints[s.name].update({"ci95": [lo, hi], "std": sd, "at_bound": side, "one_sided": True})


def bound_notes(specs: list[ParamSpec], theta: np.ndarray, edge: float = 12.0) -> list[str]:
    """Parameters that ran to a bound of their transform (a log-parameter towards 0, a boxed one
    to an end): the data pushed them there, which is a finding, not a converged value."""
    out = []
    for s, th in zip(specs, theta):
        if s.transform == "log" and th < -edge:
            out.append(
                f"{s.name} ran to its lower bound (0): the record gives no evidence for this term, or the "
                "model lacks what the data show; its interval is one-sided, from 0 to the largest value the "
                "record allows"
            )
        elif s.transform == "box" and abs(th) > edge:
            end = s.lower if th < 0 else s.upper
            out.append(
                f"{s.name} ran to the {'lower' if th < 0 else 'upper'} end of its range ({end:g}): widen "
                f"system.params.{s.name}.lower/upper if that range is not physical, else the record does not "
                "determine it (its interval is one-sided, from that end)"
            )
    return out


def identifiability_notes(
    names: list[str],
    ints: dict[str, dict],
    corr: np.ndarray,
    cond: float,
    wide_pct: float = 10.0,
    strong_corr: float = 0.95,
) -> list[str]:
    """Sentences a structural engineer acts on, for parameters the record does not pin down."""
    notes = []
    half = {
        n: 100 * (ints[n]["ci95"][1] - ints[n]["ci95"][0]) / 2 / max(abs(ints[n]["value"]), 1e-300)
        for n in names
    }
    wide = [n for n in names if half[n] > wide_pct]
    done: set[str] = set()
    for n in wide:
        if n in done:
            continue
        i = names.index(n)
        group = [names[j] for j in range(len(names)) if j == i or abs(corr[i, j]) >= strong_corr]
        done.update(group)
        widths = ", ".join(f"{g} +-{half[g]:.3g} %" for g in group)
        if len(group) > 1:
            idx = [names.index(g) for g in group]
            rho = max(abs(corr[a, b]) for a in idx for b in idx if a != b)
            notes.append(
                note(
                    "not_separable",
                    f"{', '.join(group)} are not separable from this record (correlation {rho:.2f}; 95 % "
                    f"intervals {widths}); a stronger or longer excitation is needed",
                )
            )
        else:
            notes.append(
                note(
                    "poorly_determined",
                    f"{n} is poorly determined by this record (95 % interval {widths}); a stronger or longer "
                    "excitation, or a channel that responds to it, is needed",
                )
            )
    if cond > 1e14 and not notes:
        notes.append(
            note(
                "near_singular",
                f"the information matrix is near-singular (condition number {cond:.2g}): some combination "
                "of parameters is not determined by this record",
            )
        )
    return notes


def residual_correlation(problem: ShootingProblem, r: np.ndarray, cap: float = 0.9999) -> float:
    """Lag-1 autocorrelation of the measured-channel residuals in time order, averaged over
    the channels and floored at 0 (about 0 for white noise, near 1 for a smooth model error)."""
    rhos = []
    for sl in problem.channel_slices():
        e = r[sl] - np.mean(r[sl])
        denom = float(e @ e)
        if denom > 0 and len(e) > 2:
            rhos.append(float(e[1:] @ e[:-1]) / denom)
    return float(np.clip(np.mean(rhos), 0.0, cap)) if rhos else 0.0


def residual_covariance(
    problem: ShootingProblem, r: np.ndarray, J: np.ndarray, C: np.ndarray
) -> tuple[np.ndarray, float, int]:
    """The parameters' covariance scaled by the residuals' own variance, its condition number, and
    the lags it took: the sandwich where the residuals are correlated (``sandwich``, ``bandwidth``),
    else the inverse information."""
    n_free = problem.n_theta + (problem.ns if problem.free_state0 else 0)
    dof = max(len(r) - n_free, 1)
    lags = bandwidth(residual_correlation(problem, r), len(r) // max(len(problem.channels), 1))
    if lags:
        cov, cond = covariance(problem, J, C, r, lags)
        return cov * len(r) / dof, cond, lags
    cov, cond = covariance(problem, J, C)
    return cov * float(r @ r) / dof, cond, lags
