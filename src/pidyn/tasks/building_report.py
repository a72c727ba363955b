"""What a run on a building adds to its folder: modal properties of the identified linear part
beside the truth, storey hysteresis loops, and the identified equation of every storey.

    modal.json          frequencies, damping ratios, mode shapes (identified, truth, errors, MAC)
    building.md         the same as tables, and one equation per storey
    figures/storey_loops.png   restoring force against drift per storey, identified and true
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from pidyn.integrate import rk4
from pidyn.reporting import diverged, plottable, write_json
from pidyn.systems.modal import compare_modes, modal_table


def storey_response(system, values: Mapping[str, float], t: np.ndarray, f: np.ndarray,
                    state0: np.ndarray | None = None, substeps: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Drift and restoring force of every storey (each (N, n_storeys)) of the model simulated
    over the record."""
    y0 = np.zeros(system.n_state) if state0 is None else np.asarray(state0, float)
    with np.errstate(all="ignore"):
        Y, _ = rk4(system, dict(values), t, f, y0[None, :], substeps=substeps)
    return _drift_and_force(system, values, t, Y[:, 0])


def _drift_and_force(system, values: Mapping[str, float], t: np.ndarray, Y: np.ndarray):
    n = system.n_dof
    x, v, z = Y[:, :n], Y[:, n:2 * n], Y[:, 2 * n:]
    drift = np.diff(np.concatenate([np.zeros((len(t), 1)), x], axis=1), axis=1)
    force = np.stack(system.storey_forces(t, x, v, z, dict(values)), axis=1)
    return drift, force


def write_building_report(system, record, identified: Mapping[str, float], truth: Mapping[str, Any] | None,
                          state0: np.ndarray | None, run_dir: Path, logger: Any = None, step: int = 0) -> dict:
    """Modal table, storey equations and loops into ``run_dir``; returns the modal comparison."""
    modes = compare_modes(system, identified, truth if truth and all(v is not None for v in truth.values()) else None)
    d_id, f_id = storey_response(system, identified, record.t, record.f, state0)
    modes["diverged"] = diverged(d_id) or diverged(f_id)
    write_json(run_dir / "modal.json", modes)
    eqs = system.storey_equations(identified)
    lines = [f"# {system.name}: {system.n_dof} storeys under {record.name}", "",
             "## Modes of the identified linear part (about rest)", "", modal_table(modes), "",
             "## Identified storey equations (d_i: drift of storey i)", "", "```", *eqs, "```", ""]
    if "truth" in modes:
        lines.append("Truth: " + "; ".join(s.strip() for s in system.storey_equations(truth)))
    if modes["diverged"]:
        lines += ["", "**The identified model diverges when simulated over the record** (its response blows "
                  "up): the estimate is not a usable model of this building, and the loops show only the part "
                  "before the blow-up."]
    (run_dir / "building.md").write_text("\n".join(lines) + "\n")
    fig_dir = run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    true_loops = None
    if record.clean is not None and truth and "truth" in modes:
        clean = record.clean
        Y = np.concatenate([clean.x, clean.v] + ([clean.z] if clean.z is not None else []), axis=1)
        true_loops = _drift_and_force(system, truth, record.t, Y)
    plot_storey_loops(fig_dir / "storey_loops.png", d_id, f_id, true_loops, title=f"{system.name} under {record.name}")
    exp = getattr(logger, "experiment", None) if logger is not None else None
    if exp is not None and hasattr(exp, "add_text"):
        exp.add_text("storey_equations", "\n\n".join(eqs), step)
        exp.add_text("modes", modal_table(modes), step)
        for r, fr in enumerate(modes["identified"]["frequency_hz"], 1):
            exp.add_scalar(f"modes/f{r}_hz", fr, step)
            exp.add_scalar(f"modes/zeta{r}", modes["identified"]["damping_ratio"][r - 1], step)
    return modes


def plot_storey_loops(path: Path, drift: np.ndarray, force: np.ndarray,
                      truth: tuple[np.ndarray, np.ndarray] | None, title: str = "") -> None:
    """Restoring force against drift, one panel per storey: the identified model simulated over
    the record, and the true structure's when known."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = drift.shape[1]
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.2 * rows), squeeze=False)
    for i in range(n):
        ax = axes[i // cols][i % cols]
        if truth is not None:
            ax.plot(truth[0][:, i], truth[1][:, i], color="0.6", lw=2.0, label="true")
        ax.plot(plottable(drift[:, i]), plottable(force[:, i]), color="C3", lw=0.7, label="identified")
        ax.set_title(f"storey {i + 1}")
        ax.set_xlabel("drift (m)")
        ax.set_ylabel("restoring force (N)")
    for j in range(n, rows * cols):
        axes[j // cols][j % cols].axis("off")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
