"""Where the measured record comes from: a simulation of a known system, or a file."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pidyn.excitation.ground_motion import GroundMotion, prepare
from pidyn.simulate import Trajectory, add_noise, simulate
from pidyn.systems.base import StructuralSystem


class DataError(ValueError):
    """Raised for unusable measurement files; the message names the file and the problem."""


@dataclass
class Record:
    """A measured (or simulated-and-measured) response record on a uniform time grid.

    ``f`` is the excitation (ground acceleration in m/s^2, or force in N). ``truth`` holds
    the true parameters and the noise-free trajectory when the data are synthetic.
    """

    name: str
    t: np.ndarray
    f: np.ndarray
    x: np.ndarray
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    excitation: str = "ground"
    truth: dict[str, float] | None = None
    clean: Trajectory | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Response channels are (N, n_dof); a 1-D series is one degree of freedom."""
        for name in ("x", "v", "a"):
            arr = getattr(self, name)
            if arr is not None:
                arr = np.asarray(arr, dtype=float)
                setattr(self, name, arr[:, None] if arr.ndim == 1 else arr)
        self.f = np.asarray(self.f, dtype=float)
        if len(self.x) != len(self.t) or len(self.f) != len(self.t):
            raise DataError(f"record '{self.name}': {len(self.t)} times, {len(self.x)} displacements, "
                            f"{len(self.f)} excitation samples; they must match")

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    def segment(self, t0: float | None, t1: float | None) -> "Record":
        """The samples with t0 <= t <= t1 (times kept absolute; the truth travels along)."""
        from dataclasses import replace

        lo = -np.inf if t0 is None else t0 - 1e-9
        hi = np.inf if t1 is None else t1 + 1e-9
        keep = (self.t >= lo) & (self.t <= hi)
        if keep.sum() < 10:
            raise ValueError(f"record '{self.name}': only {int(keep.sum())} samples in [{t0}, {t1}] s")
        cut = lambda a: None if a is None else a[keep]  # noqa: E731
        return replace(self, t=self.t[keep], f=self.f[keep], x=self.x[keep], v=cut(self.v), a=cut(self.a),
                       clean=None, meta={**self.meta, "segment": [t0, t1]})


def synthetic(
    system: StructuralSystem,
    record: str = "kobe",
    eq_scale: float = 1.0,
    stretch: float = 1.0,
    duration: float | None = 40.0,
    dt: float | None = 0.01,
    noise: float = 0.0,
    data_seed: int = 0,
    channels: tuple[str, ...] = ("x", "v"),
) -> Record:
    """Simulate ``system`` at its true parameters under a ground-motion record and measure it.

    Noise of std ``noise`` x RMS is added to each measured channel (seeded by ``data_seed``).
    """
    gm = prepare(record, scale=eq_scale, stretch=stretch, duration=duration, dt=dt)
    return synthetic_from_motion(system, gm, noise=noise, data_seed=data_seed, channels=channels)


def synthetic_from_motion(
    system: StructuralSystem,
    gm: GroundMotion,
    noise: float = 0.0,
    data_seed: int = 0,
    channels: tuple[str, ...] = ("x", "v"),
    params: dict[str, float] | None = None,
) -> Record:
    bad = set(channels) - {"x", "v", "a"}
    if bad or "x" not in channels:
        raise ValueError(f"channels must include 'x' and be among x, v, a; got {list(channels)}")
    truth = params or system.true_values()
    clean = simulate(system, truth, gm, gm.t)
    meas = add_noise({c: getattr(clean, c) for c in channels}, noise, data_seed)
    return Record(
        name=gm.name,
        t=clean.t,
        f=clean.f,
        x=meas["x"],
        v=meas.get("v"),
        a=meas.get("a"),
        excitation=system.excitation,
        truth=dict(truth),
        clean=clean,
        meta={"record": gm.name, "pga": gm.pga, "dt": gm.dt, "noise": noise, "data_seed": data_seed},
    )


def from_csv(
    path: str | Path,
    time_col: str = "t",
    excitation: str | None = None,
    units: dict[str, float] | None = None,
    t_end: float | None = None,
    at2: str | Path | None = None,
) -> Record:
    """Read a measured record: columns ``t`` (s), ``x`` (m), optional ``v``, ``a``, and
    the excitation as ``ag`` (m/s^2, ground) or ``u`` (N, force).

    ``units`` multiplies columns into SI (e.g. ``{"x": 0.001}`` for millimetres). ``at2``
    takes the ground acceleration from a PEER AT2 record (a path or a shipped record's
    name) instead of a column: interpolated at the CSV's times, which start with the record.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        df = pd.read_csv(path)
    except Exception as exc:  # pandas raises many types for malformed CSVs
        raise DataError(f"{path}: cannot be read as CSV ({exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    df = df.loc[:, [c for c in df.columns if c and not c.startswith("Unnamed")]]
    for col, factor in (units or {}).items():
        if col not in df.columns:
            raise DataError(f"{path}: units given for '{col}', which is not a column ({list(df.columns)})")
        df[col] = df[col] * factor
    if at2 is not None:
        from pidyn.excitation.ground_motion import load_record

        if "ag" in df.columns or "u" in df.columns:
            raise DataError(f"{path}: has an excitation column and an AT2 record ({at2}) was given too; use one")
        if time_col not in df.columns:
            raise DataError(f"{path}: missing column '{time_col}' (columns: {list(df.columns)})")
        gm = load_record(at2)
        t_csv = df[time_col].to_numpy(float)
        if t_csv[-1] - t_csv[0] > gm.duration + 1e-9:
            raise DataError(f"{path}: spans {t_csv[-1] - t_csv[0]:.4g} s, longer than the AT2 record {at2} "
                            f"({gm.duration:.4g} s)")
        df["ag"] = gm(t_csv - t_csv[0])
    for need in (time_col, "x"):
        if need not in df.columns:
            raise DataError(f"{path}: missing column '{need}' (columns: {list(df.columns)})")
    has = [c for c in ("ag", "u") if c in df.columns]
    if excitation is None:
        if len(has) != 1:
            raise DataError(f"{path}: need exactly one excitation column 'ag' (ground) or 'u' (force); found {has}")
        col = has[0]
    else:
        col = {"ground": "ag", "force": "u"}[excitation]
        if col not in df.columns:
            raise DataError(f"{path}: excitation '{excitation}' needs a column '{col}'")
    for c in df.columns:
        if not np.issubdtype(df[c].dtype, np.number):
            raise DataError(f"{path}: column '{c}' is not numeric")
        bad = ~np.isfinite(df[c].to_numpy(float))
        if bad.any():
            raise DataError(f"{path}: column '{c}' has {int(bad.sum())} NaN/infinite value(s), first at row {int(np.flatnonzero(bad)[0]) + 2}")
    t = df[time_col].to_numpy(float)
    if t.size < 10:
        raise DataError(f"{path}: only {t.size} rows")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise DataError(f"{path}: time column '{time_col}' is not strictly increasing (row {int(np.flatnonzero(dt <= 0)[0]) + 3})")
    if np.max(np.abs(dt - dt.mean())) > 1e-6 * max(dt.mean(), 1e-12) + 1e-9:
        raise DataError(
            f"{path}: non-uniform time step (from {dt.min():.6g} to {dt.max():.6g} s); resample to a uniform grid first"
        )
    if t_end is not None:
        keep = t <= t_end + 1e-12
        df, t = df.loc[keep], t[keep]
    get = lambda c: df[c].to_numpy(float) if c in df.columns else None  # noqa: E731
    return Record(
        name=path.stem,
        t=t - t[0],
        f=get(col),
        x=get("x"),
        v=get("v"),
        a=get("a"),
        excitation="ground" if col == "ag" else "force",
        meta={"path": str(path), "dt": float(dt.mean())},
    )
