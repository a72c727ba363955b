"""Ground-motion records in SI units and the transformations used to make unseen excitations."""

from __future__ import annotations

import csv
from dataclasses import dataclass, replace
from fractions import Fraction
from importlib import resources
from pathlib import Path

import numpy as np
from scipy import signal

from pidyn.excitation.at2 import AT2FormatError, G, read_at2

RECORDS_PACKAGE = "pidyn.excitation.records"

#: Short names for the shipped records (files in ``pidyn/excitation/records``).
SHIPPED = {
    "el_centro": "ELCENTRO1940_RSN6_IMPVALL.I_I-ELC180.AT2",
    "el_centro_peer2000": "ELCENTRO1940_PEER2000_IELC180.AT2",
    "el_centro_peknold": "ELCENTRO1940_NS_PEKNOLD_dt0.02.AT2",
    "kobe": "KOBE1995_RSN1106_KOBE_KJM000.AT2",
    "kobe_090": "KOBE1995_RSN1106_KOBE_KJM090.AT2",
    "taft": "TAFT1952_RSN15_KERN_TAF021.AT2",
    "san_fernando": "SANFERNANDO1971_RSN77_SFERN_PUL164.AT2",
    "tabas": "TABAS1978_RSN140_TABAS_FER-L1.AT2",
    "loma_prieta": "LOMAPRIETA1989_RSN753_LOMAP_CLS000.AT2",
    "landers": "LANDERS1992_RSN879_LANDERS_LCN260.AT2",
    "northridge": "NORTHRIDGE1994_RSN1084_NORTHR_SCS052.AT2",
    "kocaeli": "KOCAELI1999_RSN1162_KOCAELI_GYN000.AT2",
    "chichi": "CHICHI1999_RSN1512_CHICHI_TCU078-E.AT2",
}


@dataclass(frozen=True)
class GroundMotion:
    """A uniformly sampled ground acceleration ``acc`` (m/s^2) with step ``dt`` (s).

    Transformations return new objects, so one loaded record can feed many experiments.
    """

    name: str
    dt: float
    acc: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        acc = np.asarray(self.acc, dtype=np.float64)
        if acc.ndim != 1 or acc.size < 2:
            raise ValueError(f"ground motion '{self.name}': need a 1-D series of >= 2 samples")
        if not np.all(np.isfinite(acc)):
            k = int(np.flatnonzero(~np.isfinite(acc))[0])
            raise ValueError(f"ground motion '{self.name}': sample {k} is not finite")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"ground motion '{self.name}': dt={self.dt} must be positive")
        object.__setattr__(self, "acc", acc)
        object.__setattr__(self, "_grid", np.arange(acc.size) * self.dt)  # once: an integrator calls per step

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.acc.size) * self.dt

    @property
    def duration(self) -> float:
        return (self.acc.size - 1) * self.dt

    @property
    def pga(self) -> float:
        return float(np.max(np.abs(self.acc)))

    def scaled(self, factor: float) -> GroundMotion:
        """Amplitude scaling (the usual way to make a record stronger or weaker)."""
        return replace(self, acc=self.acc * factor, name=_tag(self.name, f"x{factor:g}"))

    def stretched(self, factor: float) -> GroundMotion:
        """Time stretching: the same samples played ``factor`` times slower (dt * factor)."""
        if factor <= 0:
            raise ValueError(f"stretch factor must be positive, got {factor}")
        return replace(self, dt=self.dt * factor, name=_tag(self.name, f"t{factor:g}"))

    def truncated(self, duration: float | None) -> GroundMotion:
        """Keep the first ``duration`` seconds (None keeps all)."""
        if duration is None or duration >= self.duration:
            return self
        n = int(round(duration / self.dt)) + 1
        return replace(self, acc=self.acc[:n])

    def starting_at(self, t0: float) -> GroundMotion:
        """Drop the samples before ``t0`` (s); the structure is taken at rest at the new t = 0."""
        if t0 <= 0.0:
            return self
        k = int(round(t0 / self.dt))
        if k >= self.acc.size - 1:
            raise ValueError(
                f"ground motion '{self.name}': start {t0} s is past its end ({self.duration:g} s)"
            )
        return replace(self, acc=self.acc[k:], name=_tag(self.name, f"from{k * self.dt:g}s"))

    def arias_time(self, fraction: float) -> float:
        """Time (s) at which the Arias intensity (integral of acc^2) reaches ``fraction`` of its total:
        0.05 marks the onset of strong motion, 0.95 its end (Trifunac and Brady, 1975)."""
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"Arias fraction must lie in [0, 1], got {fraction}")
        cum = np.cumsum(self.acc**2)
        return float(np.searchsorted(cum, fraction * cum[-1]) * self.dt)

    def resampled(self, dt: float) -> GroundMotion:
        """Resample to step ``dt``: linear interpolation up, anti-aliased polyphase down."""
        if np.isclose(dt, self.dt, rtol=1e-9):
            return self
        if dt < self.dt:
            t_new = np.arange(0.0, self.duration + 1e-12, dt)
            return replace(self, dt=dt, acc=np.interp(t_new, self.t, self.acc))
        ratio = dt / self.dt
        frac = _rational(ratio)
        if frac is None:
            raise ValueError(f"cannot downsample dt={self.dt} to dt={dt}: ratio {ratio:g} not rational")
        up, down = frac
        acc = signal.resample_poly(self.acc, up, down)
        return replace(self, dt=dt, acc=acc)

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        """Linear interpolation, zero outside the record (the ground is at rest)."""
        return np.interp(t, self._grid, self.acc, left=0.0, right=0.0)


def _tag(name: str, tag: str) -> str:
    return f"{name}_{tag}"


def _rational(x: float, max_den: int = 64) -> tuple[int, int] | None:

    f = Fraction(x).limit_denominator(max_den)
    if abs(float(f) - x) > 1e-9 * x:
        return None
    return f.denominator, f.numerator


def load_record(name_or_path: str | Path) -> GroundMotion:
    """Load a shipped record by short name (see ``SHIPPED``) or any AT2 file by path."""
    key = str(name_or_path)
    if key in SHIPPED:
        ref = resources.files(RECORDS_PACKAGE).joinpath(SHIPPED[key])
        with resources.as_file(ref) as path:
            rec = read_at2(path)
        return GroundMotion(name=key, dt=rec.dt, acc=rec.acc_g * G, source=rec.title)
    path = Path(key)
    if not path.exists():
        raise AT2FormatError(
            f"{path}: no such file, and not a shipped record name (choose from {sorted(SHIPPED)})"
        )
    rec = read_at2(path)
    return GroundMotion(name=path.stem, dt=rec.dt, acc=rec.acc_g * G, source=rec.title)


def record_index() -> list[dict[str, str]]:
    """Metadata of the shipped records (event, station, PGA, provenance, checksum)."""
    ref = resources.files(RECORDS_PACKAGE).joinpath("index.csv")
    with ref.open("r", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def prepare(
    record: str | Path,
    scale: float = 1.0,
    stretch: float = 1.0,
    duration: float | None = None,
    dt: float | None = None,
    start: float = 0.0,
) -> GroundMotion:
    """Load a record and apply, in order: resampling, start (s, in record time), truncation,
    stretching, scaling."""
    gm = load_record(record)
    if dt is not None:
        gm = gm.resampled(dt)
    gm = gm.starting_at(start)
    gm = gm.truncated(duration)
    if stretch != 1.0:
        gm = gm.stretched(stretch)
    if scale != 1.0:
        gm = gm.scaled(scale)
    return gm


@dataclass(frozen=True)
class SupportMotions:
    """Several ground accelerations on one time grid, ``acc`` (N, n_inputs) in m/s^2: a
    structure on supports that move differently (a bridge's abutments and bent). It gives the
    excitation of a model with several inputs: the accelerations, then the velocities
    (integrated from rest by the trapezoidal rule, exact for an acceleration linear between samples)."""

    name: str
    dt: float
    acc: np.ndarray
    inputs: tuple[str, ...]
    source: str = ""

    def __post_init__(self) -> None:
        acc = np.asarray(self.acc, dtype=np.float64)
        if acc.ndim != 2 or acc.shape[0] < 2 or acc.shape[1] != len(self.inputs):
            raise ValueError(
                f"support motions '{self.name}': need (N, {len(self.inputs)}) samples, got {acc.shape}"
            )
        if not np.all(np.isfinite(acc)):
            raise ValueError(f"support motions '{self.name}': non-finite samples")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"support motions '{self.name}': dt={self.dt} must be positive")
        object.__setattr__(self, "acc", acc)
        object.__setattr__(self, "_grid", np.arange(acc.shape[0]) * self.dt)
        vel = np.concatenate(
            [np.zeros((1, acc.shape[1])), np.cumsum(0.5 * (acc[1:] + acc[:-1]) * self.dt, axis=0)]
        )
        object.__setattr__(self, "vel", vel)

    @property
    def columns(self) -> np.ndarray:
        """The excitation's samples (N, 2 n_inputs): accelerations, then velocities."""
        return np.concatenate([self.acc, self.vel], axis=1)

    @classmethod
    def from_motions(cls, motions: dict[str, GroundMotion], name: str = "supports") -> SupportMotions:
        """One motion per support (same step; cut to the shortest)."""
        dts = {m.dt for m in motions.values()}
        if len(dts) != 1:
            raise ValueError(f"support motions '{name}': different steps {sorted(dts)}; resample first")
        n = min(m.acc.size for m in motions.values())
        return cls(name, dts.pop(), np.stack([m.acc[:n] for m in motions.values()], axis=1), tuple(motions))

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.acc.shape[0]) * self.dt

    @property
    def duration(self) -> float:
        return (self.acc.shape[0] - 1) * self.dt

    @property
    def pga(self) -> float:
        return float(np.max(np.abs(self.acc)))

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        """Linear interpolation of every column (accelerations, velocities), zero before the record
        and the last velocity held after it: (2 n_inputs,) or (N, 2 n_inputs)."""
        cols = [
            np.interp(t, self._grid, self.acc[:, j], left=0.0, right=0.0) for j in range(self.acc.shape[1])
        ]
        cols += [np.interp(t, self._grid, self.vel[:, j], left=0.0) for j in range(self.vel.shape[1])]
        return np.stack(cols, axis=-1)
