"""PEER AT2 reader that checks the header before trusting the numbers.

An AT2 file is a few free-text header lines, one line with ``NPTS=..., DT=...``, and the
acceleration samples in units of g. Real files differ in spacing, in header wording and
in the number of values per line, so the reader looks for the NPTS/DT line instead of
counting lines, and it checks everything it can: the units line, the sample count, the
step, and that every value is a finite number.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

G = 9.80665  # standard gravity, m/s^2 per g

_HEADER = re.compile(r"NPTS\s*=\s*(\d+)\s*,?\s*DT\s*=\s*([-+0-9.Ee]+)", re.IGNORECASE)
_UNITS = re.compile(r"UNITS?\s+(?:OF|ARE|IS|:|=)?\s*\(?\s*([A-Z/*0-9^.]+)", re.IGNORECASE)


class AT2FormatError(ValueError):
    """Raised when an AT2 file cannot be read; the message names the file and the problem."""


@dataclass(frozen=True)
class AT2Record:
    """Raw content of an AT2 file: acceleration in g at a uniform step ``dt`` (s)."""

    path: Path
    title: str
    dt: float
    acc_g: np.ndarray


def read_at2(path: str | Path, units: str = "g") -> AT2Record:
    """Read and validate a PEER AT2 acceleration file.

    Args:
        path: the file.
        units: the units the file must declare; only ``"g"`` is supported, since PEER
            acceleration files are in g and a velocity (VT2) or displacement (DT2) file
            handed in by mistake must not be read as acceleration.
    """
    path = Path(path)
    lines = _read_lines(path)
    header_idx, npts, dt = _parse_header(path, lines)
    header = lines[:header_idx]
    _check_units(path, header, units)
    acc = _read_samples(path, lines, header_idx, npts)
    title = " / ".join(h.strip() for h in header if h.strip())
    return AT2Record(path=path, title=title, dt=dt, acc_g=acc)


def _read_lines(path: Path) -> list[str]:
    if not path.is_file():
        raise AT2FormatError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="ascii", errors="strict")
    except UnicodeDecodeError as exc:
        raise AT2FormatError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None
    return text.splitlines()


def _parse_header(path: Path, lines: list[str]) -> tuple[int, int, float]:
    """The 'NPTS=..., DT=...' line: its index, NPTS and DT, checked."""
    header_idx = next((i for i, line in enumerate(lines[:12]) if _HEADER.search(line)), None)
    if header_idx is None:
        raise AT2FormatError(
            f"{path}: no 'NPTS=..., DT=...' line in the first 12 lines; is this a PEER AT2 file?"
        )
    m = _HEADER.search(lines[header_idx])
    assert m is not None
    npts = int(m.group(1))
    try:
        dt = float(m.group(2))
    except ValueError:
        raise AT2FormatError(f"{path}: line {header_idx + 1}: DT '{m.group(2)}' is not a number") from None
    if not np.isfinite(dt) or dt <= 0:
        raise AT2FormatError(f"{path}: line {header_idx + 1}: DT={m.group(2)} must be positive")
    if npts <= 1:
        raise AT2FormatError(f"{path}: line {header_idx + 1}: NPTS={npts} is too few samples")
    return header_idx, npts, dt


def _check_units(path: Path, header: list[str], units: str) -> None:
    """An acceleration file in g; a velocity or displacement file handed in by mistake fails."""
    declared = _declared_units(header)
    if declared is not None and declared.lower() != units.lower():
        raise AT2FormatError(
            f"{path}: header declares units '{declared}', expected '{units}' "
            "(an AT2 acceleration file is in g; VT2/DT2 files hold velocity/displacement)"
        )
    if any("VELOCITY" in h.upper() or "DISPLACEMENT" in h.upper() for h in header):
        raise AT2FormatError(f"{path}: header describes velocity or displacement, not acceleration")


def _read_samples(path: Path, lines: list[str], header_idx: int, npts: int) -> np.ndarray:
    """The samples after the header: numbers, NPTS of them, finite, plausibly in g."""
    tokens = " ".join(lines[header_idx + 1 :]).split()
    try:
        acc = np.array([float(tok) for tok in tokens], dtype=np.float64)
    except ValueError:
        bad = next(tok for tok in tokens if not _is_float(tok))
        line_no = next(i + 1 for i, line in enumerate(lines) if i > header_idx and bad in line.split())
        raise AT2FormatError(f"{path}: line {line_no}: '{bad}' is not a number") from None
    if acc.size != npts:
        raise AT2FormatError(
            f"{path}: header says NPTS={npts} but the file holds {acc.size} values "
            "(truncated or concatenated file?)"
        )
    if not np.all(np.isfinite(acc)):
        k = int(np.flatnonzero(~np.isfinite(acc))[0])
        raise AT2FormatError(f"{path}: sample {k} is {acc[k]} (NaN or infinite)")
    if np.max(np.abs(acc)) > 10.0:
        raise AT2FormatError(
            f"{path}: peak |acceleration| {np.max(np.abs(acc)):.3g} exceeds 10 g; "
            "the file is probably in cm/s^2 or m/s^2, not g"
        )
    return acc


def _declared_units(header: list[str]) -> str | None:
    for line in header:
        if "UNIT" in line.upper():
            m = _UNITS.search(line)
            if m:
                return m.group(1).rstrip(".,")
    return None


def _is_float(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True
