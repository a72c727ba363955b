"""Candidate starts scored by a free simulation: of several starting estimates, the one whose
model simulates the record best from rest. (The refinement scores its own candidates on its
shooting problem, from the states it will solve with: ``pidyn.refine.stage``.)"""

from __future__ import annotations

import logging

from pidyn.refine.output_error import output_error_cost

log = logging.getLogger(__name__)


def cheapest(record, system, options: dict[str, dict[str, float]]) -> str:
    """The option with the lowest output-error cost on ``record`` (said in the log when there is a
    choice)."""
    if len(options) == 1:
        return next(iter(options))
    costs = {k: output_error_cost(record, system, v) for k, v in options.items()}
    best = min(costs, key=costs.get)
    log.info(
        "starts (output-error cost on the fitting part): %s; the cheapest: %s",
        ", ".join(f"{k} {c:.4g}" for k, c in costs.items()),
        best,
    )
    return best
