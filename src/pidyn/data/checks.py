"""A record checked before any work: it must carry an excitation and a response, on a time step
that can resolve a structure's vibration, with magnitudes that fit the units it declares.

What is certain is refused by name (a constant excitation, a dead channel, a step of seconds);
what is only likely is said in a warning that names the likely unit, and the run goes on.
"""

from __future__ import annotations

import logging

import numpy as np

from pidyn.data.sources import CHANNEL_KINDS, DataError, Record

log = logging.getLogger(__name__)

#: a sampling step above this cannot resolve structural vibration (Nyquist 1 Hz): certain enough to refuse
MAX_DT_S = 0.5
#: the response's relative acceleration over the ground's, by RMS: about 1-3 on simulated and
#: measured records; beyond these the units are likely wrong (g against m/s^2 is a factor 9.81)
RATIO_HIGH, RATIO_LOW = 8.0, 1.0 / 50.0
G = 9.80665


def record_where(record: Record) -> str:
    """The record as an error names it: its file, else its name."""
    return str(record.meta.path or f"record '{record.name}'")


def check_record(record: Record, system_n_dof: int | None = None) -> list[str]:
    """Refuse a record no identification can use; returns the warnings it logged."""
    where = record_where(record)
    f = np.asarray(record.f, float)
    excitation = f if f.ndim == 1 else f[:, : record.n_inputs]
    if not np.all(np.isfinite(excitation)):
        raise DataError(f"{where}: the excitation has NaN or infinite values")
    if float(np.max(np.std(excitation, axis=0))) == 0.0:
        raise DataError(f"{where}: no excitation (the {record.excitation} excitation is constant)")
    dead = []
    for kind in CHANNEL_KINDS:
        arr = getattr(record, kind)
        if arr is None:
            continue
        for j in range(arr.shape[1]):
            col = arr[:, j]
            if np.all(np.isnan(col)):
                continue
            if float(np.nanstd(col)) == 0.0:
                dead.append(f"{kind}{j + 1}" if arr.shape[1] > 1 else kind)
    if dead:
        raise DataError(
            f"{where}: no response variance in channel(s) {dead} (constant): a dead sensor or an empty "
            "record; remove the column(s)"
        )
    dt = record.dt
    if dt > MAX_DT_S:
        raise DataError(
            f"{where}: a time step of {dt:g} s cannot resolve a structure's vibration; if the time column is "
            "in milliseconds, convert it (data.source.units={t: 0.001})"
        )
    warnings = _unit_warnings(record, where)
    for w in warnings:
        log.warning("%s", w)
    return warnings


def _relative_acceleration(record: Record) -> np.ndarray | None:
    """The response's relative acceleration, from the accelerometers or by differentiating."""
    if record.a is not None:
        return record.a
    if record.v is not None:
        return np.gradient(record.v, record.dt, axis=0)
    if record.x is not None:
        return np.gradient(np.gradient(record.x, record.dt, axis=0), record.dt, axis=0)
    return None


def _unit_warnings(record: Record, where: str) -> list[str]:
    """Magnitudes against the declared units: the excitation against the response it drives."""
    out = []
    dt = record.dt
    if 0.05 < dt <= MAX_DT_S:
        out.append(
            f"{where}: a time step of {dt:g} s is coarse for a structure (Nyquist {0.5 / dt:.3g} Hz); "
            "check that the time column is in seconds"
        )
    if record.excitation != "ground" or record.n_inputs > 1:
        return out
    acc = _relative_acceleration(record)
    if acc is None:
        return out
    rms_f = float(np.sqrt(np.mean(np.square(record.f))))
    rms_a = float(np.sqrt(np.nanmean(np.square(acc))))
    if rms_f <= 0 or not np.isfinite(rms_a):
        return out
    ratio = rms_a / rms_f
    if ratio > RATIO_HIGH:
        out.append(
            f"{where}: the response accelerates {ratio:.3g} times as much as the ground (about 1-3 on "
            f"structures); the ground acceleration may be in g, not m/s^2 (data.source.units={{ag: {G}}}), "
            "or the response in other units than m"
        )
    elif ratio < RATIO_LOW:
        out.append(
            f"{where}: the response accelerates {ratio:.3g} times as much as the ground (about 1-3 on "
            "structures); the ground acceleration may be in cm/s^2 (data.source.units={ag: 0.01}), or the "
            "response in mm (units={x: 0.001})"
        )
    return out


def check_floors(record: Record, system_name: str, n_dof: int, n_outputs: int | None = None) -> None:
    """A record's floors against the model's: a building CSV with columns for more floors than the
    model has is refused by name, not met by an index error later."""
    floors = {k: v for k, v in record.sensors().items() if v}
    top = max((max(v) for v in floors.values()), default=0)
    limit = n_outputs if n_outputs is not None else n_dof
    if top > limit:
        cols = ", ".join(f"{k}{top}" for k, v in floors.items() if top in v)
        raise DataError(
            f"{record_where(record)}: channel(s) {cols} of floor {top}, but system '{system_name}' has {limit} "
            f"floor(s); set system.n_storeys={top} or drop the columns above floor {limit}"
        )
