"""The refinement stage: multiple shooting from PIDynNet's estimate and networks.

PIDynNet's windows are shooting segments, and its networks give the full state (x, x', and
the latent z) at every segment start: exactly what multiple shooting needs and what a
single-shooting fit lacks. The stage takes those states and PIDynNet's parameters (or a
classical estimate, when that one simulates the record better), solves the shooting
problem to exact continuity (``pidyn.refine.solve``), estimates the noise from the
residuals, and returns every parameter with its 95 % interval.

    result = refine(system, record, start={"pidynnet": values}, network_states=states)
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.stats import chi2

from pidyn.notes import note
from pidyn.params import to_theta
from pidyn.refine import polish
from pidyn.refine.period_profile import profile_period
from pidyn.refine.period_scan import scan_period
from pidyn.refine.problem import ShootingProblem
from pidyn.refine.settings import RefineSettings
from pidyn.refine.setup import build_problem, initial_states, state_scale
from pidyn.refine.solve import solve, solve_constrained
from pidyn.refine.uncertainty import (
    bound_notes,
    correlation,
    estimate_noise,
    identifiability_notes,
    intervals,
    one_sided_intervals,
    residual_correlation,
    residual_covariance,
    set_noise,
)

log = logging.getLogger(__name__)


@dataclass
class RefineResult:
    params: dict[str, float]
    intervals: dict[str, dict]  # name -> value, std, ci95 [lo, hi], rel_std_pct
    correlation: list[list[float]]
    names: list[str]
    noise_std: dict[str, float]  # per channel, estimated from the residuals
    notes: list[str]  # identifiability, in words
    start: str  # which starting estimate the solution came from
    start_costs: dict[str, float]  # free-simulation cost of each candidate start (noise units)
    initial_state: list[float]
    cost: float
    max_defect: float
    segments: int
    condition_number: float
    converged: bool
    seconds: float
    state_source: str
    initial_state_mode: str = "free"  # rest: held at rest; free: estimated
    rest_test: dict = field(default_factory=dict)  # auto: the likelihood-ratio test of a start at rest
    history: list[dict] = field(default_factory=list)
    compared: dict = field(default_factory=dict)  # the same refinement from other segment states (by source)
    #: covariance of the parameters' unconstrained coordinates (log / logit / scaled), in ``names`` order
    covariance: list[list[float]] = field(default_factory=list)
    #: 0: the inverse information (white residuals); else the sandwich over this many lags
    covariance_lags: int = 0
    #: the scan of the period after the local solve (``pidyn.refine.period_scan.PeriodScan``); empty: none ran
    period_scan: dict = field(default_factory=dict)
    #: the period's adjusted profile likelihood (``pidyn.refine.period_profile.PeriodProfile``); empty: none ran
    period_profile: dict = field(default_factory=dict)
    #: several records: the output-error finish from rest (``pidyn.refine.polish``); empty: none ran
    polish: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def refine(
    system,
    record,
    start: dict[str, dict[str, float]],
    settings: RefineSettings | None = None,
    network_states: np.ndarray | None = None,
    t_start: float | None = None,
    t_end: float | None = None,
    prefer: str = "pidynnet",
) -> RefineResult:
    """Refine the best of the ``start`` estimates (label -> parameter values) by multiple shooting.

    Every candidate is scored by a free simulation of the span from the same initial state;
    the best one starts the refinement. When ``prefer`` (PIDynNet) is not the best, the log
    and the notes say so. A candidate that still simulates better than the refined estimate is
    refined as well, and the lower cost wins; then the other basins of the period (``_period_scan``).
    """
    settings = settings or RefineSettings()
    t_wall = time.perf_counter()
    problem = build_problem(system, record, settings, t_start, t_end)
    starts = _Starts(problem, settings, start, network_states, prefer)
    rep, used, scan = _period_scan(record, problem, starts, *starts.solve_best(), settings)
    u, converged = rep.u, rep.converged
    if settings.reweight:
        r, _ = problem.residuals(u)
        set_noise(problem, estimate_noise(problem, r))
        u, _, converged = solve_constrained(problem, u, max_steps=settings.gn_steps, history=rep.history)
    test: dict = {}
    if settings.initial_state == "auto":
        problem, u, converged, test = _test_rest(problem, u, converged, settings, rep.history)
    final, theta, (r, J, C), shooting, polished = _finish(record, problem, u, settings)
    ints, corr, cond, cov, lags, notes = _uncertainty(final, r, J, C, theta)
    return RefineResult(
        params=final.values(theta),
        intervals=ints,
        correlation=corr.tolist(),
        names=problem.names,
        noise_std=estimate_noise(final, r),
        notes=starts.notes + test.pop("notes", []) + ([polished["note"]] if polished else []) + notes,
        start=used,
        start_costs=starts.costs,
        initial_state=shooting["initial_state"],
        cost=shooting["cost"],
        max_defect=shooting["max_defect"],
        segments=problem.S,
        condition_number=cond,
        converged=bool(converged),
        seconds=time.perf_counter() - t_wall,
        state_source=settings.states,
        rest_test=test,
        history=rep.history,
        covariance=cov.tolist(),
        covariance_lags=lags,
        period_scan=scan.to_dict() if scan is not None else {},
        period_profile=_period_profile(record, problem, theta, settings),
        polish=polished,
        initial_state_mode="rest" if polished else ("free" if problem.free_state0 else "rest"),
    )


def _finish(record, problem: ShootingProblem, u: np.ndarray, settings: RefineSettings):
    """The problem whose solution is the estimate, its coordinates and linearization (r, J, C),
    the shooting solution's cost, largest defect and initial state, and the polish: for several
    records the output-error finish from rest (``pidyn.refine.polish``), else the shooting problem."""
    r, J, c, C = problem.linearize(u)
    theta, states = problem.unpack(u)
    shooting = {
        "cost": float(r @ r),
        "max_defect": float(np.max(np.abs(c))) if c.size else 0.0,
        "initial_state": states[0].tolist(),
    }
    if not polish.applies(record, problem, settings):
        return problem, theta, (r, J, C), shooting, {}
    final, theta, polished = polish.polish_from_rest(record, problem, theta, settings)
    r, J, _, C = final.linearize(theta)
    shooting["initial_state"] = [0.0] * problem.ns  # the polished model starts each record at rest
    return final, theta, (r, J, C), shooting, polished


def _period_scan(record, problem: ShootingProblem, starts: _Starts, rep, used: str, settings: RefineSettings):
    """The refined estimate checked against the other basins of the period (linear models, a span
    from the record's start not known to be moving, where the scan's output error from rest is the
    right cost); where the scan's start refines to a lower cost, it replaces the estimate, and the
    notes say so. (rep, the start it came from, the scan or None.)"""
    if not settings.period_scan or settings.initial_state == "free" or problem.bounds[0] != 0:
        return rep, used, None
    span = record.segment(None, float(problem.t[problem.bounds[-1]]))
    theta, _ = problem.unpack(rep.u)
    scan = scan_period(problem.system, span, problem.values(theta), substeps=problem.substeps)
    if scan is None or scan.values is None:
        return rep, used, scan
    alt = starts.run_from(starts.add("period_scan", scan.values))
    if not alt.cost < rep.cost * (1 - 1e-6):
        return rep, used, scan
    starts.notes.append(
        note(
            "period_scan_moved",
            f"the refinement from {used} ended in a basin of the cost that another period fits better: "
            f"a scan of the period (output error, {scan.best_ratio:.3g} times the period) refined to "
            f"cost {alt.cost:.4g} against {rep.cost:.4g}; the estimate is the scan's",
        )
    )
    log.warning(starts.notes[-1])
    return alt, "period_scan", scan


def _period_profile(record, problem: ShootingProblem, theta: np.ndarray, settings: RefineSettings) -> dict:
    """The period's profile-likelihood interval about the final estimate, where the scan's cost
    is the right one (see ``_period_scan``) and the model is one linear mode; {} elsewhere."""
    if not settings.period_profile or problem.free_state0 or problem.bounds[0] != 0:
        return {}
    span = record.segment(None, float(problem.t[problem.bounds[-1]]))
    prof = profile_period(problem.system, span, problem.values(theta), substeps=problem.substeps)
    if prof is None:
        return {}
    log.info(
        "period profile: %.4g s, 95 %% set %s (adjusted by %.3g, %.1f s)",
        prof.period_min,
        prof.ci95,
        prof.adjustment,
        prof.seconds,
    )
    return prof.to_dict()


def _test_rest(
    problem: ShootingProblem, u: np.ndarray, converged: bool, settings: RefineSettings, history: list[dict]
) -> tuple[ShootingProblem, np.ndarray, bool, dict]:
    """Is the record's initial state rest? An earthquake record starts before the ground
    moves, and a structure at rest gives its initial state for free: on a hysteretic system
    that roughly halves the spread of beta, gamma and n (``cramer_rao``'s two bounds). Test
    it: hold the first segment's state at rest, solve again from one free run from rest (so
    continuity holds from the first step), and compare the misfits (noise units). Under rest,
    the drop from freeing the state is chi-square with n_state degrees of freedom; beyond its
    (1 - level) quantile the state is estimated. A span that starts inside the record is
    never at rest by assumption.

    The chi-square law assumes white residuals. Correlated ones (noise-free data, where the
    residual is the integrator's smooth error, or coloured sensor noise) inflate the drop by
    the long-run variance ratio, (1 + rho) / (1 - rho) for a lag-1 correlation rho of the
    free solution's residuals; the drop is divided by it (1 for white noise). Measured: on
    noise-free Bouc-Wen under El Centro x3 an uncorrected drop of 4e3 against 11.3 said "not
    at rest" of a record that starts at rest."""
    ns = problem.ns
    if int(problem.bounds[0]) > 0:
        return (
            problem,
            u,
            converged,
            {"notes": [], "applies": False, "reason": "the span starts inside the record"},
        )
    r, _ = problem.residuals(u)
    rest, ur, ok = _solved_at_rest(problem, u, settings, history)
    rr, cr = rest.residuals(ur)
    rho = residual_correlation(problem, r)
    inflation = (1 + rho) / (1 - rho)
    delta = float(rr @ rr - r @ r) / inflation
    threshold = float(chi2.ppf(1.0 - settings.rest_test_level, ns))
    closed = (float(np.max(np.abs(cr))) if cr.size else 0.0) < 1e-6
    at_rest = bool(delta <= threshold and closed)
    test = {
        "applies": True,
        "misfit_drop": delta,
        "threshold": threshold,
        "level": settings.rest_test_level,
        "dof": ns,
        "at_rest": at_rest,
        "residual_lag1_correlation": rho,
        "inflation": inflation,
    }
    text = _rest_sentence(test, settings)
    if at_rest:
        log.info("%s", text)
        return rest, ur, ok, {**test, "notes": []}
    log.warning(text)
    return problem, u, converged, {**test, "notes": [text]}


def _solved_at_rest(problem: ShootingProblem, u: np.ndarray, settings: RefineSettings, history: list[dict]):
    """The same problem with the first segment's state held at rest, solved from one free run
    from rest (so continuity holds from the first step)."""
    ns = problem.ns
    theta, _ = problem.unpack(u)
    rest = ShootingProblem(
        problem.system,
        problem.t,
        problem.f,
        problem.channels,
        problem.bounds,
        problem.substeps,
        fixed_state0=np.zeros(ns),
        state_scale=problem.state_scale,
        fixed=problem.fixed,
        hold=problem.hold,
        restarts=problem.restarts,
    )
    run, _ = rest.free_run(theta, np.zeros(ns))
    states = np.nan_to_num(run[rest.bounds[:-1] - rest.bounds[0]])
    ur, _, ok = solve_constrained(
        rest, rest.pack(problem.values(theta), states), max_steps=settings.gn_steps, history=history
    )
    return rest, ur, ok


def _rest_sentence(test: dict, settings: RefineSettings) -> str:
    """What the rest test found, for the log and, when the state is estimated, the notes."""
    delta, threshold, ns, inflation = test["misfit_drop"], test["threshold"], test["dof"], test["inflation"]
    corrected = f" (divided by {inflation:.3g} for correlated residuals)" if inflation > 1.01 else ""
    if test["at_rest"]:
        return (
            f"the record starts at rest: estimating its initial state lowers the misfit by {max(delta, 0.0):.3g}"
            f"{corrected}, below the {100 * settings.rest_test_level:g} % chi-square threshold {threshold:.3g} "
            f"({ns} states), so the state is held at rest"
        )
    return note(
        "not_at_rest",
        f"the record does not start at rest: estimating its initial state lowers the misfit by {delta:.3g}"
        f"{corrected}, beyond the {100 * settings.rest_test_level:g} % chi-square threshold {threshold:.3g} ({ns} states); "
        f"the initial state is estimated, which widens the intervals",
    )


class RefinementDiverged(ValueError):
    """The refinement's solve ended where a parameter is infinite (a log coordinate run off): named,
    instead of a linear-algebra routine's complaint about infs further on."""


def _uncertainty(problem: ShootingProblem, r: np.ndarray, J: np.ndarray, C: np.ndarray, theta: np.ndarray):
    """Intervals, correlation and condition number at the solution, the lags the covariance
    took, and the notes on what the record does not determine (logged). The covariance is
    scaled by the residuals' own variance (the weights' noise unit may still be off by a
    factor); where the residuals are correlated (a model's error on a measured record, not
    white noise) it is the sandwich over that many lags (``uncertainty.sandwich``): on Painter
    Street the white-noise interval of the period was a few tenths of a percent wide while the
    peers' estimates of the same event spread over several percent."""
    lost = [n for n, v in problem.values(theta).items() if not np.isfinite(v)]
    if lost or not (np.all(np.isfinite(J)) and np.all(np.isfinite(r))):
        raise RefinementDiverged(
            f"the refinement ran {', '.join(lost) or 'the model'} to infinity: its solve did not end on a finite "
            "model of the record, and no interval can be given; give a start nearer the data "
            "(system.params.<name>.init, model.refine.starts) or a model the record determines"
        )
    cov, cond, lags = residual_covariance(problem, r, J, C)
    ints, corr = intervals(problem.specs, theta, cov), correlation(cov)
    one_sided_intervals(problem, ints, theta, r, J, C)
    notes = bound_notes(problem.specs, theta) + identifiability_notes(problem.names, ints, corr, cond)
    for n_ in notes:
        log.warning("identifiability: %s", n_)
    return ints, corr, cond, cov, lags, notes


class _Starts:
    """The candidate starting estimates, scored by a free simulation from the same state."""

    def __init__(
        self,
        problem: ShootingProblem,
        settings: RefineSettings,
        start: dict[str, dict[str, float]],
        network_states: np.ndarray | None,
        prefer: str,
    ) -> None:

        names = problem.names
        self.cands = {
            k: v for k, v in start.items() if v and all(n in v and np.isfinite(v[n]) for n in names)
        }
        if not self.cands:
            raise ValueError(f"refinement: no starting estimate has every parameter {names}")
        self.problem, self.settings, self.network_states = problem, settings, network_states
        self.thetas = {k: to_theta(problem.specs, v) for k, v in self.cands.items()}
        self.first = prefer if prefer in self.thetas else next(iter(self.thetas))
        self.states0 = initial_states(problem, self.thetas[self.first], settings.states, network_states)
        fits = {k: problem.free_run_fit(th, self.states0[0]) for k, th in self.thetas.items()}
        self.costs = {k: c for k, (c, _) in fits.items()}
        self.order = sorted(self.costs, key=lambda k: self.costs[k])
        steady = [k for k in self.order if not fits[k][1]]
        if fits[self.first][1] and steady:
            # the states carried by a model that blows up are no states (and their spread no scale)
            self.first = steady[0]
            self.states0 = initial_states(problem, self.thetas[self.first], settings.states, network_states)
        problem.state_scale = state_scale(problem, self.states0)
        self.notes: list[str] = []
        blown = [k for k, (_, b) in fits.items() if b]
        if len(blown) == len(fits):
            self.notes.append(
                note(
                    "starts_diverge",
                    f"no starting estimate ({', '.join(blown)}) simulates the record without blowing up: the "
                    "refinement starts from a diverging model and may end at a degenerate fit (parameters "
                    "at their bounds); give a classical start (baselines.run and model.refine.starts) or a "
                    "better guess (system.guess)",
                )
            )
            log.warning(self.notes[-1])
        best = self.order[0]
        if prefer in self.costs and best != prefer:
            who = "PIDynNet's estimate" if prefer == "pidynnet" else f"the {prefer} start"
            self.notes.append(
                note(
                    "start_not_preferred",
                    f"{who} simulates the record worse than {best}'s (cost "
                    f"{self.costs[prefer]:.4g} against {self.costs[best]:.4g}); the refinement started "
                    f"from {best}",
                )
            )
            log.warning(self.notes[-1])

    def add(self, label: str, values: dict[str, float]) -> str:
        """One more candidate start (found after the first solve); returns its label."""
        self.cands[label] = values
        self.thetas[label] = to_theta(self.problem.specs, values)
        return label

    def run_from(self, label: str):
        st = (
            self.states0
            if label == self.first
            else initial_states(self.problem, self.thetas[label], self.settings.states, self.network_states)
        )
        s = self.settings
        return solve(
            self.problem,
            self.problem.pack(self.cands[label], st),
            s.penalty_tol,
            s.max_nfev,
            s.gn_steps,
            s.penalty_start,
        )

    def solve_best(self):
        rep, used = self.run_from(self.order[0]), self.order[0]
        for other in self.order[1:]:
            if self.costs[other] < rep.cost * (1 - 1e-6):
                log.warning(
                    "%s's estimate simulates better (%.4g) than the refined one (%.4g): refining it too",
                    other,
                    self.costs[other],
                    rep.cost,
                )
                alt = self.run_from(other)
                if alt.cost < rep.cost:
                    rep, used = alt, other
        return rep, used
