"""A run's figures, drawn side by side on the machine's cores (``pidyn.parallel``): each figure
is one independent piece of work, its numbers (a transfer function's peak, the period against the
amplitude) returned for metrics.json. A figure that fails is a note, not the loss of the run's
results."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.notes import note
from pidyn.parallel import map_ordered
from pidyn.reporting import plot_convergence, plot_response
from pidyn.runs.amplitude_figure import amplitude_figure
from pidyn.runs.build import Run
from pidyn.runs.loop_figure import loop_figure, support_loops
from pidyn.runs.metrics import reference_channel
from pidyn.runs.mode_shape_figure import mode_shape_figure
from pidyn.runs.stabilization_figure import stabilization_figure
from pidyn.runs.transfer_figure import transfer_figure

log = logging.getLogger(__name__)

Figure = Callable[[], Any]

#: the figures whose numbers go to metrics.json (the others return their matplotlib objects, kept in
#: the process that drew them)
NUMBERS = ("period_vs_amplitude", "stabilization", "mode_shapes", "transfer_function")


def draw_figures(
    run: Run,
    results: list,
    truths: dict,
    baselines: list[dict],
    refined: Any,
    sim: dict[str, np.ndarray],
    metrics: dict,
    final: dict[str, float],
) -> None:
    """Every figure of the run into ``figures/``, their numbers into ``metrics``. The slowest
    first (on a Painter Street event: the period against the amplitude, 123 windows fitted, then the
    convergence), so that the workers' interleaved shares come out about even."""
    fig_dir = run.run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    drawn = _Drawn(run, results, truths, baselines, refined, sim, final)
    figures = {**_modal(run, fig_dir, baselines, final, sim), **_plain(drawn, fig_dir, metrics)}
    order = ("period_vs_amplitude", "param_convergence", "stabilization", "transfer_function")
    figures = {
        k: figures[k] for k in sorted(figures, key=lambda k: order.index(k) if k in order else len(order))
    }
    for key, out, text in map_ordered(_drawn, list(figures.items())):
        if text is not None:
            log.warning(text)
            metrics.setdefault("notes", []).append(text)
        elif out is not None:
            metrics[key] = out


def _drawn(item: tuple[str, Figure]) -> tuple[str, Any, str | None]:
    """(name, its numbers, None) or (name, None, the note that it was not drawn)."""
    key, draw = item
    try:
        out = draw()
        return key, out if key in NUMBERS else None, None
    except Exception as exc:  # noqa: BLE001  (a figure's failure must not cost the run its results)
        return (
            key,
            None,
            note("figure_failed", f"figures/{key}.png was not drawn: {type(exc).__name__}: {exc}"),
        )


@dataclass
class _Drawn:
    """What the plain figures draw: the run, PIDynNet's windows, the truth where known, the
    peers, the refinement, the simulated response and the final values."""

    run: Run
    results: list
    truths: dict
    baselines: list[dict]
    refined: Any
    sim: dict[str, np.ndarray]
    final: dict[str, float]


def _plain(d: _Drawn, fig_dir: Path, metrics: dict) -> dict[str, Figure]:
    """The figures every run draws: the parameters' convergence, the response, the restoring
    force, the supports' loops and the transfer function (whose peak goes to metrics)."""
    system, record, sim, final, refined = d.run.system, d.run.record, d.sim, d.final, d.refined
    ukf = next((b for b in d.baselines if b["method"] == "ukf" and b.get("trajectory")), None)
    kind, floor, label = reference_channel(record, system.n_dof)
    series = {
        f"measured {label}": getattr(record, kind)[:, floor - 1],
        "identified model (simulated)": sim[kind][:, floor - 1],
    }
    trajectory, rows, truths = d.run.ident.trajectory, [r.__dict__ for r in d.results], d.truths
    return {
        "param_convergence": lambda: plot_convergence(
            fig_dir / "param_convergence.png",
            trajectory,
            truths,
            rows,
            title=f"{system.name} under {record.name}",
            other=None if ukf is None else ("UKF", ukf["trajectory"]),
            final=None if refined is None else refined.intervals,
        ),
        "transfer_function": lambda: transfer_figure(fig_dir / "transfer_function.png", record, system, sim),
        "response": lambda: plot_response(
            fig_dir / "response.png",
            record.t,
            series,
            title=f"{system.name}: NRMSE {metrics['sim_nrmse'][label]:.3g} ({label})",
        ),
        "restoring_force": lambda: loop_figure(fig_dir / "restoring_force.png", system, final, record, sim),
        "support_loops": lambda: support_loops(fig_dir / "support_loops.png", system, final, record, sim),
    }


def _modal(
    run: Run, fig_dir: Path, baselines: list[dict], final: dict[str, float], sim: dict
) -> dict[str, Figure]:
    """The figures of a measured record's modes, where they apply: the period and damping against
    the amplitude (one degree of freedom), the stabilisation diagram, the mode shapes beside the
    peers' with MAC (several floors). A simulated record has none: the truth, not a peer, is what
    its modes are held to."""
    system, record = run.system, run.record
    if record.truth:
        return {}
    modal = run.run_dir / "modal.json"
    modes = json.loads(modal.read_text()).get("modes") if modal.exists() else None
    srim = next((b.get("modes") for b in baselines if b["method"] == "srim"), None)
    out: dict[str, Figure] = {}
    if modes and system.n_dof == 1:
        period = modes[0]["period_s"]
        out["period_vs_amplitude"] = lambda: amplitude_figure(
            fig_dir / "period_vs_amplitude.png", record, system, final, sim, period
        )
    out["stabilization"] = lambda: stabilization_figure(fig_dir / "stabilization.png", record, system.n_dof)
    if modes and system.n_dof > 1:
        out["mode_shapes"] = lambda: mode_shape_figure(fig_dir / "mode_shapes.png", record, modes, srim)
    return out
