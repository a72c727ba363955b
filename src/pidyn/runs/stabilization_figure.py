"""The stabilisation diagram: the modes of linear state-space models of increasing order fitted to
the record's fitting part (``pidyn.baselines.subspace``), each marked by whether it is found again
at the next lower order. A physical mode stands as a column of stable poles; poles that move with
the order are the noise's and the model's. It tells an engineer how many modes the record
supports, and where, before any model of the structure is trusted.

A pole is stable in frequency when it is within 1 % of the previous order's nearest pole, in
damping within 5 %, in shape at a MAC of 0.98 or more: the usual criteria of operational modal
analysis (Peeters and De Roeck 2001). A pole with a damping ratio outside (0, 0.5) is not drawn as
a mode."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pidyn.baselines.peers import io_arrays, spans
from pidyn.baselines.subspace import Pole, poles
from pidyn.reporting import pyplot
from pidyn.signals import powered, transfer_function
from pidyn.systems.modal import mac

#: the criteria of a stable pole against the previous order's nearest one
FREQ_TOL, DAMP_TOL, MAC_MIN = 0.01, 0.05, 0.98
#: classes, from least to most stable, and how each is drawn (marker, colour)
CLASSES = {
    "new": ("x", "0.65"),
    "frequency": ("+", "C1"),
    "frequency and damping": ("^", "C0"),
    "stable": ("o", "C2"),
}


def orders_for(n_outputs: int, n_dof: int) -> list[int]:
    """Even orders from 2 to twice the modes a record of ``n_outputs`` sensors on a model of
    ``n_dof`` degrees of freedom could show, with room for the noise's: at least 20."""
    return list(range(2, max(20, 4 * max(n_outputs, n_dof) + 8) + 1, 2))


def classify(table: dict[int, list[Pole]]) -> list[tuple[Pole, str]]:
    """Every physical pole of every order with its class against the order below it."""
    out: list[tuple[Pole, str]] = []
    previous: list[Pole] = []
    for order in sorted(table):
        current = [p for p in table[order] if 0.0 < p.damping_ratio < 0.5]
        for p in current:
            out.append((p, _class(p, previous)))
        previous = current
    return out


def _class(p: Pole, previous: list[Pole]) -> str:
    if not previous:
        return "new"
    q = min(previous, key=lambda q: abs(q.frequency_hz - p.frequency_hz))
    if abs(p.frequency_hz - q.frequency_hz) > FREQ_TOL * q.frequency_hz:
        return "new"
    if abs(p.damping_ratio - q.damping_ratio) > DAMP_TOL * q.damping_ratio:
        return "frequency"
    return "stable" if mac(p.shape, q.shape) >= MAC_MIN else "frequency and damping"


def stable_modes(marked: list[tuple[Pole, str]], min_orders: int = 3) -> list[dict[str, Any]]:
    """The columns of the diagram: stable poles within 2 % of each other's frequency, found at
    ``min_orders`` orders or more, with their median frequency and damping ratio."""
    stable = sorted((p for p, c in marked if c == "stable"), key=lambda p: p.frequency_hz)
    groups: list[list[Pole]] = []
    for p in stable:
        if groups and p.frequency_hz <= 1.02 * np.median([q.frequency_hz for q in groups[-1]]):
            groups[-1].append(p)
        else:
            groups.append([p])
    return [
        {
            "frequency_hz": float(np.median([p.frequency_hz for p in g])),
            "damping_ratio": float(np.median([p.damping_ratio for p in g])),
            "orders": sorted({p.order for p in g}),
        }
        for g in groups
        if len({p.order for p in g}) >= min_orders
    ]


def stabilization_figure(path: Path, record: Any, n_dof: int) -> dict[str, Any] | None:
    """Draw the diagram of the record's fitting part; returns its summary for metrics.json (the
    orders, and the stable modes), or None where it does not apply (no accelerometer outputs, or a
    record too short for the subspace fit)."""
    try:
        U, Y = io_arrays(record)
    except ValueError:
        return None
    fit, _ = spans(record)
    ok = fit & np.all(np.isfinite(U), axis=0) & np.all(np.isfinite(Y), axis=0)
    if not ok[fit].all():  # a gap in the fitting part: no Hankel matrix across it
        return None
    orders = orders_for(Y.shape[0], n_dof)
    try:
        table = poles(U[:, fit], Y[:, fit], record.dt, orders)
    except (ValueError, np.linalg.LinAlgError):
        return None
    marked = classify(table)
    modes = stable_modes(marked)
    _draw(path, record, U[:, fit], Y[:, fit], marked, orders)
    return {"method": "PO-MOESP subspace", "orders": orders, "stable_modes": modes}


def _draw(path: Path, record: Any, U: np.ndarray, Y: np.ndarray, marked, orders: list[int]) -> None:
    plt = pyplot()

    tf = transfer_function(U.mean(axis=0), Y[-1], record.dt)
    band = powered(tf, tf.freq > 0)
    f_lo, f_hi = float(tf.freq[band].min()), float(tf.freq[band].max())
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    axh = ax.twinx()
    axh.semilogy(tf.freq[band], np.abs(tf.h[band]), color="0.8", lw=1.0, zorder=0)
    axh.set_ylabel("|H| last output / mean input (H1)", color="0.5")
    ax.set_zorder(axh.get_zorder() + 1)
    ax.patch.set_visible(False)
    for name, (marker, colour) in CLASSES.items():
        pts = [(p.frequency_hz, p.order) for p, c in marked if c == name and f_lo <= p.frequency_hz <= f_hi]
        if pts:
            f, o = zip(*pts)
            ax.scatter(f, o, marker=marker, color=colour, s=22, label=name, lw=1.0)
    ax.set_xscale("log")
    ax.set_xlim(f_lo, f_hi)
    ax.set_ylim(0, max(orders) + 2)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8, loc="upper left", title="against the order below", title_fontsize=8)
    ax.set_title(f"{record.name}: stabilisation diagram (subspace, fitting part)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
