"""What a record says of itself beyond its samples: where it came from, how it was sampled and cut,
its channels' layout, its noise, and the views the diagnosis derives from it.

Typed so that a reader finds each fact by name and a misspelt key fails where the record is made,
not where a later step looks it up and finds nothing. A mapping is accepted where a record is built
(``Record(meta={...})``) and checked against these fields."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from pidyn.data.errors import DataError


@dataclass(frozen=True)
class Split:
    """The record's own fitting and held-out time spans (s, record time)."""

    fit: tuple[float, float]
    heldout: tuple[float, float]

    @classmethod
    def at(cls, cut: float, end: float, start: float = 0.0) -> Split:
        """Fit from ``start`` to ``cut``, hold out the rest up to ``end``."""
        return cls((float(start), float(cut)), (float(cut), float(end)))

    @classmethod
    def of(cls, value: Split | Mapping) -> Split:
        if isinstance(value, Split):
            return value
        return cls(tuple(map(float, value["fit"])), tuple(map(float, value["heldout"])))  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, list[float]]:
        return {"fit": list(self.fit), "heldout": list(self.heldout)}


@dataclass(frozen=True)
class Piece:
    """One record of several laid end to end (``pidyn.data.multi``): samples ``i0:i1``, starting
    ``t_offset`` s into the joined record; ``origin`` is what its own record said of itself."""

    name: str
    i0: int
    i1: int
    t_offset: float = 0.0
    origin: RecordMeta | None = None

    @classmethod
    def of(cls, value: Piece | Mapping) -> Piece:
        if isinstance(value, Piece):
            return value
        origin = value.get("meta", value.get("origin"))
        return cls(
            str(value["name"]),
            int(value["i0"]),
            int(value["i1"]),
            float(value.get("t_offset", 0.0)),
            None if origin is None else RecordMeta.of(origin),
        )

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "i0": self.i0, "i1": self.i1, "t_offset": self.t_offset}
        if self.origin is not None:
            out["meta"] = self.origin.to_dict()
        return out


@dataclass(frozen=True)
class Motion:
    """The relative displacement and velocity integrated from measured accelerations, and the drive
    filtered as they are: the weak-form screening's signals."""

    x: np.ndarray
    v: np.ndarray
    f: np.ndarray

    @classmethod
    def of(cls, value: Motion | Mapping) -> Motion:
        if isinstance(value, Motion):
            return value
        return cls(*(np.asarray(value[k], float) for k in ("x", "v", "f")))


@dataclass(frozen=True)
class AccelerometerView:
    """How an accelerometer record was turned into relative motion: the supports' combination
    (``influence``), the nominal model it came with, the high-pass corner and the resonance."""

    influence: dict[str, float] = field(default_factory=dict)
    nominal: dict[str, float] = field(default_factory=dict)
    highpass_hz: float | None = None
    resonance_hz: float | None = None
    note: str = ""
    weights: Any = None
    inputs: list[str] = field(default_factory=list)
    derived: str = "x, v integrated from a"

    @classmethod
    def of(cls, value: AccelerometerView | Mapping) -> AccelerometerView:
        return value if isinstance(value, AccelerometerView) else cls(**dict(value))

    def to_dict(self) -> dict[str, Any]:
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}


@dataclass
class RecordMeta:
    """Every fact a record may carry; ``None`` where its source does not say."""

    # where it came from
    path: str | None = None  # the file or folder read
    source: str | None = None  # a benchmark's citation
    record: str | None = None  # the ground motion a simulation was driven by
    station: str | None = None
    direction: str | None = None
    run: str | None = None  # a shake-table run's label
    event: str | None = None
    paths: list[str] | None = None  # the files of several records joined
    floors: list[str] | None = None  # an IMU set's floor folders
    files: list[str] | None = None
    devices: list[str] | None = None
    align: str | None = None  # how the IMU clocks were aligned
    alignment: Any = None  # pidyn.data.imu.Alignment: what the alignment found
    # how it was sampled and cut
    dt: float | None = None
    fs: float | None = None
    t_offset: float | None = None  # the record's start in its file's time (s)
    span: list[float] | None = None  # the shaking span kept, in file time (s)
    segment: list[float] | None = None  # a segment cut from a longer record (s, record time)
    input_hold: str | None = None  # how the excitation is read between samples (pidyn.integrate)
    acceleration: str | None = None  # "absolute" or "relative" accelerometer outputs
    units: dict[str, str] | None = None
    pga: float | None = None  # the largest input acceleration (m/s^2)
    band_hz: Any = None  # the processed band of the archive's channels
    # noise
    noise: float | None = None  # a simulation's largest noise level (share of each channel's RMS)
    noise_levels: dict[str, float] | None = None
    data_seed: int | None = None
    pre_event_rms: dict[str, Any] | None = None  # the quiet before the shaking, per channel group
    # the channels
    inputs: list[str] | None = None  # the names of several inputs
    excitation_columns: list[str] | None = None
    input_channels: list[int] | None = None
    output_channels: list[int] | None = None
    locations: dict[int, str] | None = None
    sensor_channels: list[int] | None = None  # a deck's channels, read where each stands
    observation: list[list[float]] | None = None  # how those channels read the deck's motions
    sensor_a: np.ndarray | None = None  # their accelerations, beside the deck's end motions
    # the record's own parts
    split: Split | None = None
    pieces: list[Piece] | None = None
    # several records joined: each record's weight in a fit is (the joined spread over its own) to
    # this power (pidyn.refine.problem.record_weights); None: 1, every record by its own spread
    record_weighting: float | None = None
    notes: list[str] = field(default_factory=list)
    # a simulated case with a hidden effect
    hidden_effect: str | None = None
    hidden_params: dict[str, float] | None = None
    seed: int | None = None
    # the accelerometer view the diagnosis derives (pidyn.discrepancy.accelerometers)
    sensor_ground: np.ndarray | None = None
    motion: Motion | None = None
    accelerometers: AccelerometerView | None = None

    def __post_init__(self) -> None:
        if self.split is not None:
            self.split = Split.of(self.split)
        if self.pieces is not None:
            self.pieces = [Piece.of(p) for p in self.pieces]
        if self.motion is not None:
            self.motion = Motion.of(self.motion)
        if self.accelerometers is not None:
            self.accelerometers = AccelerometerView.of(self.accelerometers)
        self.notes = list(self.notes or [])

    @classmethod
    def of(cls, value: RecordMeta | Mapping | None, where: str = "record") -> RecordMeta:
        """A record's metadata from itself, a mapping of its fields, or nothing."""
        if isinstance(value, RecordMeta):
            return value
        value = dict(value or {})
        unknown = sorted(set(value) - NAMES)
        if unknown:
            raise DataError(
                f"{where}: unknown metadata {unknown}; a record's metadata has {', '.join(sorted(NAMES))}"
            )
        return cls(**value)

    def with_(self, **changes: Any) -> RecordMeta:
        """A copy with some fields changed (the record's views share the rest)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self, keys: Iterable[str] | None = None) -> dict[str, Any]:
        """The set fields (or ``keys``, unset ones as None) in JSON's terms."""
        if keys is not None:
            return {k: _plain(getattr(self, k)) for k in keys}
        return {
            f.name: _plain(getattr(self, f.name))
            for f in fields(self)
            if getattr(self, f.name) is not None and not (f.name == "notes" and not self.notes)
        }

    def same_as(self, other: RecordMeta, keys: Iterable[str]) -> list[str]:
        """The ``keys`` on which two records' metadata differ, each with both values."""
        return [
            f"{k} {getattr(other, k)!r} against {getattr(self, k)!r}"
            for k in keys
            if _plain(getattr(self, k)) != _plain(getattr(other, k))
        ]


NAMES = frozenset(f.name for f in fields(RecordMeta))


def _plain(value: Any) -> Any:
    """A value in JSON's terms: typed parts by their own ``to_dict``, arrays as lists."""
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value
