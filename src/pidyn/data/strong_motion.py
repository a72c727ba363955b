"""A strong-motion archive as a record: a station's input (support) and output (structure)
channels, aligned, resampled and cut to the shaking.

    python train.py data=csmip data.path=FILE.zip data.station=CE89324 data.direction=transverse

The channel sets of a station come from ``stations.yaml`` beside the shipped records (the
station is read from the files when not given); ``data.inputs=[...] data.outputs=[...]``
choose any others. What is done to the data, each step said in the record's ``meta``:

* **two recorders' clocks** (film records): the headers give each recorder's trigger time to
  0.1 s only, so a further recorder whose offset, read from the supports' ground motions, is at
  least a sample has its channels shifted onto the reference recorder's clock
  (``pidyn.data.clocks``; ``one_clock=False`` keeps each recorder's own);
* **channels of different lengths** (film records: the recorders stop apart) are cut to the
  shortest; different steps are refused;
* **missing channels** end in ``MissingChannelError`` naming them, or with ``on_missing=drop``
  are left out (and said so); an event left without an input or an output is refused;
* **resampling** to ``dt`` (0.02 s, 50 Hz: ten samples a period up to 5 Hz) by zero-phase
  polyphase filtering; a record already that coarse is kept as it is;
* **the span** around the shaking: from ``pre`` seconds before 0.5 % of the inputs' Arias
  intensity to ``post`` seconds after 99.5 %; the pre-event part's RMS (the sensors' noise) is
  kept in ``meta.pre_event_rms``; ``span=[t0, t1]`` (s, file time) overrides it;
* **units**: SI (the V2 files' cm/s^2 times 0.01).

With several inputs the record keeps absolute accelerations (there is no single ground to
subtract); with one, the convention of every record: relative to it.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from dataclasses import replace
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import resample_poly

from pidyn.data.clocks import recorder_offsets, shifted
from pidyn.data.csmip import Archive, CsmipFormatError, MissingChannelError, read_archive
from pidyn.data.layout import end_motions, observation
from pidyn.data.meta import RecordMeta, Split
from pidyn.data.sources import READERS, DataError, Record, checked_hold
from pidyn.data.stations import STATIONS_FILE, station_number, stations
from pidyn.notes import note
from pidyn.signals import integrate

log = logging.getLogger(__name__)


def channel_sets(
    station: str | None,
    direction: str,
    inputs: Sequence[int] | None,
    outputs: Sequence[int] | None,
    archive: Archive,
) -> tuple[str, list[int], list[int]]:
    """(station, inputs, outputs): the given channels, else the station's set for ``direction``."""
    found = _station_of(archive)
    if station is None:
        station = found
    elif found is not None and station_number(found) != station_number(station):
        raise DataError(
            f"{archive.path.name}: the files are of station {found}, not data.station={station}; "
            f"give data.station={found} (with its channel sets) or the archive of {station}"
        )
    if inputs is not None and outputs is not None:
        return station or "", [int(c) for c in inputs], [int(c) for c in outputs]
    known = stations()
    if station not in known:
        raise DataError(
            f"{archive.path.name}: station '{station}' has no channel sets in {STATIONS_FILE} (known: "
            f"{sorted(known)}); give data.inputs=[...] and data.outputs=[...]"
        )
    sets = known[station].get("directions", {})
    if direction not in sets:
        raise DataError(
            f"{archive.path.name}: station {station} has no direction '{direction}'; choose from "
            f"{sorted(sets)}"
        )
    ins = [int(c) for c in (inputs if inputs is not None else sets[direction]["inputs"])]
    outs = [int(c) for c in (outputs if outputs is not None else sets[direction]["outputs"])]
    return station, ins, outs


def _station_of(archive: Archive) -> str | None:
    """``CE<number>`` from the files' ``Station No.`` line (CSMIP's network code is CE)."""
    for ch in archive.channels.values():
        for line in ch.header:
            m = re.search(r"station\s+no\.?\s*(\d+)", line, re.IGNORECASE)
            if m:
                return f"CE{int(m.group(1))}"
    return None


def csmip_record(
    path: str | Path | None,
    station: str | None = None,
    direction: str = "transverse",
    inputs: Sequence[int] | None = None,
    outputs: Sequence[int] | None = None,
    on_missing: str = "error",
    dt: float | None = 0.02,
    span: Sequence[float] | None = None,
    pre: float = 2.0,
    post: float = 5.0,
    max_outputs: int | None = None,
    fit_share: float = 0.65,
    system=None,
    input_hold: str = "linear",
    one_clock: bool = True,
) -> Record:
    """The record of one event at one station (see the module's docstring).

    ``max_outputs``: keep the first this many outputs (default: the model's degrees of freedom
    when ``system`` is given, which the train task passes). ``fit_share``: the first share is
    fitted, the rest held out (``meta.split``). ``input_hold``: how models read the inputs
    between samples (``pidyn.integrate``). ``one_clock``: the module's docstring."""
    if not 0.1 <= fit_share <= 0.95:
        raise DataError(f"data.fit_share must lie in [0.1, 0.95], got {fit_share}")
    archive, station, ins, outs, notes = _channels_used(
        path, station, direction, inputs, outputs, on_missing, _output_limit(system, max_outputs)
    )
    clocks = _clock_groups(station, ins) if one_clock else None  # the supports that read the clocks
    acc_in, vel_in, acc_out, step = _aligned_channels(archive, ins, outs, dt, notes, clocks)
    i0, i1, pre_rms = shaking_span(acc_in, acc_out, step, span, pre, post)
    t = np.arange(i1 - i0) * step
    a = acc_out[i0:i1]
    if several := len(ins) > 1:  # supports' accelerations, then velocities (for their dashpots)
        f = np.concatenate([acc_in[i0:i1], vel_in[i0:i1]], axis=1)
    else:
        f = acc_in[i0:i1, 0]
        a = a - f[:, None]  # one ground: accelerations relative to it, as every record keeps them
    a, deck = _read_through(system, outs, a)
    for text in notes:
        log.info("%s: %s", archive.path.name, text)
    meta = RecordMeta(
        path=str(path),
        station=station,
        direction=direction,
        # a deck read where each channel stands scores its channels, not its end motions
        **{**_channel_meta(archive, ins, outs, several), **deck},
        dt=step,
        t_offset=i0 * step,
        span=[i0 * step, (i1 - 1) * step],
        pre_event_rms=pre_rms,
        notes=notes,
        acceleration="absolute" if several else "relative",
        units={"a": "m/s^2", "ag": "m/s^2"},
        pga=float(np.max(np.abs(acc_in[i0:i1]))),
        input_hold=checked_hold(input_hold, "data.input_hold"),
        split=Split.at(float(t[-1]) * fit_share, float(t[-1])),
    )
    name = Path(path).name.split(".")[0]
    return Record(name=name, t=t, f=f, a=a, excitation="ground", meta=meta)


READERS["csmip"] = csmip_record


def _output_limit(system, max_outputs: int | None) -> int | None:
    """How many outputs a model keeps: as many as it has degrees of freedom, or every channel of a
    deck read where each stands."""
    if max_outputs is not None or system is None:
        return max_outputs
    return None if getattr(system, "sensors", None) else getattr(system, "n_outputs", system.n_dof)


def _read_through(system, outs: list[int], a: np.ndarray) -> tuple[np.ndarray, dict]:
    """The outputs as the model's degrees of freedom read them: a deck's end motions from its
    channels by least squares (the channels kept in the metadata for scoring,
    ``pidyn.data.layout``), else the channels themselves."""
    H = observation(system, outs) if system is not None else None
    if H is None:
        return _unmeasured_columns(a, system), {}
    meta = {
        "sensor_channels": outs,
        "observation": H.tolist(),
        "sensor_a": a,
        "output_channels": [],
    }  # RecordMeta's fields
    return end_motions(a, H), meta


def _unmeasured_columns(a: np.ndarray, system) -> np.ndarray:
    """A modal model's further degrees of freedom are modes no sensor reads on its own: NaN columns."""
    if system is None or not hasattr(system, "n_outputs") or a.shape[1] >= system.n_dof:
        return a
    return np.concatenate([a, np.full((len(a), system.n_dof - a.shape[1]), np.nan)], axis=1)


def _channels_used(
    path: str | Path | None,
    station: str | None,
    direction: str,
    inputs: Sequence[int] | None,
    outputs: Sequence[int] | None,
    on_missing: str,
    limit: int | None,
) -> tuple[Any, str, list[int], list[int], list[str]]:
    """The archive, its station and the input and output channels used (at most ``limit``
    outputs), with notes on what was left out."""
    if path is None:
        raise DataError(
            "no archive: set data.path=FILE.zip (one event) or 'data.paths=[A.zip,B.zip]' (several)"
        )
    if on_missing not in ("error", "drop"):
        raise DataError(f"data.on_missing must be 'error' or 'drop', got '{on_missing}'")
    archive = read_archive(path)
    station, ins, outs = channel_sets(station, direction, inputs, outputs, archive)
    notes: list[str] = []
    ins = _present(archive, ins, "input", on_missing, notes)
    outs = _present(archive, outs, "output", on_missing, notes)
    if limit is not None and len(outs) > limit:
        notes.append(
            note(
                "outputs_unused",
                f"outputs {outs[limit:]} not used: the model has {limit} degree(s) of freedom",
            )
        )
        outs = outs[:limit]
    return archive, station, ins, outs, notes


def _channel_meta(archive, ins: list[int], outs: list[int], several: bool) -> dict:
    """What the record's metadata says of its channels: names, columns, band, locations."""
    names = [f"ch{c}" for c in ins]
    return {
        "inputs": names if several else [],
        "excitation_columns": ([f"ag_{c}" for c in names] + [f"vg_{c}" for c in names])
        if several
        else ["ag"],
        "input_channels": ins,
        "output_channels": outs,
        "band_hz": archive.channels[outs[0]].band_hz,
        "locations": {c: archive.channels[c].location for c in ins + outs},
    }


def _aligned_channels(
    archive,
    ins: list[int],
    outs: list[int],
    dt: float | None,
    notes: list[str],
    clock_groups: list[list[int]] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The inputs' accelerations and velocities and the outputs' accelerations on one time grid:
    one sampling step, the recorders on one clock (``clock_groups``: the supports' channel sets
    whose ground motions tell the recorders' offsets, ``pidyn.data.clocks``; None leaves each
    recorder's own), cut to the shortest channel, resampled to ``dt``."""
    chans = [archive.channels[c] for c in ins + outs]
    steps = {round(c.dt, 9) for c in chans}
    if len(steps) > 1:
        raise CsmipFormatError(f"{archive.path.name}: channels sampled at different steps {sorted(steps)} s")
    step = chans[0].dt
    archive = _on_one_clock(archive, ins + outs, clock_groups, notes)
    n = min(c.n for c in chans)
    if any(c.n != n for c in chans):
        lengths = {c.station_channel: c.n for c in chans}
        notes.append(
            note(
                "cut_to_shortest",
                f"channels of different lengths {lengths} (two recorders): cut to the shortest, {n} samples "
                f"({(n - 1) * step:.3g} s)",
            )
        )
    acc_in = np.stack([archive.channels[c].acc[:n] for c in ins], axis=1)
    acc_out = np.stack([archive.channels[c].acc[:n] for c in outs], axis=1)
    vel_in = _velocities(archive, ins, n, step, acc_in, notes)
    acc_in, acc_out, step = _resample(np.concatenate([acc_in, vel_in], axis=1), acc_out, step, dt, notes)
    return acc_in[:, : len(ins)], acc_in[:, len(ins) :], acc_out, step


def _on_one_clock(archive, used: list[int], groups: list[list[int]] | None, notes: list[str]):
    """The archive with the used channels of each further recorder shifted onto the reference
    recorder's clock (``pidyn.data.clocks``); the archive itself where nothing moves."""
    if not groups:
        return archive
    offsets, said = recorder_offsets(archive, groups, used)
    notes.extend(said)
    if not offsets:
        return archive
    late = {o.recorder: o.seconds for o in offsets}
    moved = dict(archive.channels)
    for c in used:
        ch = archive.channels[c]
        if ch.recorder in late:
            back = -late[ch.recorder]
            vel = None if ch.vel is None else shifted(ch.vel, back, ch.dt)
            moved[c] = replace(ch, acc=shifted(ch.acc, back, ch.dt), vel=vel)
    return replace(archive, channels=moved)


def _clock_groups(station: str, ins: list[int]) -> list[list[int]]:
    """The supports' channel sets whose ground motions tell the recorders' clocks apart: every
    direction's of the station (the clocks are the record's, not a direction's), and the inputs used."""
    sets = stations().get(station, {}).get("directions", {})
    groups = [[int(c) for c in s["inputs"]] for s in sets.values()]
    return groups if ins in groups else [*groups, ins]


def _velocities(
    archive: Archive, ins: list[int], n: int, step: float, acc: np.ndarray, notes: list[str]
) -> np.ndarray:
    """The supports' velocities as the V2 files give them (integrated and band-passed with the
    accelerations by the processing); integrated here (spectrally, above 0.05 Hz) where a file has none."""
    cols = []
    for j, c in enumerate(ins):
        vel = archive.channels[c].vel
        if vel is None:
            notes.append(
                note(
                    "velocity_integrated", f"channel {c}: no velocity block; integrated from its acceleration"
                )
            )
            vel = integrate(acc[:, j], step, 1, 0.05)
        cols.append(np.asarray(vel[:n], float))
    return np.stack(cols, axis=1)


def _present(archive: Archive, chans: list[int], what: str, on_missing: str, notes: list[str]) -> list[int]:
    missing = [c for c in chans if c not in archive.channels]
    if missing and on_missing == "error":
        archive.require(chans, what)
    kept = [c for c in chans if c in archive.channels]
    if not kept:
        raise MissingChannelError(
            f"{archive.path.name}: none of the {what} channels {chans} is in this archive "
            f"(it holds {sorted(archive.channels)})"
        )
    if missing:
        notes.append(
            note(
                "channel_missing",
                f"{what} channel(s) {missing} missing in this event: left out (data.on_missing=drop)",
            )
        )
    return kept


def _resample(
    acc_in: np.ndarray, acc_out: np.ndarray, step: float, dt: float | None, notes: list[str]
) -> tuple[np.ndarray, np.ndarray, float]:
    """Down to ``dt`` by zero-phase polyphase filtering (an integer or simple rational ratio)."""
    if dt is None or dt <= step * (1 + 1e-9):
        return acc_in, acc_out, step

    ratio = Fraction(dt / step).limit_denominator(16)
    if abs(float(ratio) - dt / step) > 1e-6 * dt / step:
        raise DataError(f"cannot resample a step of {step} s to {dt} s (ratio {dt / step:g} not rational)")
    up, down = ratio.denominator, ratio.numerator
    notes.append(note("resampled", f"resampled from {step:g} s to {dt:g} s (polyphase, zero phase)"))
    return (resample_poly(acc_in, up, down, axis=0), resample_poly(acc_out, up, down, axis=0), float(dt))


def shaking_span(
    acc_in: np.ndarray,
    acc_out: np.ndarray,
    step: float,
    span: Sequence[float] | None,
    pre: float,
    post: float,
) -> tuple[int, int, dict[str, float]]:
    """Sample range [i0, i1) of the shaking, and the RMS of what comes before it per channel."""
    n = acc_in.shape[0]
    if span is not None:
        t0, t1 = float(span[0]), float(span[1])
        if not 0 <= t0 < t1:
            raise DataError(f"data.span must be [t0, t1] with 0 <= t0 < t1, got {list(span)}")
        i0, i1 = int(round(t0 / step)), min(n, int(round(t1 / step)) + 1)
    else:
        e = np.sum(acc_in**2, axis=1)
        cum = np.cumsum(e) / max(float(np.sum(e)), 1e-300)
        i0 = max(0, int(np.searchsorted(cum, 0.005)) - int(round(pre / step)))
        i1 = min(n, int(np.searchsorted(cum, 0.995)) + int(round(post / step)) + 1)
    if i1 - i0 < 50:
        raise DataError(f"the span holds only {i1 - i0} samples")
    pre_rms = {}
    if i0 >= int(round(1.0 / step)):  # at least a second before the shaking: the sensors' noise
        both = np.concatenate([acc_in, acc_out], axis=1)
        pre_rms = {
            "inputs": np.sqrt(np.mean(acc_in[:i0] ** 2, axis=0)).tolist(),
            "outputs": np.sqrt(np.mean(acc_out[:i0] ** 2, axis=0)).tolist(),
            "share_of_peak": float(np.sqrt(np.mean(both[:i0] ** 2)) / max(np.max(np.abs(both)), 1e-300)),
        }
    return i0, i1, pre_rms
