"""A run's figures of merit: the simulated response against every measured channel, the
record's noise level, the relative errors against a known truth."""

from __future__ import annotations

import numpy as np
from omegaconf import DictConfig

from pidyn.data.sources import Record
from pidyn.errors import errors_pct
from pidyn.reporting import nrmse


def reference_channel(record: Record, n_dof: int) -> tuple[str, int, str]:
    """(kind, floor, label) of the channel a run's figures show: the record's reference kind at its
    highest measured floor (it moves the most); the label as ``channel_nrmse`` names it."""
    kind, _ = record.reference()
    floor = max(record.sensors()[kind])
    return kind, floor, f"{kind}{floor}" if n_dof > 1 else kind


def channel_nrmse(sim: dict[str, np.ndarray], record: Record) -> dict[str, float]:
    """NRMSE of the simulated response against every measured channel (``x``, or ``a3`` for
    floor 3 of a building)."""
    out = {}
    multi = sim["x"].shape[1] > 1
    for kind, floors in record.sensors().items():
        meas = getattr(record, kind)
        for fl in floors:
            out[f"{kind}{fl}" if multi else kind] = nrmse(sim[kind][:, fl - 1], meas[:, fl - 1])
    return out


def sim_nrmse_x(sim: dict[str, np.ndarray], record: Record) -> float | None:
    """Displacement NRMSE over every floor: against the noise-free truth when simulated, else
    against the measured displacement (None when no displacement was measured)."""
    if record.clean is not None:
        return nrmse(sim["x"], record.clean.x)
    if record.x is None:
        return None
    seen = ~np.isnan(record.x)
    return nrmse(sim["x"][seen], record.x[seen])


def record_noise(cfg: DictConfig, record: Record) -> float:
    """The measurement-noise level of the record: what its data source drew or was given
    (``noise=null`` lets a source draw it), else the config's, else 0."""
    noise = record.meta.noise
    return float((cfg.get("noise") if noise is None else noise) or 0.0)


def relative_errors(values: dict[str, float], truths: dict[str, float | None]) -> dict[str, float]:
    """|value - truth| / |truth| in %, for the estimated parameters whose truth is known and nonzero."""
    return errors_pct(values, {n: truths.get(n) for n in values})
