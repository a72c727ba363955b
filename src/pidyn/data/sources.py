"""Where the measured record comes from: a simulation of a known system, or a file."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from pidyn.data.csv_table import (
    channel_columns,
    check_values,
    excitation_column,
    floor_arrays,
    ground_from_at2,
    read_table,
    uniform_time,
)
from pidyn.data.errors import DataError, needed
from pidyn.data.meta import RecordMeta
from pidyn.data.windows import spread_by_integration
from pidyn.excitation.ground_motion import GroundMotion, prepare
from pidyn.integrate import HOLDS
from pidyn.named import RESOLVERS
from pidyn.simulate import Trajectory, add_noise, simulate
from pidyn.systems.base import StructuralSystem

#: the readers of the measured formats the command line reads, by name (``Record.from_csmip``,
#: ``Record.from_xsens``): each reader's module adds its own and ``pidyn.data`` imports them, so that
#: the record does not import the readers that build it
READERS: dict[str, Callable[..., Record]] = {}


@dataclass
class Record:
    """A measured (or simulated-and-measured) response record on a uniform time grid.

    ``f`` is the excitation (ground acceleration in m/s^2, or force in N). The response
    channels ``x`` (displacement), ``v`` (velocity) and ``a`` (acceleration), all relative to
    the ground, are (N, n_dof) arrays or None; a floor without that sensor is a column of NaN.
    An accelerometer measures the absolute acceleration; under ground excitation the record
    keeps ``a`` relative (absolute minus ag, exact since ag is measured too) so that every
    estimator compares it with the model's x''. ``truth`` holds the true parameters and the
    noise-free trajectory when the data are synthetic.
    """

    name: str
    t: np.ndarray
    f: np.ndarray
    x: np.ndarray | None = None
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    excitation: str = "ground"
    truth: dict[str, float] | None = None
    clean: Trajectory | None = None
    meta: RecordMeta = field(default_factory=RecordMeta)

    def __post_init__(self) -> None:
        """Response channels are (N, n_dof); a 1-D series is one degree of freedom."""
        self.meta = RecordMeta.of(self.meta, f"record '{self.name}'")
        self.t = np.asarray(self.t, dtype=float)
        self.f = np.asarray(self.f, dtype=float)
        for name in CHANNEL_KINDS:
            arr = getattr(self, name)
            if arr is not None:
                arr = np.asarray(arr, dtype=float)
                arr = arr[:, None] if arr.ndim == 1 else arr
                if np.all(np.isnan(arr)):
                    arr = None
                setattr(self, name, arr)
        measured = {k: getattr(self, k) for k in CHANNEL_KINDS if getattr(self, k) is not None}
        if not measured:
            raise DataError(f"record '{self.name}': no response channel (x, v or a)")
        if self.f.ndim not in (1, 2):
            raise DataError(f"record '{self.name}': excitation of shape {self.f.shape}; one column per input")
        if self.f.ndim == 2 and self.f.shape[1] == 1:
            self.f = self.f[:, 0]
        names = self.meta.inputs
        if self.f.ndim == 2 and (
            self.f.shape[1] % 2 or (names is not None and 2 * len(names) != self.f.shape[1])
        ):
            raise DataError(
                f"record '{self.name}': {self.f.shape[1]} excitation columns; several inputs need their "
                f"accelerations and velocities ({len(names or [])} names)"
            )
        for kind, arr in measured.items():
            if len(arr) != len(self.t) or len(self.f) != len(self.t):
                raise DataError(
                    f"record '{self.name}': {len(self.t)} times, {len(arr)} samples of '{kind}', "
                    f"{len(self.f)} excitation samples; they must match"
                )
        widths = {arr.shape[1] for arr in measured.values()}
        if len(widths) > 1:
            raise DataError(
                f"record '{self.name}': channels cover different numbers of floors "
                f"({ {k: a.shape[1] for k, a in measured.items()} }); pad missing floors with NaN"
            )

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def n_inputs(self) -> int:
        """Excitation channels: one (``f`` is (N,)), or several supports (``f`` is (N, 2 n_inputs):
        their accelerations, then their velocities; ``a`` absolute)."""
        return 1 if self.f.ndim == 1 else int(self.f.shape[1]) // 2

    @property
    def inputs(self) -> list[str]:
        """The names of several inputs (``meta.inputs``); empty for one."""
        return list(self.meta.inputs or []) if self.n_inputs > 1 else []

    @property
    def n_dof(self) -> int:
        return next(getattr(self, k).shape[1] for k in CHANNEL_KINDS if getattr(self, k) is not None)

    def sensors(self) -> dict[str, list[int]]:
        """Measured floors (1-based) per channel kind."""
        out = {}
        for kind in CHANNEL_KINDS:
            arr = getattr(self, kind)
            if arr is not None:
                out[kind] = [j + 1 for j in range(arr.shape[1]) if not np.all(np.isnan(arr[:, j]))]
        return out

    def reference(self) -> tuple[str, np.ndarray]:
        """The channel that best shows the response: displacement if measured, else velocity,
        else acceleration (name, (N, n_dof))."""
        kind = next(k for k in CHANNEL_KINDS if getattr(self, k) is not None)
        return kind, getattr(self, kind)

    def state_scales(self) -> tuple[np.ndarray, np.ndarray]:
        """Spread of the displacement and the velocity per degree of freedom: measured where a
        sensor gives it, else integrated (and detrended) from velocity or acceleration, else
        the nearest floor's. Scales for filters and solvers, never data."""

        def spread(order: int) -> np.ndarray:
            return spread_by_integration(self.t, [(k, getattr(self, k)) for k in CHANNEL_KINDS], order)

        return spread(0), spread(1)

    @classmethod
    def from_csv(cls, path: str | Path, **kwargs) -> Record:
        """A measured record from a CSV file (see ``from_csv`` for the columns and options)."""
        return from_csv(path, **kwargs)

    @classmethod
    def from_csmip(
        cls,
        path: str | Path,
        station: str | None = None,
        direction: str = "transverse",
        inputs: Sequence[int] | None = None,
        outputs: Sequence[int] | None = None,
        **kwargs,
    ) -> Record:
        """One event of a strong-motion station from its CSMIP / CESMD archive (a zip of V2 files or
        a folder), as ``data=csmip`` reads it (``pidyn.data.strong_motion.csmip_record``: ``dt``,
        ``span``, ``fit_share``, ``on_missing`` ...)."""
        return READERS["csmip"](
            path, station=station, direction=direction, inputs=inputs, outputs=outputs, **kwargs
        )

    @classmethod
    def from_xsens(cls, path: str | Path, run: str, **kwargs) -> Record:
        """One run of a building model measured by Xsens DOT IMUs (a folder with a subfolder per
        floor), as ``data=xsens`` reads it (``pidyn.data.imu.xsens_record``: ``align``, ``dt``,
        ``span``, ``fit_share`` ...)."""
        return READERS["xsens"](path, run, **kwargs)

    @classmethod
    def simulate(
        cls,
        system: StructuralSystem | str,
        excitation: str | Path = "kobe",
        *,
        scale: float = 1.0,
        stretch: float = 1.0,
        duration: float | None = 40.0,
        dt: float | None = 0.01,
        noise: float | dict[str, float] = 0.0,
        seed: int = 0,
        channels: Sequence[str] = ("x", "v"),
        sensors: Sequence[int] | None = None,
        **system_values,
    ) -> Record:
        """``system`` (a system object, or a name from the package's configs with
        ``system_values`` setting its keys, e.g. ``n_storeys=5``) at its true parameters under
        ``excitation`` (a shipped record's name or an AT2 path), measured with noise of std
        ``noise`` x RMS on each channel (seeded by ``seed``)."""
        if isinstance(system, str):
            if "system" not in RESOLVERS:
                raise RuntimeError(
                    f"Record.simulate('{system}'): a system's name resolves through pidyn's configs; "
                    "use pidyn.Record (or import pidyn.config first), or pass a system object"
                )
            system = RESOLVERS["system"](system, **system_values)
        elif system_values:
            raise ValueError(f"settings {sorted(system_values)} need a system name, not a system object")
        return synthetic(
            system,
            record=str(excitation),
            eq_scale=scale,
            stretch=stretch,
            duration=duration,
            dt=dt,
            noise=noise,
            data_seed=seed,
            channels=tuple(channels),
            sensors=None if sensors is None else list(sensors),
        )

    @classmethod
    def from_at2(cls, path: str | Path, system: StructuralSystem | str, **kwargs) -> Record:
        """The response of ``system`` to the ground motion of a PEER AT2 file, simulated and
        measured as in ``simulate`` (to pair an AT2 file with measured responses, use
        ``from_csv(path, at2=...)``)."""
        if not Path(path).exists():
            raise FileNotFoundError(f"{path}: no such AT2 file")
        return cls.simulate(system, excitation=path, **kwargs)

    def segment(self, t0: float | None, t1: float | None) -> Record:
        """The samples with t0 <= t <= t1 (times kept absolute; the truth travels along)."""
        lo = -np.inf if t0 is None else t0 - 1e-9
        hi = np.inf if t1 is None else t1 + 1e-9
        keep = (self.t >= lo) & (self.t <= hi)
        if keep.sum() < 10:
            raise ValueError(f"record '{self.name}': only {int(keep.sum())} samples in [{t0}, {t1}] s")
        cut = lambda a: None if a is None else a[keep]  # noqa: E731
        return replace(
            self,
            t=self.t[keep],
            f=self.f[keep],
            x=cut(self.x),
            v=cut(self.v),
            a=cut(self.a),
            clean=None,
            meta=self.meta.with_(segment=[t0, t1]),
        )


CHANNEL_KINDS = ("x", "v", "a")


def synthetic(
    system: StructuralSystem,
    record: str = "kobe",
    eq_scale: float = 1.0,
    stretch: float = 1.0,
    duration: float | None = 40.0,
    dt: float | None = 0.01,
    noise: float | dict[str, float] = 0.0,
    data_seed: int = 0,
    channels: Sequence[str] = ("x", "v"),
    sensors: Sequence[int] | None = None,
) -> Record:
    """Simulate ``system`` at its true parameters under a ground-motion record and measure it.

    Noise of std ``noise`` x RMS is added to each measured channel (seeded by ``data_seed``);
    ``noise`` may give each channel kind its own level (``{a: 0.025, x: 0.01}``).
    ``sensors``: the floors (1-based) that carry the sensors, default every floor.
    """
    gm = prepare(record, scale=eq_scale, stretch=stretch, duration=duration, dt=dt)
    return synthetic_from_motion(
        system, gm, noise=noise, data_seed=data_seed, channels=channels, sensors=sensors
    )


def synthetic_from_motion(
    system: StructuralSystem,
    gm: GroundMotion,
    noise: float | dict[str, float] = 0.0,
    data_seed: int = 0,
    channels: Sequence[str] = ("x", "v"),
    params: dict[str, float] | None = None,
    sensors: Sequence[int] | None = None,
) -> Record:
    channels = tuple(channels)
    bad = set(channels) - set(CHANNEL_KINDS)
    if bad or not channels:
        raise ValueError(f"data.channels must be among x, v, a (a: accelerometers); got {list(channels)}")
    n = system.n_dof
    floors = list(range(1, n + 1)) if sensors is None else [int(s) for s in sensors]
    if not floors or any(not 1 <= s <= n for s in floors) or len(set(floors)) != len(floors):
        raise ValueError(f"data.sensors must be distinct floors among 1..{n}; got {list(sensors or [])}")
    levels = _noise_levels(noise, channels)
    truth = params or system.true_values()
    clean = simulate(system, truth, gm, gm.t)
    several = system.n_inputs > 1
    full = _measured(system, clean, truth, channels, floors, levels, data_seed)
    return Record(
        name=gm.name,
        t=clean.t,
        f=clean.f,
        x=full.get("x"),
        v=full.get("v"),
        a=full.get("a"),
        excitation=system.excitation,
        truth=dict(truth),
        clean=clean,
        meta=RecordMeta(
            record=gm.name,
            pga=gm.pga,
            dt=gm.dt,
            noise=max(levels.values()),
            noise_levels=levels,
            data_seed=data_seed,
            inputs=list(system.inputs) if several else None,
        ),
    )


def _measured(
    system: StructuralSystem,
    clean,
    truth: dict[str, float],
    channels: tuple[str, ...],
    floors: list[int],
    levels: dict[str, float],
    data_seed: int,
) -> dict[str, np.ndarray]:
    """What the sensors on ``floors`` read of the clean response, with noise: (N, n_dof) per
    channel, NaN where a floor has no sensor. An accelerometer reads the absolute acceleration;
    with one ground it is kept relative to it, with several supports absolute."""
    several = system.n_inputs > 1
    cols = [s - 1 for s in floors]
    sensed = {c: getattr(clean, c)[:, cols] for c in channels}
    ground = 0.0
    if "a" in sensed and system.excitation == "ground":
        # an accelerometer measures the absolute acceleration: the model's reading (several supports:
        # already absolute; a modal model's sensor: the sum of its modes) plus the one ground
        reading = system.acceleration_output(clean.a, clean.f, truth)[:, cols]
        ground = 0.0 if several else np.asarray(clean.f, float)[:, None]
        sensed["a"] = reading + ground
    meas = add_noise(sensed, levels, data_seed)
    if "a" in meas and not several:  # one ground: kept relative; several: no single ground, kept absolute
        meas["a"] = meas["a"] - ground
    full = {}
    for c in channels:
        arr = np.full((len(clean.t), system.n_dof), np.nan)
        arr[:, [s - 1 for s in floors]] = meas[c]
        full[c] = arr
    return full


def _noise_levels(noise: float | dict[str, float] | None, channels: Sequence[str]) -> dict[str, float]:
    if noise is None:
        noise = 0.0
    if isinstance(noise, (int, float)):
        return {c: float(noise) for c in channels}
    levels = {str(k): float(v) for k, v in dict(noise).items()}
    missing, extra = set(channels) - set(levels), set(levels) - set(channels)
    if missing or extra:
        raise ValueError(
            f"noise levels given for {sorted(levels)}; the measured channels are {list(channels)}"
        )
    return levels


def from_csv(
    path: str | Path | None,
    time_col: str = "t",
    excitation: str | None = None,
    units: dict[str, float] | None = None,
    t_end: float | None = None,
    at2: str | Path | None = None,
    acceleration: str = "absolute",
    input_hold: str = "linear",
) -> Record:
    """Read a measured record: columns ``t`` (s), the excitation as ``ag`` (m/s^2, ground) or
    ``u`` (N, force), and any response channels: ``x`` (m), ``v`` (m/s), ``a`` (m/s^2) for a
    single degree of freedom, or per floor ``x1.., v1.., a1..`` (floors without a sensor are
    simply absent). Displacements and velocities are relative to the ground;
    ``acceleration`` says what the ``a`` columns hold: ``absolute`` (what an accelerometer
    measures; ag is subtracted) or ``relative``.

    ``units`` multiplies columns into SI (e.g. ``{"x": 0.001}`` for millimetres). ``at2``
    takes the ground acceleration from a PEER AT2 record (a path or a shipped record's
    name) instead of a column: interpolated at the CSV's times, which start with the record.
    ``input_hold``: how models read the excitation between samples, ``linear`` (a record
    simulated from a piecewise-linear input) or ``bandlimited`` (a measured input, low-pass
    filtered before sampling; see ``pidyn.integrate``).
    """
    path = Path(needed(path, "no file: set data.path=FILE.csv (one record) or 'data.paths=[A.csv,B.csv]'"))
    checked_hold(input_hold, f"{path}: input_hold")
    df = read_table(path, units)
    if at2 is not None:
        ground_from_at2(path, df, time_col, at2)
    if time_col not in df.columns:
        raise DataError(f"{path}: missing column '{time_col}' (columns: {list(df.columns)})")
    if acceleration not in ("absolute", "relative"):
        raise DataError(f"{path}: acceleration must be 'absolute' or 'relative', got '{acceleration}'")
    layout = channel_columns(path, [c for c in df.columns if c != time_col])
    col = excitation_column(path, df, excitation)
    check_values(path, df)
    t = uniform_time(path, df[time_col].to_numpy(float), time_col)
    if t_end is not None:
        keep = t <= t_end + 1e-12
        df, t = df.loc[keep], t[keep]
    f = df[col].to_numpy(float)
    arrays = floor_arrays(df, layout, len(t), f if acceleration == "absolute" and col == "ag" else None)
    return Record(
        name=path.stem,
        t=t - t[0],
        f=f,
        x=arrays.get("x"),
        v=arrays.get("v"),
        a=arrays.get("a"),
        excitation="ground" if col == "ag" else "force",
        meta=RecordMeta(
            path=str(path),
            dt=float(np.mean(np.diff(t))),
            acceleration=acceleration,
            input_hold=input_hold,
        ),
    )


def checked_hold(hold: str, what: str) -> str:
    """``hold`` if the integrator knows it, else a DataError naming ``what``."""
    if hold not in HOLDS:
        raise DataError(f"{what} must be one of {', '.join(HOLDS)}, got '{hold}'")
    return hold
