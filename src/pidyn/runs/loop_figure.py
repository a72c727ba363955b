"""A single degree of freedom's restoring force against its displacement over the record (the
hysteresis loop an engineer reads a nonlinear structure by: its slope is the stiffness, its
area the energy dissipated per cycle), the identified model's beside the true structure's when
the record carries it. A building draws one per storey (``building_report.plot_storey_loops``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.integrate import input_hold, piece_starts
from pidyn.runs.building_report import plot_storey_loops
from pidyn.simulate import simulate_states


def restoring_loop(
    system: Any, values: Mapping[str, float], record: Any, state0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(displacement, restoring force) of the model simulated over the record, each (N, 1): the
    sum of its force terms, damping included."""
    Y, _ = simulate_states(
        system,
        dict(values),
        record.t,
        record.f,
        state0,
        hold=input_hold(record),
        restarts=piece_starts(record),
    )
    x, v, z = Y[:, 0], Y[:, 1], Y[:, 2:]
    force = np.broadcast_to(system.restoring_force(record.t, x, v, z, dict(values)), x.shape)
    return x[:, None], np.asarray(force, float)[:, None]


def loop_figure(
    path: Path, system: Any, values: Mapping[str, float], record: Any, state0: np.ndarray | None = None
) -> bool:
    """Draw the loop of a single degree of freedom; False (nothing drawn) for another structure."""
    if system.n_dof != 1 or not hasattr(system, "restoring_force"):
        return False
    x, force = restoring_loop(system, values, record, state0)
    truth = None
    known = record.truth or {}
    if all(s.name in known for s in system.param_specs()):
        truth = restoring_loop(system, {s.name: float(known[s.name]) for s in system.param_specs()}, record)
    plot_storey_loops(
        path, x, force, truth, f"{system.name} under {record.name}", ["restoring force"], "displacement (m)"
    )
    return True
