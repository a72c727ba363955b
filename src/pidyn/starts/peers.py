"""The peers' realizations as starts: SRIM's and OKID-ERA's model of twice the system's modes on a
record, mapped onto the system's parameters (``realization``). A real record can have several
linear optima far apart (a Painter Street longitudinal record: the transfer function's peak at
0.19 s, the output-error optimum at 0.28 s), and a start from one peak is not a start from the
other; the peers find the second. Without mdof installed there are none."""

from __future__ import annotations

import logging

from pidyn.baselines.peers import okid_era, realization_start, srim

log = logging.getLogger(__name__)


def peer_starts(record, system) -> dict[str, dict[str, float]]:
    """``{method: parameters}`` of each peer whose realization of order ``2 * n_dof`` on the whole
    of ``record`` is stable and maps onto ``system``; empty without mdof."""
    try:
        import mdof  # noqa: F401
    except ImportError:
        return {}

    order = 2 * int(system.n_dof)
    out: dict[str, dict[str, float]] = {}
    for name, method in (("srim", srim), ("okid_era", okid_era)):
        try:
            params = realization_start(method(record, orders=(order,)), system, record.dt)
        except (ValueError, RuntimeError, ArithmeticError, IndexError) as exc:
            log.info("no %s start (%s)", name, exc)
            continue
        if params:
            out[name] = params
    return out
