"""A model from several records, finished for what it is for: the next record, simulated from rest.

Multiple shooting frees each record's initial state and solves the records' segments to
continuity. Over many records its cost is flat along directions that the initial states absorb:
on Painter Street's leave-events-out folds two refinements that ended within 0.002 % of one cost
simulated their own 17 events from rest at NRMSE 0.467 and 0.527, and predicted the fold's unseen
events 0.03-0.08 apart. A prediction is a free run from rest. So the estimate ends with a short
output-error solve from rest on the same span (``fit_output_error``), and its intervals are that
problem's, at its solution: from either end of that valley it reaches the same estimate.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from pidyn.integrate import piece_starts
from pidyn.notes import note
from pidyn.params import to_theta
from pidyn.refine.output_error import fit_output_error, output_error_cost, output_error_problem
from pidyn.refine.problem import ShootingProblem
from pidyn.refine.settings import RefineSettings

log = logging.getLogger(__name__)


def applies(record: Any, problem: ShootingProblem, settings: RefineSettings) -> bool:
    """Several records, a span from the record's start, and evaluations to spend."""
    return bool(settings.polish_several > 0 and piece_starts(record) and problem.bounds[0] == 0)


def polish_from_rest(
    record: Any, problem: ShootingProblem, theta: np.ndarray, settings: RefineSettings
) -> tuple[ShootingProblem, np.ndarray, dict[str, Any]]:
    """The output-error problem from rest over ``problem``'s span, the polished parameters in its
    coordinates, and what the polish did (``RefineResult.polish``)."""
    t0 = time.perf_counter()
    span = record.segment(None, float(problem.t[problem.bounds[-1]]))
    values = problem.values(theta)
    oe, theta_start = output_error_problem(span, problem.system, values, problem.substeps)
    before = output_error_cost(span, problem.system, values, problem.substeps)
    fit = fit_output_error(span, problem.system, values, problem.substeps, max_nfev=settings.polish_several)
    theta_oe, after = to_theta(oe.specs, {**values, **fit.params}), float(fit.cost)
    if not after <= before:  # the solve ends no higher than it starts; a cost that rose is a bug, not data
        log.warning(
            "the polish from rest did not lower the cost (%.6g -> %.6g); the shooting estimate kept",
            before,
            after,
        )
        theta_oe, after = theta_start, before
    out = {
        "evaluations": int(fit.nfev),
        "cost_before": before,
        "cost_after": after,
        "seconds": time.perf_counter() - t0,
        "note": note(
            "polished_from_rest",
            f"several records: the shooting estimate finished by output error from rest "
            f"({fit.nfev} evaluations, cost {before:.4g} -> {after:.4g}); the intervals are that problem's",
        ),
    }
    log.info(out["note"])
    return oe, theta_oe, out
