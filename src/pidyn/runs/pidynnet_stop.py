"""When PIDynNet's later windows cannot change where the refinement starts.

The refinement starts from the estimate that simulates the fitting part best: PIDynNet's, the
data's or a classical method's (``pidyn.refine.stage``). On the shipped strong-motion records a
peer's estimate simulated better than PIDynNet's full budget on every one of the 50 Painter Street
event-directions and the 20 leave-events-out folds of both bridges, by 1.1-15 times in cost. So a
run whose peers are already far ahead after a window spends PIDynNet's later windows on an estimate
that is reported but not used. With ``model.schedule.stop_behind`` set, PIDynNet stops after a
window whose estimate simulates the fitting part from rest at more than that many times the best
peer's cost; the refinement then starts as it would have, and the run says so (note
``pidynnet_behind``). The check waits for the baselines, which run beside PIDynNet, so the
decision never depends on which finished first.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np
from omegaconf import DictConfig

from pidyn.notes import note
from pidyn.refine.output_error import output_error_costs
from pidyn.runs.methods import peer_starts, refine_plan

log = logging.getLogger(__name__)


def behind_check(
    cfg: DictConfig, system: Any, record: Any, pending: Any, start: Any
) -> Callable[[dict[str, float]], str | None] | None:
    """The question ``SubperiodIdentifier.run`` asks after each window (None where it does not
    apply: no ``stop_behind``, no refinement, or no peer among its starts). ``pending``: the
    baselines' job (its rows, once in, are kept for the run); ``start``: the data's start."""
    factor = cfg.model.schedule.get("stop_behind")
    plan = refine_plan(cfg)
    if factor is None or plan is None:
        return None
    allowed = plan[0]
    if not allowed:
        return None
    w = cfg.data.windows
    span = record.segment(w.get("t_start"), w.get("t_end"))
    names = [s.name for s in system.param_specs() if s.trainable]

    def ask(values: dict[str, float]) -> str | None:
        own = {n: float(values[n]) for n in names}
        peers = peer_starts(allowed, own, start, pending.result())
        if not peers:
            return None
        costs = output_error_costs(span, system, [own, *peers.values()])
        best = int(np.argmin(costs[1:]))
        label, lead = list(peers)[best], costs[1 + best]
        if not (np.isfinite(lead) and costs[0] > float(factor) * lead):
            return None
        return note(
            "pidynnet_behind",
            f"PIDynNet stopped after this window: its estimate simulates the fitting part from rest at "
            f"cost {costs[0]:.4g}, {costs[0] / lead:.3g} times {label}'s {lead:.4g} (model.schedule.stop_behind: "
            f"{float(factor):g}); the refinement starts from the estimate that simulates best, and PIDynNet's "
            "later windows would have to lower its cost that many times to be it",
        )

    return ask
