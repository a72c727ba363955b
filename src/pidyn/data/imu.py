"""Wearable inertial sensors (Xsens DOT) on a shake-table model: one file per floor per run, read,
aligned and turned into a building record.

A model's folder holds one subfolder per floor (``Ground Floor`` for the table, then ``1st Floor``,
``2nd Floor``, ..., ``3rd Floor (Top floor)``, or ``Top Floor`` for a one-storey model); a run's
file in each starts with its label in parentheses, ``(Northridge)Xsens DOT_...csv.gz``. Each
file: six preamble lines (``DeviceTag``, ``FirmwareVersion``, ``AppVersion``, ``StartTime`` to
the second), then ``PacketCounter, SampleTimeFine, Euler_X..Z, Acc_X..Z, Gyr_X..Z``, the first row
all zeros but the counters. What is done, each step said in the record's ``meta``:

* **time**: ``SampleTimeFine`` (microseconds, wrapping at 2^32) unwrapped; a file whose step
  is not the nominal 1/120 s or whose time does not increase is refused, a dropped packet is
  filled by interpolation and counted;
* **the shaking axis**: gravity is each sensor's mean acceleration (the model stands still
  before and after), its direction is removed, and the principal direction of what is left is
  the axis the table shakes along; each floor's sign follows the table's (positive correlation);
  the tilt of each sensor from vertical is reported;
* **clocks**: the sensors share the app's clock when synchronised, so ``SampleTimeFine`` gives
  each file's offset; the offset is checked by cross-correlating the floor's shaking with the
  table's within a few samples (a structure lags its table by a fraction of its period, the
  peak is found by a parabola through the top three lags), and both lags are reported; the
  records are put on the table's time grid by interpolation;
* **bias**: the mean over the first second (the model at rest) is taken off each axis.
"""

from __future__ import annotations

import datetime as _dt
import gzip
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pidyn.data.meta import RecordMeta, Split
from pidyn.data.sources import READERS, DataError, Record, checked_hold
from pidyn.data.strong_motion import _resample, shaking_span
from pidyn.notes import note
from pidyn.signals import lagged_correlation, peak_fraction

NOMINAL_STEP_US = 1e6 / 120.0
COLUMNS = (
    "PacketCounter",
    "SampleTimeFine",
    "Euler_X",
    "Euler_Y",
    "Euler_Z",
    "Acc_X",
    "Acc_Y",
    "Acc_Z",
    "Gyr_X",
    "Gyr_Y",
    "Gyr_Z",
)
_ORDINAL = re.compile(r"^(\d+)(st|nd|rd|th)\s+floor", re.IGNORECASE)


class ImuFormatError(DataError):
    """An IMU file or folder that cannot be read; the message names it and the problem."""


@dataclass
class ImuFile:
    """One sensor's record: time (s, from its own first sample, on its own clock), the clock's first
    value (us), and acceleration (m/s^2, gravity included) in the sensor's frame."""

    path: Path
    device: str
    start_time: str
    t: np.ndarray
    clock0_us: float
    acc: np.ndarray
    gaps_filled: int = 0


def uniform_samples(
    path: Path, clock: np.ndarray, acc: np.ndarray, first: int
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Times (s from the first sample), accelerations on the 120 Hz grid, the first clock reading
    (us) and the dropped packets filled; a clock that stalls or runs at another rate is refused."""
    clock = np.unwrap(clock, period=2.0**32)  # SampleTimeFine wraps at 2^32 us
    step = np.diff(clock)
    if np.any(step <= 0):
        raise ImuFormatError(
            f"{path}: SampleTimeFine does not increase at data row {int(np.flatnonzero(step <= 0)[0]) + first + 2}"
        )
    nominal = float(np.median(step))
    if abs(nominal - NOMINAL_STEP_US) > 0.02 * NOMINAL_STEP_US:
        raise ImuFormatError(
            f"{path}: a step of {nominal:.0f} us; an Xsens DOT records at 120 Hz ({NOMINAL_STEP_US:.0f} us)"
        )
    gaps = int(np.sum(np.round(step / nominal) - 1))
    t = (clock - clock[0]) * 1e-6
    if gaps:  # dropped packets: onto the uniform grid
        grid = np.arange(0.0, t[-1] + 0.5 * nominal * 1e-6, nominal * 1e-6)
        acc = np.stack([np.interp(grid, t, acc[:, j]) for j in range(3)], axis=1)
        t = grid
    return t, acc, float(clock[0]), max(gaps, 0)


def read_xsens(path: str | Path) -> ImuFile:
    """An Xsens DOT CSV export (``.csv`` or ``.csv.gz``)."""
    path = Path(path)
    if not path.is_file():
        raise ImuFormatError(f"{path}: no such file")
    try:
        raw = gzip.open(path, "rt").read() if path.suffix == ".gz" else path.read_text()
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise ImuFormatError(f"{path}: cannot be read ({exc})") from None
    lines = raw.splitlines()
    head = next((i for i, ln in enumerate(lines[:20]) if ln.startswith("PacketCounter")), None)
    if head is None:
        raise ImuFormatError(f"{path}: no 'PacketCounter,SampleTimeFine,...' header in its first 20 lines")
    meta = {
        ln.split(",")[0].strip().rstrip(":"): ",".join(ln.split(",")[1:]).strip()
        for ln in lines[:head]
        if "," in ln
    }
    try:
        df = pd.read_csv(io.StringIO("\n".join(lines[head:])))
    except Exception as exc:  # pandas raises many types for a malformed table
        raise ImuFormatError(f"{path}: the table cannot be read ({exc})") from None
    missing = [c for c in ("SampleTimeFine", "Acc_X", "Acc_Y", "Acc_Z") if c not in df.columns]
    if missing:
        raise ImuFormatError(f"{path}: missing column(s) {missing} (columns: {list(df.columns)})")
    num = df[["SampleTimeFine", "Acc_X", "Acc_Y", "Acc_Z"]].apply(
        pd.to_numeric, errors="coerce"
    )  # text: NaN, named below
    acc = num[["Acc_X", "Acc_Y", "Acc_Z"]].to_numpy(float)
    clock = num["SampleTimeFine"].to_numpy(float)
    first = 1 if len(acc) and not np.any(acc[0]) else 0  # the first row: counters only
    acc, clock = acc[first:], clock[first:]
    if len(acc) < 240:
        raise ImuFormatError(f"{path}: only {len(acc)} samples (two seconds at 120 Hz at least)")
    bad = ~np.all(np.isfinite(acc), axis=1) | ~np.isfinite(clock)
    if bad.any():
        raise ImuFormatError(
            f"{path}: {int(bad.sum())} row(s) with missing or non-numeric accelerations or times, first at "
            f"data row {int(np.flatnonzero(bad)[0]) + first + 1}"
        )
    t, acc, clock0, gaps = uniform_samples(path, clock, acc, first)
    return ImuFile(
        path=path,
        device=meta.get("DeviceTag", ""),
        start_time=meta.get("StartTime", ""),
        t=t,
        clock0_us=clock0,
        acc=acc,
        gaps_filled=gaps,
    )


def floor_folders(folder: str | Path) -> list[tuple[int, Path]]:
    """(floor number, folder): 0 for ``Ground Floor`` (the table), ``1st Floor`` -> 1 ...; ``Top Floor``
    is the storey above the highest numbered one."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ImuFormatError(f"{folder}: no such folder (a model's folder holds one subfolder per floor)")
    out: list[tuple[int, Path]] = []
    top = None
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()):
        name = sub.name.lower()
        m = _ORDINAL.match(sub.name)
        if name.startswith("ground"):
            out.append((0, sub))
        elif m:
            out.append((int(m.group(1)), sub))
        elif name.startswith("top"):
            top = sub
    if top is not None:
        out.append((max((n for n, _ in out), default=0) + 1, top))
    floors = sorted(out)
    if not floors or floors[0][0] != 0:
        raise ImuFormatError(
            f"{folder}: no 'Ground Floor' subfolder (the table's sensor); found "
            f"{[p.name for p in folder.iterdir() if p.is_dir()]}"
        )
    numbers = [n for n, _ in floors]
    if numbers != list(range(len(numbers))):
        raise ImuFormatError(
            f"{folder}: floors {numbers}: a floor between the table and the top has no folder"
        )
    return floors


def run_labels(folder: str | Path) -> list[str]:
    """The run labels of a model's folder (the text in parentheses at the start of a file's name)."""
    labels = set()
    for _, sub in floor_folders(folder):
        for f in sub.iterdir():
            m = re.match(r"^\((.*?)\)", f.name)
            if m:
                labels.add(m.group(1))
    return sorted(labels)


def run_files(folder: str | Path, run: str) -> list[tuple[int, Path]]:
    """(floor, file) of run ``run`` on every floor, table first."""
    floors = floor_folders(folder)
    labels = run_labels(folder)
    if run not in labels:
        raise ImuFormatError(f"{folder}: no run labelled '{run}'; the runs are {labels}")
    out = []
    for number, sub in floors:
        files = sorted(f for f in sub.iterdir() if f.name.startswith(f"({run})"))
        if not files:
            raise ImuFormatError(f"{sub}: no file of run '{run}' on this floor (floor {number})")
        if len(files) > 1:
            raise ImuFormatError(f"{sub}: {len(files)} files of run '{run}': {[f.name for f in files]}")
        out.append((number, files[0]))
    return out


@dataclass
class Axis:
    """A sensor's shaking axis in its own frame, its gravity and its tilt from vertical (degrees)."""

    direction: np.ndarray
    gravity: np.ndarray
    tilt_deg: float
    share: float  # the horizontal variance along the axis


def shaking_axis(acc: np.ndarray, rest: slice = slice(0, 120)) -> Axis:
    """Gravity from the mean (the sensor at rest on average); the principal direction of the
    acceleration left in the plane normal to it."""
    g = acc.mean(axis=0)
    up = g / max(float(np.linalg.norm(g)), 1e-12)
    dyn = acc - g
    horizontal = dyn - np.outer(dyn @ up, up)
    cov = horizontal.T @ horizontal
    w, vec = np.linalg.eigh(cov)
    d = vec[:, -1]
    tilt = float(np.degrees(np.arccos(min(abs(up[2]), 1.0))))
    return Axis(d, g, tilt, float(w[-1] / max(w.sum(), 1e-300)))


def along(acc: np.ndarray, axis: Axis, rest: slice = slice(0, 120)) -> np.ndarray:
    """The acceleration along the axis, gravity and bias off (the mean over the rest at the start)."""
    s = (acc - axis.gravity) @ axis.direction
    return s - float(np.mean(s[rest]))


def start_seconds(start_time: str) -> float | None:
    """``StartTime`` (``2025-03-06_12:26:07_000 PST``) in seconds of its day's clock (None if unreadable)."""
    m = re.search(r"(\d{4})-(\d{2})-(\d{2})_(\d{2}):(\d{2}):(\d{2})_(\d{3})", start_time or "")
    if not m:
        return None

    y, mo, d, h, mi, sec, ms = (int(g) for g in m.groups())
    return _dt.datetime(y, mo, d, h, mi, sec, ms * 1000).timestamp()


def low_band_lag(
    ref: np.ndarray, sig: np.ndarray, dt: float, max_lag_s: float, band_hz: tuple[float, float] = (0.2, 2.0)
) -> tuple[float, float, float]:
    """(lag s, sign, correlation) of ``sig`` against ``ref`` where a floor moves with its table:
    well below the fundamental frequency a floor's acceleration is the table's, in phase (its phase
    there is about 2 zeta r^3 at r = f / f_n: a delay of a fraction of a millisecond below a quarter
    of the fundamental), so the lag of the cross-correlation of the band-passed signals is the
    sensors' timing offset, not the structure's response. Positive: ``sig`` later. Sub-sample by a
    parabola through the top three lags."""
    cc = lagged_correlation(ref, sig, dt, max_lag_s, band_hz)
    m = (len(cc) - 1) // 2
    i = int(np.argmax(np.abs(cc)))
    sign = float(np.sign(cc[i])) or 1.0
    c = sign * cc
    return float((i - m + peak_fraction(c, i)) * dt), sign, float(c[i])


@dataclass
class Alignment:
    """Per floor: the clock offset used (ms), the low-band lag against the table found after it
    (ms; the clocks' residual error), the correlation there, each sensor's tilt and axis share."""

    coarse: str = "clock"  # clock: the sensors' shared SampleTimeFine; start_time: StartTime, to the second
    clock_ms: list[float] = field(default_factory=list)
    lag_ms: list[float] = field(default_factory=list)
    lag_correlation: list[float] = field(default_factory=list)
    applied_ms: list[float] = field(default_factory=list)
    tilt_deg: list[float] = field(default_factory=list)
    axis_share: list[float] = field(default_factory=list)
    gaps_filled: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    start_s: float = 0.0  # where the floors' common part starts on the table's time


#: the lag search around a shared clock's offset (s), and the low-band correlation a lag needs to be used
SHARED_CLOCK_SEARCH_S = 0.1
MIN_LAG_CORRELATION = 0.9


def shared_clock(imus: list[ImuFile]) -> bool:
    """Whether the sensors' SampleTimeFine is one clock: its offsets agree with StartTime (to the
    second it has) for every file; unsynchronised sensors' clocks start anywhere."""
    starts = [start_seconds(m.start_time) for m in imus]
    if any(s is None for s in starts):
        return True  # nothing to check against
    return all(
        abs((m.clock0_us - imus[0].clock0_us) * 1e-6 - (s - starts[0])) < 1.5 for m, s in zip(imus, starts)
    )


def align_floors(
    imus: list[ImuFile],
    axes: list[Axis],
    align: str = "clock",
    max_lag_s: float = 1.5,
    band_hz: tuple[float, float] = (0.2, 2.0),
) -> tuple[np.ndarray, np.ndarray, Alignment]:
    """Every sensor's acceleration along its axis on the table's time grid, (t, (N, floors)), and
    what was done. The coarse offset: the shared clock, else StartTime (to the second). Then each
    floor's low-band lag against the table (``low_band_lag``, within ``max_lag_s``) is measured;
    ``align='lag'`` (or StartTime as the coarse offset) moves the floor by it. Each floor's sign
    follows the table's (in phase in the low band)."""
    table = imus[0]
    step = float(np.median(np.diff(table.t)))
    report = Alignment(coarse="clock" if shared_clock(imus) else "start_time")
    starts = [start_seconds(m.start_time) for m in imus]
    grid, cols = table.t, []
    ref = along(table.acc, axes[0])
    for k, (m, ax) in enumerate(zip(imus, axes)):
        s = along(m.acc, ax)
        offset = (m.clock0_us - table.clock0_us) * 1e-6 if report.coarse == "clock" else starts[k] - starts[0]
        lag, sign, corr = (0.0, 1.0, 1.0)
        if k:
            coarse = np.interp(grid, m.t + offset, s, left=0.0, right=0.0)
            # a shared clock is off by milliseconds if at all: a narrow search keeps a sine's
            # periodic correlation from choosing another period
            lag, sign, corr = low_band_lag(
                ref,
                coarse,
                step,
                max_lag_s if report.coarse == "start_time" else min(max_lag_s, SHARED_CLOCK_SEARCH_S),
                band_hz,
            )
        trusted = corr >= MIN_LAG_CORRELATION
        moved = lag if trusted and (align == "lag" or report.coarse == "start_time") else 0.0
        if k and not trusted:
            report.notes.append(
                note(
                    "lag_not_trusted",
                    f"floor {k}: low-band correlation with the table {corr:.2f} < {MIN_LAG_CORRELATION}: "
                    f"its lag ({1e3 * lag:.1f} ms) is not used",
                )
            )
        cols.append(sign * np.interp(grid, m.t + offset - moved, s, left=np.nan, right=np.nan))
        report.clock_ms.append(1e3 * offset)
        report.lag_ms.append(1e3 * lag)
        report.lag_correlation.append(corr)
        report.applied_ms.append(1e3 * (offset - moved))
        report.tilt_deg.append(ax.tilt_deg)
        report.axis_share.append(ax.share)
        report.gaps_filled.append(m.gaps_filled)
    data = np.stack(cols, axis=1)
    keep = np.all(np.isfinite(data), axis=1)
    if not keep.any():
        raise ImuFormatError(f"{table.path.parent.parent}: the floors' records do not overlap in time")
    i0, i1 = int(np.argmax(keep)), len(keep) - int(np.argmax(keep[::-1]))
    report.start_s = float(grid[i0])
    return grid[i0:i1] - grid[i0], data[i0:i1], report


def checked_run(
    path: str | Path, run: str | None, n_storeys: int | None, align: str, fit_share: float | None
) -> list[tuple[str, Path]]:
    """The run's files, one per floor, after the settings and the storey count are checked."""
    if run is None:
        raise ImuFormatError("no run: set data.run=LABEL (one run) or 'data.runs=[A,B]' (several)")
    if align not in ("clock", "lag"):
        raise ImuFormatError(f"data.align must be 'clock' or 'lag', got '{align}'")
    if fit_share is not None and not 0.1 <= fit_share <= 0.95:
        raise ImuFormatError(f"data.fit_share must lie in [0.1, 0.95], got {fit_share}")
    files = run_files(path, run)
    if n_storeys is not None and int(n_storeys) != len(files) - 1:
        raise ImuFormatError(
            f"{path}: {len(files) - 1} floor(s) above the table, the model has {n_storeys} storey(s): set "
            f"system.n_storeys={len(files) - 1}"
        )
    return files


def _meta(path, run: str, files, imus, report, align: str, notes: list[str], pre_rms) -> RecordMeta:
    """What a run's record says of where it came from and how its sensors were placed."""
    return RecordMeta(
        path=str(path),
        run=run,
        floors=[f.parent.name for _, f in files],
        files=[f.name for _, f in files],
        alignment=report,
        align=align,
        units={"a": "m/s^2", "ag": "m/s^2"},
        pre_event_rms=pre_rms,
        notes=notes,
        devices=[m.device for m in imus],
    )


def xsens_record(
    path: str | Path,
    run: str | None,
    n_storeys: int | None = None,
    dt: float | None = None,
    align: str = "lag",
    max_lag_s: float = 1.5,
    lag_band_hz: tuple[float, float] = (0.2, 2.0),
    span: list[float] | None = None,
    pre: float = 2.0,
    post: float = 3.0,
    fit_share: float | None = None,
    system=None,
    input_hold: str = "linear",
) -> Record:
    """The run ``run`` of the model in ``path`` as a building record: the table's acceleration along
    the shaking axis as ``ag`` and each floor's acceleration (relative to the table, as every
    one-input record keeps it). ``align``: ``clock`` (the sensors' shared clock; each floor's
    low-band lag against the table reported) or ``lag`` (each floor moved by that lag); sensors
    without a shared clock are placed by StartTime and moved by their lag whatever ``align`` says.
    ``dt``: resample (s). ``span``/``pre``/``post``: the shaking, as for strong-motion records.
    ``fit_share``: the first share of the span is for fitting, the rest held out (``meta.split``).
    ``input_hold``: how models read the table's motion between samples (``pidyn.integrate``)."""
    files = checked_run(
        path, run, n_storeys if n_storeys is not None else getattr(system, "n_dof", None), align, fit_share
    )
    imus = [read_xsens(f) for _, f in files]
    axes = [shaking_axis(m.acc) for m in imus]
    t, data, report = align_floors(imus, axes, align, max_lag_s, tuple(lag_band_hz))
    step = float(t[1] - t[0])
    notes: list[str] = list(report.notes)
    if dt is not None and dt > step * 1.001:
        data, _, step = _resample(data, data[:, :0], step, dt, notes)

    i0, i1, pre_rms = shaking_span(data[:, :1], data[:, 1:], step, span, pre, post)
    data = data[i0:i1]
    t = np.arange(len(data)) * step
    ag = data[:, 0]
    meta = _meta(path, run, files, imus, report, align, notes, pre_rms).with_(
        dt=step,
        span=[i0 * step, (i1 - 1) * step],
        pga=float(np.max(np.abs(ag))),
        input_hold=checked_hold(input_hold, "data.input_hold"),
        split=None if fit_share is None else Split.at(float(t[-1]) * fit_share, float(t[-1])),
    )
    return Record(
        name=f"{Path(path).name}:{run}",
        t=t,
        f=ag,
        a=data[:, 1:] - ag[:, None],
        excitation="ground",
        meta=meta,
    )


READERS["xsens"] = xsens_record
