"""Where a bridge's sensors and supports stand along its deck, and how its deck channels become
the rigid deck's two end motions.

A station's layout (``stations.yaml``, or ``system.layout`` for a station the file does not
describe) gives the deck's length and each channel's position along it, in metres from the
deck's first end. ``station_deck`` builds a ``RigidDeck`` from it for one direction's channel
set. The strong-motion reader then keeps every deck channel and reads the two end motions from
them by least squares: fitting the end motions with the weight H^T H is fitting every channel
(the part of the channels no rigid deck can move, orthogonal to H's columns, is the same for
every model), and ``sensor_view`` gives the channels back, measured and modelled, so that a
prediction is scored channel by channel.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from pidyn.data.errors import DataError
from pidyn.data.stations import station_entry, station_layout
from pidyn.systems import LinearSDOF
from pidyn.systems.deck import RigidDeck, sensor_row


def station_deck(
    station: str | None,
    direction: str = "transverse",
    layout: Mapping[str, Any] | None = None,
    inputs: list[int] | None = None,
    outputs: list[int] | None = None,
    **kwargs: Any,
) -> Any:
    """A rigid deck on a station's supports for one direction's channel set (``stations.yaml``):
    one support per input channel, read where each stands; the outputs are its deck sensors.
    Along the deck, one translation on the supports."""
    if inputs is None or outputs is None:
        sets = (station_entry(station).get("directions") or {}).get(direction) or {}
        inputs = inputs if inputs is not None else sets.get("inputs")
        outputs = outputs if outputs is not None else sets.get("outputs")
    if not inputs or not outputs:
        raise DataError(
            f"station {station}: no channel set for '{direction}'; give data.inputs and data.outputs"
        )
    if direction != "transverse":
        return _along(inputs, direction, **kwargs)
    lay = station_layout(station, layout)
    missing = [c for c in [*inputs, *outputs] if int(c) not in lay["positions"]]
    if missing:
        raise DataError(f"station {station}: the layout gives no position for channel(s) {missing}")
    return RigidDeck(
        inputs=[f"ch{c}" for c in inputs],
        positions=[lay["positions"][int(c)] for c in inputs],
        length=lay["length"],
        sensors={f"ch{c}": lay["positions"][int(c)] for c in outputs},
        **kwargs,
    )


def _along(inputs: list[int], direction: str, **kwargs: Any) -> Any:
    """Along the deck (longitudinal) a deck rigid in its plane only translates: every deck channel
    reads one motion, a single degree of freedom on the supports (``SDOFSystem`` with inputs)."""
    if kwargs.get("support_terms"):
        raise DataError(
            f"system=rigid_deck: support_terms act on the deck's supports across it, not '{direction}'"
        )
    k = kwargs.get("stiffnesses", 200.0)
    c = kwargs.get("dampings", 1.0)
    k = float(np.sum(k)) * (len(inputs) if np.ndim(k) == 0 else 1)
    c = float(np.sum(c)) * (len(inputs) if np.ndim(c) == 0 else 1)
    return LinearSDOF(
        c=c,
        k=k,
        inputs=[f"ch{i}" for i in inputs],
        params=kwargs.get("params"),
        name="rigid_deck_longitudinal",
    )


def observation(system: Any, channels: list[int]) -> np.ndarray | None:
    """H (channels x 2): how each deck channel reads the deck's end motions; None for a model
    without a sensor layout (its outputs are its degrees of freedom)."""
    sensors = getattr(system, "sensors", None)
    if not sensors:
        return None
    missing = [c for c in channels if f"ch{c}" not in sensors]
    if missing:
        raise DataError(
            f"{system.name}: output channel(s) {missing} have no position on the deck; the layout gives "
            f"{sorted(sensors)}"
        )
    H = np.array([sensor_row(sensors[f"ch{c}"], system.length) for c in channels])
    if np.linalg.matrix_rank(H) < H.shape[1]:
        raise DataError(
            f"{system.name}: the deck channels {channels} stand at one position; they cannot tell the "
            "deck's translation from its rotation"
        )
    return H


def end_motions(a: np.ndarray, H: np.ndarray) -> np.ndarray:
    """The deck's end accelerations (N, 2) that best explain the channels ``a`` (N, n) by least squares."""
    return a @ np.linalg.pinv(H).T


def sensor_view(record, sim: dict[str, np.ndarray]) -> tuple[Any, dict[str, np.ndarray]]:
    """The record and a simulation of it channel by channel where the record was read through a
    deck layout (``meta.observation``); unchanged otherwise."""
    meta = record.meta
    H, raw = meta.observation, meta.sensor_a
    if H is None or raw is None:
        return record, sim
    H, raw = np.asarray(H, float), np.asarray(raw, float)
    if len(raw) != len(record.t):
        raise DataError(f"record '{record.name}': its deck channels and its samples differ in length")
    channels = list(meta.sensor_channels or [])
    view = replace(record, a=raw, x=None, v=None, meta=meta.with_(output_channels=channels))
    out = {k: v for k, v in sim.items() if k not in ("x", "v", "a")}
    if "a" in sim:
        out["a"] = np.asarray(sim["a"], float) @ H.T
    return view, out


def read_where_they_stand(record, system: RigidDeck, noise: float = 0.0, seed: int = 0):
    """A simulated deck record (its two end motions, absolute) as its deck sensors read it: each
    channel of ``system.sensors`` at its position, with white noise of ``noise`` times the
    channel's RMS, and the end motions read back from them by least squares, as a strong-motion
    archive is read. What a test or a benchmark hides an effect at a support in."""
    names = sorted(system.sensors, key=lambda c: int(str(c).lstrip("ch")))
    channels = [int(str(c).lstrip("ch")) for c in names]
    H = observation(system, channels)
    clean = np.asarray(record.a, float) @ H.T
    rng = np.random.default_rng(seed)
    raw = clean + noise * np.sqrt(np.mean(clean**2, axis=0)) * rng.standard_normal(clean.shape)
    meta = record.meta.with_(
        sensor_channels=channels, observation=H.tolist(), sensor_a=raw, output_channels=[]
    )
    return replace(record, a=end_motions(raw, H), x=None, v=None, meta=meta)
