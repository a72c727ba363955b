"""The period and damping ratio against the amplitude of shaking, within one record: windows of the
record fitted one by one by the linear part of the identified model (``pidyn.discrepancy.running``),
each window's estimate with its 95 % interval, over the peak the sensor read in it. A structure
whose soil or joints soften in strong shaking shows a period that grows with the amplitude; a
linear one, a flat row. Where the model carries an amplitude law (``AmplitudeSoftening``), the
law's own period at each window's simulated envelope is drawn beside the windows' estimates, so
the law is seen against what each part of the record says by itself."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.discrepancy.running import running_modes
from pidyn.reporting import pyplot
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.terms import LinearStiffness, ViscousDamping

log = logging.getLogger(__name__)


def linear_part(system: Any) -> Any | None:
    """A single degree of freedom's spring and dashpot alone (with its inputs and their
    parameters), the model an equivalent-linear window fits; None for other structures."""
    terms = getattr(system, "terms", None)
    if terms is None or system.n_dof != 1:
        return None
    keep = [t for t in terms if type(t) in (ViscousDamping, LinearStiffness)]
    if len(keep) != 2:
        return None
    if len(keep) == len(terms):
        return system
    new = SDOFSystem(
        keep,
        mass=system.mass,
        excitation=system.excitation,
        name=f"{system.name} (linear part)",
        inputs=system.inputs,
    )
    names = {s.name for s in new.param_specs()}
    new._specs = [s for s in system.param_specs() if s.name in names]
    return new


def amplitude_figure(
    path: Path, record: Any, system: Any, values: dict[str, float], sim: dict[str, np.ndarray], period: float
) -> dict[str, Any] | None:
    """Draw the figure for a measured record; returns the windows' rows for metrics.json
    (``period_vs_amplitude``), or None where it does not apply (a simulated record, not a single
    degree of freedom with one spring and one dashpot, too short for two windows)."""
    local = linear_part(system)
    if local is None or record.truth or not np.isfinite(period) or period <= 0:
        return None
    width = max(12.0 * period, 2.0)  # the diagnosis's running period's windows
    if record.t[-1] - record.t[0] < 2 * width:
        return None
    try:
        rows = running_modes(record, local, values, width=width, step=width / 4)
    except ValueError as exc:
        log.info("no period against amplitude (%s)", exc)
        return None
    law = _law(record, system, values, sim, rows["t"], width)
    _draw(path, record, rows, law)
    keep = np.isfinite(rows["period"])
    out = {
        key: [float(v) for v in rows[key][keep]]
        for key in ("t", "peak", "period", "period_lo", "period_hi", "damping", "damping_lo", "damping_hi")
    }
    if law is not None:
        out["law_period"] = [float(v) for v in law[keep]]
    return {"window_s": width, "unit": _unit(record), **out}


def _law(record: Any, system: Any, values: dict[str, float], sim: dict, centres: np.ndarray, width: float):
    """The amplitude law's period at each window's mean simulated envelope (what a window's one
    period averages over; None without a law)."""
    term = next((t for t in getattr(system, "terms", []) if hasattr(t, "at_envelope")), None)
    if term is None or sim.get("z") is None or sim["z"].shape[1] == 0:
        return None
    col = sum(t.n_latent for t in system.terms[: system.terms.index(term)])  # the law's own latent column
    e = sim["z"][:, col]
    m = float(values.get("m", 1.0))
    out = np.full(len(centres), np.nan)
    for i, tc in enumerate(centres):
        sel = np.abs(record.t - tc) <= width / 2
        if sel.any() and np.isfinite(e[sel]).all():
            k, _ = term.at_envelope(values, float(np.mean(e[sel])))
            out[i] = 2 * np.pi * np.sqrt(m / k) if k > 0 else np.nan
    return out


def _unit(record: Any) -> str:
    kind, _ = record.reference()
    return (record.meta.units or {}).get(kind) or {"a": "m/s^2", "x": "m", "v": "m/s"}.get(kind, "")


def _draw(path: Path, record: Any, rows: dict[str, np.ndarray], law: np.ndarray | None) -> None:
    plt = pyplot()

    ok = np.isfinite(rows["period"])
    peak = rows["peak"][ok]
    fig, (ax, axd) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True)
    for axis, key, scale, label in (
        (ax, "period", 1.0, "period (s)"),
        (axd, "damping", 100.0, "damping ratio (%)"),
    ):
        mid, lo, hi = (rows[k][ok] * scale for k in (key, f"{key}_lo", f"{key}_hi"))
        bounded = np.isfinite(lo) & np.isfinite(hi) & (lo > 0)
        err = np.vstack([mid - lo, hi - mid])[:, bounded]
        axis.errorbar(
            peak[bounded],
            mid[bounded],
            yerr=np.clip(err, 0, None),
            fmt="o",
            ms=4,
            color="C0",
            ecolor="0.6",
            lw=0.8,
            capsize=2,
            label="window estimate, 95 % interval",
        )
        if not bounded.all():  # a quiet window that does not bound it (a damping of 0 to infinity)
            axis.plot(
                peak[~bounded],
                mid[~bounded],
                "o",
                ms=4,
                mfc="none",
                color="0.5",
                label="window estimate, not bounded by the window",
            )
        axis.set_ylabel(label)
        axis.grid(True, lw=0.3, alpha=0.5)
    if law is not None:  # a marker per window: the law reads the envelope, not the peak
        ax.plot(
            peak, law[ok], "D", ms=4, mfc="none", color="C3", label="the model's law at the window's envelope"
        )
    ax.legend(fontsize=8)
    axd.set_xscale("log")  # shaking spans decades between the coda and the strong motion
    axd.set_xlabel(f"peak of the response in the window ({_unit(record)})")
    ax.set_title(f"{record.name}: period and damping against amplitude", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
