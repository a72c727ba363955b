"""Several records of one structure as one record: the pieces follow each other on one time axis.

A structure identified from several earthquakes shares its parameters across them; each record
keeps its own initial state. Laid end to end, the records go through every stage of a run as one
record, and ``meta.pieces`` says where each begins. Whatever simulates over a junction starts
the next record from rest (``pidyn.integrate.piece_starts``), the shooting segments and PIDynNet's windows end
there, and a continuity defect never joins two records.

The fitting part is every record but the last one's held-out share (when the records have a
split): the held-out part is the end of the last record, as it is for one record.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from pidyn.data.errors import DataError
from pidyn.data.meta import Piece, RecordMeta, Split
from pidyn.simulate import Trajectory

#: metadata that must agree between the records of one structure (the channel map and its units)
SAME = (
    "station",
    "direction",
    "input_channels",
    "output_channels",
    "sensor_channels",
    "acceleration",
    "units",
    "input_hold",
)


def pieces(record) -> list[Piece]:
    """The records a record is made of (samples i0 <= i < i1); one piece for a plain record."""
    return list(record.meta.pieces or [Piece(record.name, 0, len(record.t))])


def concatenate(records: Sequence, name: str | None = None, weighting: float | None = None):
    """One record from several of one structure (same step, channels, inputs and units).
    ``weighting``: how a fit weighs the records (``RecordMeta.record_weighting``; None keeps the
    first record's, by default every record by its own spread)."""
    records = list(records)
    weighting = check_weighting(weighting)
    if not records:
        raise DataError("no record to identify from (data.paths or data.runs is empty)")
    if len(records) == 1:
        return records[0]
    first = records[0]
    dt = first.dt
    for r in records[1:]:
        _check_alike(first, r, dt)
    t_parts, offset, out_pieces = [], 0.0, []
    n = 0
    for r in records:
        local = r.t - r.t[0]
        t_parts.append(local + offset)
        out_pieces.append(Piece(r.name, n, n + len(r.t), offset, _origin(r.meta)))
        n += len(r.t)
        offset = float(t_parts[-1][-1]) + dt
    t = np.concatenate(t_parts)
    cat = lambda k: None if getattr(first, k) is None else np.concatenate([getattr(r, k) for r in records])  # noqa: E731
    meta = first.meta.with_(
        pieces=out_pieces,
        # a deck's channels, kept beside its end motions (pidyn.data.layout)
        sensor_a=None
        if first.meta.sensor_a is None
        else np.concatenate([np.asarray(r.meta.sensor_a) for r in records]),
        paths=[r.meta.path or r.name for r in records],
        notes=[f"{r.name}: {text}" for r in records for text in r.meta.notes],
        pga=None if first.meta.pga is None else max(float(r.meta.pga or 0.0) for r in records),
        split=_joined_split(records, out_pieces[-1], t),
        record_weighting=first.meta.record_weighting if weighting is None else weighting,
        path=None,
        span=None,
    )
    return replace(
        first,
        name=name or "+".join(r.name for r in records),
        t=t,
        f=np.concatenate([r.f for r in records]),
        x=cat("x"),
        v=cat("v"),
        a=cat("a"),
        clean=_joined_clean(records, t),
        meta=meta,
    )


def _joined_clean(records: list, t: np.ndarray) -> Trajectory | None:
    """The records' noise-free trajectories laid end to end (a simulation's truth), if all have one."""
    if not all(r.clean is not None for r in records):
        return None
    c = [r.clean for r in records]
    return Trajectory(
        t=t,
        x=np.concatenate([ci.x for ci in c]),
        v=np.concatenate([ci.v for ci in c]),
        a=np.concatenate([ci.a for ci in c]),
        f=np.concatenate([ci.f for ci in c]),
        z=None if c[0].z is None else np.concatenate([ci.z for ci in c]),
    )


def check_weighting(weighting: float | None) -> float | None:
    """``data.record_weighting``: a number from 0 (the joined spread, the strongest record weighs
    most) to 1 (each record its own spread), or None."""
    if weighting is None:
        return None
    try:
        value = float(weighting)
    except (TypeError, ValueError):
        value = float("nan")
    if not (0.0 <= value <= 1.0):
        raise DataError(
            f"data.record_weighting must be a number from 0 to 1 (1: every record by its own spread, "
            f"0: by the records' joined spread), got {weighting!r}"
        )
    return value


def split(record) -> list:
    """The records a record of several is made of (``pieces``), each by itself again: its own
    time from 0 and its own metadata. A plain record: itself."""
    parts = pieces(record)
    if len(parts) == 1:
        return [record]
    out = []
    for p in parts:
        sl = slice(p.i0, p.i1)
        origin = p.origin or RecordMeta()
        meta = record.meta.with_(
            pieces=None,
            sensor_a=None if record.meta.sensor_a is None else np.asarray(record.meta.sensor_a)[sl],
            paths=None,
            notes=[],
            pga=origin.pga,
            split=None,
            path=origin.path,
            span=origin.span,
            t_offset=origin.t_offset,
            event=origin.event,
            run=origin.run,
        )
        cut = lambda a: None if a is None else a[sl]  # noqa: E731
        out.append(
            replace(
                record,
                name=p.name,
                t=record.t[sl] - p.t_offset,
                f=record.f[sl],
                x=cut(record.x),
                v=cut(record.v),
                a=cut(record.a),
                clean=None,
                meta=meta,
            )
        )
    return out


def _joined_split(records: list, last: Piece, t: np.ndarray) -> Split | None:
    """The fitting part of records laid end to end: all but the last one's held-out share."""
    split = records[-1].meta.split
    if not (split and all(r.meta.split for r in records)):
        return None
    cut = last.t_offset + split.fit[1] - float(records[-1].t[0])
    return Split.at(cut, float(t[-1]), float(t[0]))


def _origin(meta: RecordMeta) -> RecordMeta:
    """What a piece keeps of its own record's metadata (where it came from, its shaking)."""
    return RecordMeta(
        path=meta.path, t_offset=meta.t_offset, span=meta.span, pga=meta.pga, run=meta.run, event=meta.event
    )


def _check_alike(first, other, dt: float) -> None:
    """Records of one structure: one step, one channel map, the same excitation and truth."""
    problems = []
    if abs(other.dt - dt) > 1e-9 * max(dt, 1.0):
        problems.append(f"time step {other.dt:g} s against {dt:g} s (set data.dt to resample)")
    if other.excitation != first.excitation:
        problems.append(f"{other.excitation} excitation against {first.excitation}")
    if other.n_inputs != first.n_inputs or other.inputs != first.inputs:
        problems.append(f"inputs {other.inputs or other.n_inputs} against {first.inputs or first.n_inputs}")
    if other.sensors() != first.sensors():
        problems.append(f"channels {other.sensors()} against {first.sensors()}")
    problems += first.meta.same_as(other.meta, SAME)
    if (first.truth or None) != (other.truth or None):
        problems.append("another true structure")
    if problems:
        raise DataError(
            f"record '{other.name}' does not match '{first.name}' ({'; '.join(problems)}): "
            "the records of one identification must measure one structure the same way"
        )
