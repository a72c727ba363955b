"""A building's mode shapes as ``modal.json`` gives them (the identified model's, with their 95 %
intervals as bands), beside those of a linear state-space model fitted to the same fitting part
(the subspace realization, and mdof's SRIM where it is installed), each pair with its MAC: the
check an engineer makes first, that the physical model's shapes are the data's.

The peers see only the measured floors, so shapes are compared there, each scaled to 1 at the
highest measured floor. A peer's mode is matched to the model's by the MAC, not by its rank in
frequency: a noise pole may fall between two physical ones."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pidyn.baselines.peers import io_arrays, spans, srim
from pidyn.baselines.subspace import poles, real_shape
from pidyn.reporting import pyplot
from pidyn.systems.modal import mac


def peer_shapes(record: Any, n_dof: int) -> list[dict[str, Any]]:
    """The subspace realization's modes at the lowest order (from 2 n_dof) that gives n_dof
    physical ones: frequency, damping ratio and real shape at the measured floors."""
    U, Y = io_arrays(record)
    fit, _ = spans(record)
    orders = list(range(2 * n_dof, 4 * n_dof + 9, 2))
    table = poles(U[:, fit], Y[:, fit], record.dt, orders)
    for order in orders:
        found = [p for p in table.get(order, []) if 0.0 < p.damping_ratio < 0.5]
        if len(found) >= n_dof or order == orders[-1]:
            return [
                {
                    "frequency_hz": p.frequency_hz,
                    "damping_ratio": p.damping_ratio,
                    "mode_shape": real_shape(p.shape).tolist(),
                    "order": order,
                }
                for p in found
            ]
    return []


def srim_shapes(record: Any, n_modes: int) -> list[dict[str, Any]] | None:
    """mdof's SRIM at the order of ``n_modes`` modes (its modes with their shapes), or None where
    mdof is not installed or the realization does not simulate stably."""
    try:
        import mdof  # noqa: F401  (an optional peer: pip install 'pidyn[peer]')
    except ImportError:
        return None

    return srim(record, orders=(2 * n_modes,)).modes or None


def match(ours: list[np.ndarray], theirs: list[dict[str, Any]]) -> list[tuple[int | None, float]]:
    """For each of our shapes, the peer mode of highest MAC (index, MAC), each peer mode used once."""
    taken: set[int] = set()
    out: list[tuple[int | None, float]] = []
    for shape in ours:
        scores = [(mac(shape, p["mode_shape"]), j) for j, p in enumerate(theirs) if j not in taken]
        if not scores:
            out.append((None, float("nan")))
            continue
        best, j = max(scores)
        taken.add(j)
        out.append((j, best))
    return out


def mode_shape_figure(
    path: Path, record: Any, modes: list[dict], srim_modes: list[dict] | None = None
) -> list[dict[str, Any]] | None:
    """Draw the figure; returns per mode the peers' matched frequency and MAC (metrics.json's
    ``mode_shapes``), or None where there is nothing to compare (one degree of freedom, no shapes,
    no accelerometers)."""
    shaped = [m for m in modes if m.get("mode_shape") is not None]
    floors = [f - 1 for f in (record.sensors().get("a") or [])]
    if len(shaped) < 2 or len(floors) < 2:
        return None
    ours = [real_shape(np.asarray(m["mode_shape"], float)[floors]) for m in shaped]  # 1 at the top sensor
    try:
        peers = {"subspace": peer_shapes(record, len(shaped))}
    except (ValueError, np.linalg.LinAlgError):
        return None
    if srim_modes is None:  # the run did not fit SRIM: fit it here where mdof is installed
        srim_modes = srim_shapes(record, len(shaped))
    if srim_modes and all(m.get("mode_shape") is not None for m in srim_modes):
        peers["SRIM"] = srim_modes
    matched = {name: match(ours, rows) for name, rows in peers.items()}
    _draw(path, record, shaped, ours, floors, peers, matched)
    return [
        {
            "mode": r + 1,
            "frequency_hz": float(m["frequency_hz"]),
            **{
                name: None
                if j is None
                else {"frequency_hz": float(peers[name][j]["frequency_hz"]), "mac": float(score)}
                for name, pairs in matched.items()
                for j, score in [pairs[r]]
            },
        }
        for r, m in enumerate(shaped)
    ]


def _draw(path: Path, record: Any, shaped, ours, floors, peers, matched) -> None:
    plt = pyplot()

    n = len(shaped)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n + 0.6, 4.2), sharey=True, squeeze=False)
    level = np.concatenate([[0], np.array(floors) + 1])  # the ground, where every shape is 0
    for r, (ax, m, shape) in enumerate(zip(axes[0], shaped, ours)):
        ax.axvline(0.0, color="0.8", lw=0.8)
        ci = m.get("mode_shape_ci95")
        if ci is not None:
            band = np.vstack([[0.0, 0.0], np.asarray(ci, float)[floors] / m["mode_shape"][floors[-1]]])
            ax.fill_betweenx(
                level, band[:, 0], band[:, 1], color="C3", alpha=0.2, lw=0, label="95 % interval"
            )
        ax.plot(np.r_[0.0, shape], level, "o-", color="C3", lw=1.4, label=f"model {m['frequency_hz']:.3g} Hz")
        title = [f"mode {r + 1}"]
        for (name, rows), style in zip(peers.items(), ("s--", "d:")):
            j, score = matched[name][r]
            if j is None:
                continue
            peer = np.asarray(rows[j]["mode_shape"], float)  # real_shape's: 1 at the top sensor
            ax.plot(
                np.r_[0.0, peer],
                level,
                style,
                color="0.3",
                lw=1.0,
                label=f"{name} {rows[j]['frequency_hz']:.3g} Hz",
            )
            title.append(f"MAC {name} {score:.3f}")
        ax.set_title("\n".join(title), fontsize=9)
        ax.set_xlabel("shape (1 at the top sensor)")
        ax.legend(fontsize=7, loc="best")
        ax.grid(True, lw=0.3, alpha=0.5)
    axes[0][0].set_ylabel("floor (0: the ground)")
    axes[0][0].set_yticks(level)
    fig.suptitle(f"{record.name}: mode shapes at the measured floors", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
