"""A single degree of freedom's restoring force against its displacement over the record (the
hysteresis loop an engineer reads a nonlinear structure by: its slope is the stiffness, its
area the energy dissipated per cycle), the identified model's beside the true structure's when
the record carries it. A building draws one per storey (``building_report.plot_storey_loops``), a
bridge deck one per support (``support_loops``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.runs.building_report import plot_storey_loops
from pidyn.simulate import simulate_response


def restoring_loop(
    system: Any, values: Mapping[str, float], t: np.ndarray, sim: Mapping[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """(displacement, restoring force), each (N, 1), along a simulated response ``sim``
    (``simulate_response``): the sum of the model's force terms, damping included."""
    x, v, z = sim["x"][:, 0], sim["v"][:, 0], sim["z"]
    force = np.broadcast_to(system.restoring_force(t, x, v, z, dict(values)), x.shape)
    return x[:, None], np.asarray(force, float)[:, None]


def loop_figure(
    path: Path, system: Any, values: Mapping[str, float], record: Any, sim: Mapping[str, np.ndarray]
) -> bool:
    """Draw the loop of a single degree of freedom along ``sim``, the identified model's response
    over the record; False (nothing drawn) for another structure."""
    if system.n_dof != 1 or not hasattr(system, "restoring_force"):
        return False
    truth = None
    known = record.truth or {}
    if all(s.name in known for s in system.param_specs()):
        true_values = {s.name: float(known[s.name]) for s in system.param_specs()}
        truth = restoring_loop(system, true_values, record.t, simulate_response(system, true_values, record))
    x, force = restoring_loop(system, values, record.t, sim)
    plot_storey_loops(
        path, x, force, truth, f"{system.name} under {record.name}", ["restoring force"], "displacement (m)"
    )
    return True


def support_loops(
    path: Path, system: Any, values: Mapping[str, float], record: Any, sim: Mapping[str, np.ndarray]
) -> bool:
    """Draw each support's force against its deformation along ``sim`` (a deck on its supports,
    ``support_response``); False (nothing drawn) for another structure."""
    if not hasattr(system, "support_response"):
        return False
    f = np.asarray(record.f, float)
    d, forces = system.support_response(record.t, sim["x"], sim["v"], sim["z"], f, dict(values))
    deformation = np.stack([np.broadcast_to(x, record.t.shape) for x in d], axis=1)
    force = np.stack([np.broadcast_to(q, record.t.shape) for q in forces], axis=1)
    names = [f"support {j + 1} ({name})" for j, name in enumerate(system.inputs)]
    plot_storey_loops(
        path,
        deformation,
        force,
        None,
        f"{system.name} under {record.name}",
        names,
        "support deformation (m)",
        "force per kg of deck (m/s$^2$)",
    )
    return True
