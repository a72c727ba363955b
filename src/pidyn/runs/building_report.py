"""What a run on a building adds to its folder: modal properties of the identified linear part
beside the truth, storey hysteresis loops, and the identified equation of every storey.

    modal.json          frequencies, damping ratios, mode shapes (identified, truth, errors, MAC)
    building.md         the same as tables, and one equation per storey
    figures/storey_loops.png   restoring force against drift per storey, identified and true
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import welch

from pidyn.discrepancy.storey_model import storey_views
from pidyn.reporting import diverged, plottable, pyplot, write_json
from pidyn.signals import fundamental
from pidyn.simulate import simulate_states
from pidyn.systems.modal import compare_modes, modal_table


def storey_response(
    system,
    values: Mapping[str, float],
    t: np.ndarray,
    f: np.ndarray,
    state0: np.ndarray | None = None,
    substeps: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """Drift and restoring force of every storey (each (N, n_storeys)) of the model simulated
    over the record."""
    Y, _ = simulate_states(system, values, t, f, state0, substeps)
    return _drift_and_force(system, values, t, Y)


def _drift_and_force(system, values: Mapping[str, float], t: np.ndarray, Y: np.ndarray):
    n = system.n_dof
    x, v, z = Y[:, :n], Y[:, n : 2 * n], Y[:, 2 * n :]
    drift = np.diff(np.concatenate([np.zeros((len(t), 1)), x], axis=1), axis=1)
    force = np.stack(system.storey_forces(t, x, v, z, dict(values)), axis=1)
    return drift, force


def _interface_modes(path: Path) -> dict:
    """The ``modes`` list (periods and damping ratios with intervals) already in ``modal.json``,
    kept beside the building's own tables."""
    try:
        return {"modes": json.loads(path.read_text())["modes"]}
    except (OSError, ValueError, KeyError):
        return {}


def write_building_report(
    system,
    record,
    identified: Mapping[str, float],
    truth: Mapping[str, Any] | None,
    state0: np.ndarray | None,
    run_dir: Path,
    logger: Any = None,
    step: int = 0,
) -> dict:
    """Modal table, storey equations and loops into ``run_dir``; returns the modal comparison."""
    modes = compare_modes(
        system, identified, truth if truth and all(v is not None for v in truth.values()) else None
    )
    d_id, f_id = storey_response(system, identified, record.t, record.f, state0)
    modes["diverged"] = diverged(d_id) or diverged(f_id)
    eqs = system.storey_equations(identified)
    lines = _report_lines(system, record, identified, truth, modes, eqs)
    # written once every part is in (the storey residuals of a measured building included)
    write_json(run_dir / "modal.json", {**_interface_modes(run_dir / "modal.json"), **modes})
    (run_dir / "building.md").write_text("\n".join(lines) + "\n")
    fig_dir = run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    true_loops = None
    if record.clean is not None and truth and "truth" in modes:
        clean = record.clean
        Y = np.concatenate([clean.x, clean.v] + ([clean.z] if clean.z is not None else []), axis=1)
        true_loops = _drift_and_force(system, truth, record.t, Y)
    plot_storey_loops(
        fig_dir / "storey_loops.png", d_id, f_id, true_loops, title=f"{system.name} under {record.name}"
    )
    exp = getattr(logger, "experiment", None) if logger is not None else None
    if exp is not None and hasattr(exp, "add_text"):
        exp.add_text("storey_equations", "\n\n".join(eqs), step)
        exp.add_text("modes", modal_table(modes), step)
        for r, fr in enumerate(modes["identified"]["frequency_hz"], 1):
            exp.add_scalar(f"modes/f{r}_hz", fr, step)
            exp.add_scalar(f"modes/zeta{r}", modes["identified"]["damping_ratio"][r - 1], step)
    return modes


def _report_lines(
    system, record, identified: Mapping[str, float], truth, modes: dict, eqs: list[str]
) -> list[str]:
    """building.md: the modal table, the storey equations, the storey residuals of a measured
    building (added to ``modes``), and what a divergence or unknown masses mean."""
    lines = [
        f"# {system.name}: {system.n_dof} storeys under {record.name}",
        "",
        "## Modes of the identified linear part (about rest)",
        "",
        modal_table(modes),
        "",
        "## Identified storey equations (d_i: drift of storey i)",
        "",
        "```",
        *eqs,
        "```",
        "",
    ]
    if "truth" in modes:
        lines.append("Truth: " + "; ".join(s.strip() for s in system.storey_equations(truth)))
    if modes["diverged"]:
        lines += [
            "",
            "**The identified model diverges when simulated over the record** (its response blows "
            "up): the estimate is not a usable model of this building, and the loops show only the part "
            "before the blow-up.",
        ]
    if not record.truth:  # a measured building: what the model leaves of each storey's force
        split = record.meta.split
        modes["storey_residuals"] = storey_residuals(
            system, identified, record, split.heldout if split else None
        )
        lines += residual_lines(modes["storey_residuals"], bool(split))
    if not getattr(system, "mass_known", True):
        lines += [
            "",
            "Masses unknown: floor 1's mass is the unit; stiffness and damping are per kg of floor 1 "
            "(k in s^-2, c in s^-1) and the masses are ratios to floor 1's. Absolute N/m need a mass.",
        ]
    return lines


def plot_storey_loops(
    path: Path,
    drift: np.ndarray,
    force: np.ndarray,
    truth: tuple[np.ndarray, np.ndarray] | None,
    title: str = "",
    panels: list[str] | None = None,
    xlabel: str = "drift (m)",
    ylabel: str = "restoring force (N)",
) -> None:
    """Restoring force against drift, one panel per storey (or per ``panels`` name): the identified
    model simulated over the record, and the true structure's when known."""
    plt = pyplot()

    n = drift.shape[1]
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.2 * rows), squeeze=False)
    for i in range(n):
        ax = axes[i // cols][i % cols]
        if truth is not None:
            ax.plot(truth[0][:, i], truth[1][:, i], color="0.6", lw=2.0, label="true")
        ax.plot(plottable(drift[:, i]), plottable(force[:, i]), color="C3", lw=0.7, label="identified")
        ax.set_title(f"storey {i + 1}" if panels is None else panels[i])
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    for j in range(n, rows * cols):
        axes[j // cols][j % cols].axis("off")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: what a storey's residual force is compared with: the force shape each would leave behind
RESIDUAL_SHAPES = {
    "stiffness (d)": lambda d, v: d,
    "viscous (d')": lambda d, v: v,
    "friction (sign d')": lambda d, v: np.tanh(v / max(3 * float(np.std(v)) * 0.05, 1e-12)),
    "cubic (d^3)": lambda d, v: d**3,
}


def residual_lines(rows: list[dict], heldout: bool) -> list[str]:
    """building.md's table of the storeys' residual forces."""
    if not rows:
        return []
    return [
        "",
        f"## What the model leaves of each storey's force ({'held-out part' if heldout else 'whole record'})",
        "",
        "F_i = -sum_(j>=i) m_j a_j from the floors' accelerations against the model's storey force on the "
        "integrated drifts; the share of the residual each force shape would explain says where to look.",
        "",
        *residual_table({None: rows}),
    ]


def residual_table(rows_by: dict[str | None, list[dict]], label: str = "model") -> list[str]:
    """The storeys' residual forces as a markdown table; with several buildings (keys not None)
    a first column ``label`` names each row's building."""
    first = next(iter(rows_by.values()))
    shapes = list(first[0]["explained_by"])
    named = any(k is not None for k in rows_by)
    head = f"| {label} " if named else ""
    out = [
        head + "| storey | residual / force (RMS) | residual's peak (Hz) | " + " | ".join(shapes) + " |",
        ("|---" if named else "") + "|---|---|---|" + "---|" * len(shapes),
    ]
    for key, rows in rows_by.items():
        for r in rows:
            out.append(
                (f"| {key} " if named else "")
                + f"| {r['storey']} | {r['residual_share']:.3f} | {r['residual_peak_hz']:.2f} | "
                + " | ".join(f"{r['explained_by'][k]:.2f}" for k in shapes)
                + " |"
            )
    return out


def storey_residuals(
    system, values: Mapping[str, float], record, span: tuple[float, float] | None = None
) -> list[dict]:
    """Per storey, what the identified model leaves of the storey force the floors' accelerations
    give: F_i = -sum_{j >= i} m_j a_j (absolute; masses as identified, per kg of floor 1 when
    unknown) against the model's F_i on the drifts integrated from the same accelerations (both
    high-passed alike at a fifth of the fundamental). Its RMS share of F_i, its dominant frequency,
    and the share of it each simple force shape would explain (a stiffness, damping, friction or
    cubic error of that storey): where to look, not a verdict."""
    if record.a is None or np.isnan(record.a).any() or record.n_inputs != 1:
        return []
    peak = fundamental(record)
    corner = max((peak[0] if peak else 1.0) / 5.0, 2.0 / max(float(record.t[-1]), 1e-9))
    dt, n = record.dt, system.n_dof
    # each storey's shear F_i = -sum_{j>=i} m_j a_j and its drift, as the building diagnosis sees them
    views = storey_views(record, system, dict(values), corner)
    measured = np.stack([view.shear for view in views], axis=1)
    d_all = np.stack([view.drift for view in views], axis=1)
    dv_all = np.stack([view.drift_velocity for view in views], axis=1)
    x, v = np.cumsum(d_all, axis=1), np.cumsum(dv_all, axis=1)
    z = np.zeros((len(record.t), system.n_latent))
    model = np.stack(
        [np.broadcast_to(f, record.t.shape) for f in system.storey_forces(record.t, x, v, z, dict(values))],
        axis=1,
    )
    edge = max(1, int(round(2.0 / (5 * corner) / dt)))
    keep = np.zeros(len(record.t), bool)
    keep[edge : len(record.t) - edge] = True
    if span is not None:
        keep &= (record.t >= span[0]) & (record.t <= span[1])
    d, dv = d_all[keep], dv_all[keep]
    rows = []
    for i in range(n):
        r, F = (measured - model)[keep, i], measured[keep, i]
        freq, P = welch(r, fs=1.0 / dt, nperseg=min(len(r), 1024))
        shares = {}
        for name, shape in RESIDUAL_SHAPES.items():
            g = shape(d[:, i], dv[:, i])
            coef = float(g @ r) / max(float(g @ g), 1e-300)
            shares[name] = float(1.0 - np.sum((r - coef * g) ** 2) / max(float(r @ r), 1e-300))
        rows.append(
            {
                "storey": i + 1,
                "residual_share": float(np.std(r) / max(np.std(F), 1e-300)),
                "residual_peak_hz": float(freq[int(np.argmax(P[1:])) + 1]),
                "explained_by": shares,
            }
        )
    return rows
