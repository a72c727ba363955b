"""Reader of CSMIP / CESMD processed strong-motion files (V2), one channel per file.

A V2 file is 25 lines of text, an integer header (100 values, 16I5), a real header (100
values, 8F10) and three blocks of samples (acceleration, velocity, displacement), each led by
a line ``N points of accel data equally spaced at DT sec, in cm/sec2. (8f10.6)``. The
samples are fixed-width Fortran fields: neighbours may touch (``-999.00000 1662.0000``), so
they are sliced by width, never split on blanks. Film-era files (before the 1990s) spell the
same layout in capitals and omit the format, which is then 8F10.

The reader looks for the block headers instead of counting lines, and checks what it can:
the sample count against the header, the three blocks' steps against each other, the units,
every value finite, and the peak acceleration against the one the header states. The
station channel comes from ``(Sta Chn: N)`` when the text has it, else from the integer
header (its third value); a file whose two disagree is refused. An archive (a zip file, or
a folder) is read whole; files other than V2 (V1, V3, the A/ and other products) are left.
"""

from __future__ import annotations

import io
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pidyn.data.errors import DataError

#: factors to SI of the units V2 files declare
_UNITS = {
    "cm/sec2": 0.01,
    "cm/sec/sec": 0.01,
    "cm/s2": 0.01,
    "cm/s/s": 0.01,
    "cm/sec": 0.01,
    "cm/s": 0.01,
    "cm": 0.01,
    "g": 9.80665,
}
_BLOCK = re.compile(
    r"^\s*(\d+)\s+points\s+of\s+(accel|veloc|displ)\s+data\s+equally\s+spaced\s+at\s+"
    r"([0-9.Ee+-]+)\s*sec\.?\s*(.*)$",
    re.IGNORECASE,
)
_FORMAT = re.compile(r"\(\s*(\d+)\s*[fe]\s*(\d+)\.(\d+)\s*\)", re.IGNORECASE)
_UNIT_TEXT = re.compile(r"(?:units\s*:\s*|in\s+)([a-z/0-9]+)", re.IGNORECASE)
_STA_CHN = re.compile(r"sta\s*chn\s*:\s*(\d+)", re.IGNORECASE)
_CHAN = re.compile(r"chan\s+(\d+)\s*:\s*([^(]*?)\s*(?:\(|location|$)", re.IGNORECASE)
_PEAK = re.compile(r"peak\s+acceleration\s*=\s*([-0-9.Ee+]+)", re.IGNORECASE)
_LOCATION = re.compile(r"location\s*:\s*(.*)$", re.IGNORECASE)


class CsmipFormatError(DataError):
    """A V2 file or archive that cannot be read; the message names the file and the problem."""


class MissingChannelError(DataError):
    """An archive without a channel that was asked for; the message names both."""


@dataclass
class V2Channel:
    """One channel of a V2 file, in SI units: acceleration (m/s^2), velocity (m/s),
    displacement (m), all absolute, at a uniform step ``dt`` (s)."""

    station_channel: int
    recorder_channel: int
    orientation: str
    location: str
    dt: float
    acc: np.ndarray
    vel: np.ndarray | None
    disp: np.ndarray | None
    source: str
    recorder: str = ""
    band_hz: tuple[float, float] | None = None  # the processing band-pass, where the header gives it
    header: list[str] = field(default_factory=list, repr=False)

    @property
    def n(self) -> int:
        return len(self.acc)

    @property
    def duration(self) -> float:
        return self.dt * (self.n - 1)


def read_v2(text: str, source: str) -> V2Channel:
    """One V2 file's content (``source`` names it in errors)."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    blocks = [(i, m) for i, line in enumerate(lines) if (m := _BLOCK.match(line))]
    kinds = [m.group(2).lower() for _, m in blocks]
    if "accel" not in kinds:
        raise CsmipFormatError(
            f"{source}: no acceleration block ('N points of accel data ...'): not a V2 file"
        )
    data: dict[str, np.ndarray] = {}
    dts: dict[str, float] = {}
    factors: dict[str, float] = {}
    for i, m in blocks:
        kind = m.group(2).lower()
        if kind in data:
            raise CsmipFormatError(f"{source}: two {kind} blocks")
        n, dt = int(m.group(1)), float(m.group(3))
        if not dt > 0:
            raise CsmipFormatError(f"{source}: {kind} block has step {dt} s")
        width = _field_width(m.group(4))
        data[kind] = _samples(lines, i + 1, n, width, f"{source}: {kind} block")
        dts[kind] = dt
        factors[kind] = _unit_factor(m.group(4), kind, source)
    dt = dts["accel"]
    for kind, d in dts.items():
        if abs(d - dt) > 1e-9 * dt:
            raise CsmipFormatError(
                f"{source}: the {kind} block has step {d} s, the acceleration block {dt} s"
            )
    lengths = {k: len(v) for k, v in data.items()}
    if len(set(lengths.values())) > 1:
        raise CsmipFormatError(f"{source}: blocks of different lengths {lengths}")
    head = lines[: blocks[0][0]]
    station, recorder_chan, orientation, location = _channel_identity(head, source)
    acc = data["accel"] * factors["accel"]
    _check_peak(head, data["accel"], source)
    return V2Channel(
        station_channel=station,
        recorder_channel=recorder_chan,
        orientation=orientation,
        location=location,
        dt=dt,
        acc=acc,
        vel=data["veloc"] * factors["veloc"] if "veloc" in data else None,
        disp=data["displ"] * factors["displ"] if "displ" in data else None,
        source=source,
        recorder=_recorder(head),
        band_hz=_band(head),
        header=head[:25],
    )


def _field_width(tail: str) -> int:
    m = _FORMAT.search(tail)
    return int(m.group(2)) if m else 10


def _unit_factor(tail: str, kind: str, source: str) -> float:
    m = _UNIT_TEXT.search(tail)
    if not m:
        raise CsmipFormatError(f"{source}: the {kind} block does not state its units ('{tail.strip()}')")
    unit = m.group(1).lower().rstrip(".")
    if unit not in _UNITS:
        raise CsmipFormatError(
            f"{source}: unknown units '{m.group(1)}' of the {kind} block; known: {sorted(_UNITS)}"
        )
    expected = {
        "accel": ("cm/sec2", "cm/sec/sec", "cm/s2", "cm/s/s", "g"),
        "veloc": ("cm/sec", "cm/s"),
        "displ": ("cm",),
    }[kind]
    if unit not in expected:
        raise CsmipFormatError(f"{source}: the {kind} block is in '{unit}', which is not a {kind} unit")
    return _UNITS[unit]


def _samples(lines: list[str], start: int, n: int, width: int, where: str) -> np.ndarray:
    """``n`` fixed-width values from line ``start`` on."""
    out: list[float] = []
    i = start
    while len(out) < n:
        if i >= len(lines) or _BLOCK.match(lines[i]) or lines[i].lstrip().startswith("/&"):
            raise CsmipFormatError(
                f"{where}: {len(out)} values where the header states {n} (file truncated?)"
            )
        line = lines[i].rstrip()
        for j in range(0, len(line), width):
            cell = line[j : j + width].strip()
            if not cell:
                continue
            try:
                out.append(float(cell))
            except ValueError:
                raise CsmipFormatError(f"{where}: line {i + 1} has '{cell}', not a number") from None
        i += 1
    if len(out) != n:
        raise CsmipFormatError(f"{where}: line {i} ends with {len(out) - n} more values than the {n} stated")
    arr = np.asarray(out)
    if not np.all(np.isfinite(arr)):
        raise CsmipFormatError(f"{where}: non-finite values")
    return arr


def _channel_identity(head: list[str], source: str) -> tuple[int, int, str, str]:
    """(station channel, recorder channel, orientation, location) from the text and integer header."""
    text = "\n".join(head[:25])
    # the line that names the channel and its location (the first line names the channel too, followed by "from")
    chan = next((m for line in head[:25] if "location" in line.lower() and (m := _CHAN.search(line))), None)
    chan = chan or next((m for line in head[:25] if (m := _CHAN.search(line))), None)
    if chan is None:
        raise CsmipFormatError(f"{source}: no 'Chan N:' line in the header")
    recorder_chan = int(chan.group(1))
    orientation = chan.group(2).strip()
    sta = _STA_CHN.search(text)
    from_int = _int_header_station(head)
    if sta is not None:
        station = int(sta.group(1))
        if from_int is not None and from_int != station:
            raise CsmipFormatError(
                f"{source}: the text names station channel {station}, the integer header {from_int}"
            )
    else:
        station = from_int if from_int is not None else recorder_chan
    loc = next((m.group(1).strip() for line in head[:25] if (m := _LOCATION.search(line))), "")
    return station, recorder_chan, orientation, loc


def _int_header_station(head: list[str]) -> int | None:
    """The third value of the integer header (16I5): the station channel number."""
    for i in range(20, min(len(head), 32)):
        line = head[i].rstrip()
        cells = [line[j : j + 5].strip() for j in range(0, 80, 5)]
        if len(line) >= 70 and all(re.fullmatch(r"-?\d+", c or "0") for c in cells):
            try:
                return int(cells[2])
            except ValueError:
                return None
    return None


def _recorder(head: list[str]) -> str:
    """The recorder's id (``89324-C0161-...`` or ``s/n A874``): channels of one recorder share a clock."""
    m = re.search(r"\d{4,5}-([A-Z]+\d+)-", head[0], re.IGNORECASE) if head else None
    return m.group(1) if m else ""


def _band(head: list[str]) -> tuple[float, float] | None:
    text = " ".join(head[:25])
    m = re.search(r"3\s*dB\s*pts\s*at\s*([0-9.]+)\s*and\s*([0-9.]+)", text, re.IGNORECASE)
    if m:
        return float(m.group(1)), float(m.group(2))
    m = re.search(
        r"ramps\s*at\s*([0-9.]+)\s*-\s*([0-9.]+)\s*and\s*([0-9.]+)\s*-\s*([0-9.]+)", text, re.IGNORECASE
    )
    if m:
        return float(m.group(2)), float(m.group(3))
    return None


def _check_peak(head: list[str], acc_raw: np.ndarray, source: str) -> None:
    """The header's peak acceleration must be the samples' (to its printed digits)."""
    m = next((m for line in head if (m := _PEAK.search(line))), None)
    if m is None:
        return
    stated = abs(float(m.group(1)))
    found = float(np.max(np.abs(acc_raw)))
    if abs(stated - found) > 1e-5 * stated + 1.5e-3:  # the header prints three decimals
        raise CsmipFormatError(
            f"{source}: peak acceleration {found:.6g} in the samples, {stated:.6g} in the header"
        )


@dataclass
class Archive:
    """The V2 channels of one event at one station, by station channel number."""

    path: Path
    channels: dict[int, V2Channel]
    skipped: list[str] = field(default_factory=list)  # files in the archive that are not V2

    def require(self, numbers: list[int], what: str) -> list[V2Channel]:
        missing = [n for n in numbers if n not in self.channels]
        if missing:
            raise MissingChannelError(
                f"{self.path.name}: {what} channel(s) {missing} not in this archive (it holds "
                f"{sorted(self.channels)}); choose others with data.inputs=[...] data.outputs=[...], or "
                f"data.on_missing=drop to go on without them"
            )
        return [self.channels[n] for n in numbers]


def read_archive(path: str | Path) -> Archive:
    """Every V2 file of a CSMIP archive (a .zip, or a folder of V1/V2/V3 files)."""
    path = Path(path)
    if not path.exists():
        raise CsmipFormatError(f"{path}: no such archive or folder")
    files = list(_members(path))
    channels: dict[int, V2Channel] = {}
    combined: list[V2Channel] = []
    skipped = []
    for name, text in files:
        if not name.lower().endswith(".v2"):
            skipped.append(name)
            continue
        read = read_v2_channels(text, f"{path.name}/{name}")
        if len(read) > 1:  # a combined file of every channel: the per-channel files come first
            combined += read
            continue
        ch = read[0]
        if ch.station_channel in channels:
            raise CsmipFormatError(
                f"{path.name}: station channel {ch.station_channel} in both "
                f"{channels[ch.station_channel].source} and {ch.source}"
            )
        channels[ch.station_channel] = ch
    for ch in combined:
        _merge_combined(channels, ch, path)
    if not channels:
        raise CsmipFormatError(f"{path}: no V2 file (*.v2) in it; found {[n for n, _ in files][:10]}")
    return Archive(path=path, channels=channels, skipped=skipped)


def read_v2_channels(text: str, source: str) -> list[V2Channel]:
    """Every channel of a V2 file: one, or several where the file combines them (CESMD archives
    may hold one V2 file with every channel, each ended by a ``/&`` line, beside the per-channel
    files)."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    accel = [i for i, line in enumerate(lines) if (m := _BLOCK.match(line)) and m.group(2).lower() == "accel"]
    if len(accel) <= 1:
        return [read_v2(text, source)]
    chunks, current = [], []
    for line in lines:
        current.append(line)
        if line.lstrip().startswith("/&"):
            chunks.append(current)
            current = []
    if any(line.strip() for line in current):
        chunks.append(current)
    found = [
        c for c in chunks if any((m := _BLOCK.match(line)) and m.group(2).lower() == "accel" for line in c)
    ]
    if len(found) != len(accel):
        raise CsmipFormatError(
            f"{source}: {len(accel)} acceleration blocks but {len(found)} channels ended by '/&' lines"
        )
    return [read_v2("\n".join(c), f"{source} (channel {k + 1} of {len(found)})") for k, c in enumerate(found)]


def _merge_combined(channels: dict[int, V2Channel], ch: V2Channel, path: Path) -> None:
    """A combined file's channel where no per-channel file gives it; where one does, they must agree."""
    have = channels.get(ch.station_channel)
    if have is None:
        channels[ch.station_channel] = ch
        return
    same = have.n == ch.n and abs(have.dt - ch.dt) <= 1e-9 * have.dt and np.allclose(have.acc, ch.acc)
    if not same:
        raise CsmipFormatError(
            f"{path.name}: station channel {ch.station_channel} differs between {have.source} and {ch.source}"
        )


def _members(path: Path):
    """(name, text) of every file of a zip archive or folder."""
    if path.is_dir():
        for p in sorted(path.iterdir()):
            if p.is_file():
                yield p.name, _decode(p.read_bytes(), str(p))
        return
    try:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                if not info.is_dir():
                    yield Path(info.filename).name, _decode(z.read(info), f"{path.name}/{info.filename}")
    except zipfile.BadZipFile as exc:
        raise CsmipFormatError(f"{path}: not a readable zip archive ({exc})") from None


def _decode(raw: bytes, source: str) -> str:
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError:
        return io.TextIOWrapper(io.BytesIO(raw), encoding="latin-1").read()
