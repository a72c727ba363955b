"""The measured and the identified model's transfer function from the ground, with the coherence:
the figure a structural engineer reads a record by (the peaks are the modes, their widths the
damping, a low coherence where the record says little), drawn as the field draws it: log-log
magnitude over frequency in Hz, the coherence below on its own axis."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pidyn.reporting import pyplot
from pidyn.runs.metrics import reference_channel
from pidyn.signals import TransferFunction, powered, transfer_function


def response_pair(
    record: Any, system: Any, sim: dict[str, np.ndarray]
) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """(label, ground acceleration, measured and simulated response) of the highest measured
    floor: absolute accelerations where the record is of accelerometers (a transmissibility),
    the record's own channel otherwise; the ground is the mean of several supports."""
    kind, floor, label = reference_channel(record, system.n_dof)
    f = np.asarray(record.f, float)
    several = f.ndim == 2
    ground = f[:, : f.shape[1] // 2].mean(axis=1) if several else f
    y_meas, y_model = getattr(record, kind)[:, floor - 1], sim[kind][:, floor - 1]
    if kind == "a" and not several:  # the record keeps accelerations relative to its one ground
        y_meas, y_model = y_meas + ground, y_model + ground
    return label, ground, y_meas, y_model


def transfer_figure(
    path: Path, record: Any, system: Any, sim: dict[str, np.ndarray]
) -> dict[str, Any] | None:
    """Draw the figure; returns the two estimates' peak frequencies (Hz), or None where the
    record is too short for a spectral estimate (fewer than 64 samples)."""
    label, ground, y_meas, y_model = response_pair(record, system, sim)
    ok = np.isfinite(y_meas) & np.isfinite(y_model) & np.isfinite(ground)
    if ok.sum() < 64:
        return None
    measured = transfer_function(ground[ok], y_meas[ok], record.dt)
    model = transfer_function(ground[ok], y_model[ok], record.dt)
    band = powered(measured, measured.freq > 0)
    _draw(path, measured, model, band, label, record.name, _unit(label[0]))
    peak = {
        name: float(tf.freq[band][np.argmax(np.abs(tf.h[band]))])
        for name, tf in (("measured", measured), ("model", model))
    }
    return {"channel": label, "peak_hz": peak, "segments": measured.segments}


def _unit(kind: str) -> str:
    return {"a": "-", "v": "s", "x": "s$^2$"}.get(kind, "")


def _draw(
    path: Path,
    measured: TransferFunction,
    model: TransferFunction,
    band: np.ndarray,
    label: str,
    name: str,
    unit: str,
) -> None:
    plt = pyplot()

    fig, (ax, axc) = plt.subplots(
        2, 1, figsize=(7.5, 5.2), sharex=True, gridspec_kw={"height_ratios": [3, 1]}
    )
    f = measured.freq[band]
    ax.loglog(f, np.abs(measured.h[band]), color="0.25", lw=1.0, label="measured (H1)")
    ax.loglog(f, np.abs(model.h[band]), "--", color="C3", lw=1.0, label="identified model (simulated, H1)")
    ax.set_ylabel(f"|H| {label} / ground acc. ({unit})")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    ax.set_title(
        f"{name}: transfer function from the ground ({measured.segments} Welch segments)", fontsize=10
    )
    axc.semilogx(f, np.clip(measured.coherence[band], 0, 1), color="0.25", lw=0.9)
    axc.set_ylim(0, 1.05)
    axc.set_ylabel("coherence")
    axc.set_xlabel("frequency (Hz)")
    axc.grid(True, which="both", lw=0.3, alpha=0.5)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
