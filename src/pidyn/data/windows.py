"""Subperiod windows: the measured samples and collocation pool of one time slice."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np
import torch


@dataclass
class Window:
    """One subperiod [t0, t1]: measured channels at sample times plus a collocation pool.

    ``f_*`` is the excitation (ground acceleration or force) at those times; ``x``, ``v``,
    ``a`` are measured response channels (None where not measured).
    """

    index: int
    t0: float
    t1: float
    t_data: torch.Tensor
    f_data: torch.Tensor
    x: torch.Tensor | None
    v: torch.Tensor | None
    a: torch.Tensor | None
    t_pool: torch.Tensor
    f_pool: torch.Tensor
    peak_x: float = 0.0
    informative: bool = True
    piece: int = 0  # which record of several (``pidyn.data.multi``) the window is cut from
    # excitation transform: q'' = s(t) (s = ag, or -u/m), q(t0) = q'(t0) = 0; None if unused
    q_data: torch.Tensor | None = None
    qd_data: torch.Tensor | None = None
    q_pool: torch.Tensor | None = None
    qd_pool: torch.Tensor | None = None
    # per channel: measured at every floor and sample (read on the host once, so that the losses
    # never ask the device), and the pretraining fill of the floors without a sensor
    complete: dict[str, bool] = field(default_factory=dict, repr=False)
    _filled: dict[str, tuple[torch.Tensor, bool]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        for kind in ("x", "v", "a"):
            arr = getattr(self, kind)
            if arr is not None and kind not in self.complete:
                self.complete[kind] = not bool(torch.isnan(arr).any())

    def to(self, device: torch.device | str) -> Window:
        """A copy with every tensor on ``device`` (the window itself stays where it is)."""
        moved = {
            f.name: getattr(self, f.name).to(device)
            for f in fields(self)
            if isinstance(getattr(self, f.name), torch.Tensor)
        }
        return replace(
            self,
            **moved,
            complete=dict(self.complete),
            _filled={k: (v.to(device), c) for k, (v, c) in self._filled.items()},
        )

    def scales(self) -> dict[str, torch.Tensor]:
        """Per-window scales that make every loss term O(1) (x, v, a per degree of freedom; f
        overall). A floor without a displacement sensor gets the spread of its velocity or
        acceleration integrated and detrended (a scale only, never a target), a floor without
        any sensor that of the nearest floor with one."""
        s = {"f": self.f_pool.std().clamp_min(1e-12)}
        if self.complete.get("x", False):
            s["x"] = self.x.std(0).clamp_min(1e-12)
        else:
            s["x"] = torch.as_tensor(self.displacement_scale(), dtype=self.t_data.dtype).clamp_min(1e-12)
        w = 2 * np.pi / (self.t1 - self.t0)
        s["v"] = _fill(_nanstd(self.v), s["x"] * w) if self.v is not None else s["x"] * w
        s["a"] = (
            _fill(_nanstd(self.a), s["v"] * w) if self.a is not None else s["f"] * torch.ones_like(s["x"])
        )
        return s

    def filled(self, kind: str) -> tuple[torch.Tensor | None, bool]:
        """Channel ``kind`` with the floors that lack the sensor filled by linear interpolation
        over the floor number from the floors that have it (nearest floor beyond the ends): a
        starting shape for the networks' pretraining, never a target of the identification.
        Also whether no NaN is left (a dropout inside a floor's record stays NaN). Computed
        once, on the host."""
        arr = getattr(self, kind)
        if arr is None or self.complete.get(kind, False):
            return arr, arr is not None
        if kind not in self._filled:
            host = arr.detach().cpu()
            seen = ~torch.isnan(host).all(0)
            if not bool(seen.any()):
                return arr, False
            have = torch.nonzero(seen)[:, 0].numpy()
            a = host.double().numpy()
            out = np.stack([np.interp(np.arange(a.shape[1]), have, a[i, have]) for i in range(a.shape[0])])
            self._filled[kind] = (
                torch.as_tensor(out, dtype=arr.dtype, device=arr.device),
                not np.isnan(out).any(),
            )
        return self._filled[kind]

    def displacement_scale(self) -> np.ndarray:
        """Spread of the displacement per degree of freedom, measured or estimated."""
        chans = [
            (k, None if c is None else c.double().numpy())
            for k, c in (("x", self.x), ("v", self.v), ("a", self.a))
        ]
        return spread_by_integration(self.t_data.double().numpy(), chans, 0)


def spread_by_integration(
    t: np.ndarray, channels: list[tuple[str, np.ndarray | None]], order: int
) -> np.ndarray:
    """Spread of the ``order``-th derivative (0: displacement, 1: velocity) per degree of
    freedom from the channels (kind, (N, n_dof) with NaN columns where a floor has no
    sensor): the channel of that order where measured, else a higher one integrated and
    detrended, else the nearest floor's value."""
    levels = {"x": 0, "v": 1, "a": 2}
    n = next(c.shape[1] for _, c in channels if c is not None)
    out = np.full(n, np.nan)
    for j in range(n):
        for kind, chan in sorted(channels, key=lambda kc: levels[kc[0]]):
            col = None if chan is None or levels[kind] < order else np.asarray(chan, float)[:, j]
            if col is None or np.all(np.isnan(col)):
                continue
            times = levels[kind] - order
            out[j] = np.std(col, ddof=1) if times == 0 else np.std(_integrate(t, col, times))
            break
    known = np.flatnonzero(np.isfinite(out))
    if not known.size:
        return np.ones(n)
    for j in np.flatnonzero(~np.isfinite(out)):
        out[j] = out[known[np.argmin(np.abs(known - j))]]
    return out


def _nanstd(arr: torch.Tensor) -> torch.Tensor:
    """Column spread over the samples that were measured (NaN for an unmeasured column)."""
    m = ~torch.isnan(arr)
    if bool(m.all()):
        return arr.std(0)
    cnt = m.sum(0).clamp_min(1)
    mean = torch.where(m, arr, 0.0).sum(0) / cnt
    var = torch.where(m, (arr - mean) ** 2, 0.0).sum(0) / (cnt - 1).clamp_min(1)
    return torch.where(m.any(0), var.sqrt(), torch.full_like(mean, float("nan")))


def _fill(primary: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    return torch.where(torch.isfinite(primary), primary, fallback).clamp_min(1e-12)


def _integrate(t: np.ndarray, y: np.ndarray, times: int) -> np.ndarray:
    """Integrate ``times`` times by the trapezoidal rule, removing a polynomial trend of the
    integration order after each pass (the unknown initial values and the drift of noise)."""
    out = np.asarray(y, float)
    tau = (t - t[0]) / max(t[-1] - t[0], 1e-12)
    for k in range(times):
        out = np.concatenate([[0.0], np.cumsum(0.5 * (out[1:] + out[:-1]) * np.diff(t))])
        out = out - np.polyval(np.polyfit(tau, out, k + 1), tau)
    return out


def double_integral(t: np.ndarray, s: np.ndarray, tq: np.ndarray, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact q, q' at ``tq`` with q'' = s (piecewise linear through the samples), q(t0) = q'(t0) = 0.

    Integrated from the record start in float64, then the value and slope at t0 removed,
    which leaves q'' unchanged.
    """
    h = np.diff(t)
    ds = np.diff(s)
    v_nodes = np.concatenate([[0.0], np.cumsum(s[:-1] * h + ds * h / 2)])
    d_nodes = np.concatenate([[0.0], np.cumsum(v_nodes[:-1] * h + s[:-1] * h**2 / 2 + ds * h**2 / 6)])

    def at(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
        tau, hh = x - t[i], h[i]
        slope = ds[i] / hh
        v = v_nodes[i] + s[i] * tau + slope * tau**2 / 2
        d = d_nodes[i] + v_nodes[i] * tau + s[i] * tau**2 / 2 + slope * tau**3 / 6
        return d, v

    d0, v0 = at(np.array([t0]))
    d, v = at(np.asarray(tq, float))
    return d - d0[0] - v0[0] * (np.asarray(tq) - t0), v - v0[0]


def make_windows(
    t: np.ndarray,
    f: np.ndarray,
    x: np.ndarray | None,
    v: np.ndarray | None,
    a: np.ndarray | None,
    length: float,
    pool_size: int,
    min_peak_fraction: float = 0.0,
    t_start: float | None = None,
    t_end: float | None = None,
    dtype: torch.dtype | None = None,
    accel_signal: np.ndarray | None = None,
    cover_tail: bool = False,
    pieces: list[tuple[float, float]] | None = None,
) -> list[Window]:
    """Cut a record into equal windows of ``length`` seconds.

    ``pieces``: the time spans of the records a record is made of (``pidyn.data.multi``): each is
    cut on its own, so that no window spans two records, and the windows take turns between
    the records (the first of each, then the second of each, ...) so that a budget of windows
    sees every record.

    ``accel_signal`` (the excitation as an acceleration: ag, or -u/m) switches on the
    excitation transform: each window carries q, q' with q'' = accel_signal, so that the
    network can represent the smooth y = x + q instead of x (see ``PIDynNet``).

    The collocation pool holds ``pool_size`` equally spaced times per window with the
    excitation linearly interpolated between samples. A window whose peak |x| is below
    ``min_peak_fraction`` of the record's peak is marked uninformative (it carries almost
    no information on stiffness nonlinearity) but still listed. Without a displacement channel
    the peak is that of the first measured one (velocity, else acceleration).
    """
    dtype = dtype or torch.get_default_dtype()
    t = np.asarray(t, float)
    as2d = lambda arr: None if arr is None else np.asarray(arr, float).reshape(len(t), -1)  # noqa: E731
    x, v, a = as2d(x), as2d(v), as2d(a)
    ref = next(c for c in (x, v, a) if c is not None)
    t_start = t[0] if t_start is None else t_start
    t_end = t[-1] if t_end is None else min(t_end, t[-1])
    bounds = [(t0, t1, 0) for t0, t1 in window_bounds(t, length, t_start, t_end, cover_tail)]
    if pieces and len(pieces) > 1:
        bounds = _taking_turns(t, length, t_start, t_end, cover_tail, pieces)
    record_peak = float(np.nanmax(np.abs(ref[(t >= t_start) & (t <= t_end)])))
    series = _Series(t, np.asarray(f, float), x, v, a, ref, accel_signal)
    out = []
    for i, (t0, t1, k) in enumerate(bounds):
        w = _window(i, t0, t1, series, pool_size, min_peak_fraction * record_peak, dtype)
        w.piece = k
        out.append(w)
    return out


def _taking_turns(
    t: np.ndarray,
    length: float,
    t_start: float,
    t_end: float,
    cover_tail: bool,
    pieces: list[tuple[float, float]],
) -> list[tuple[float, float, int]]:
    """Every record's windows within [t_start, t_end], in turns: (t0, t1, record)."""
    per = []
    for k, (p0, p1) in enumerate(pieces):
        lo, hi = max(p0, t_start), min(p1, t_end)
        per.append(
            [(a, b, k) for a, b in window_bounds(t, length, lo, hi, cover_tail)] if hi - lo >= length else []
        )
    if not any(per):
        raise ValueError(f"no record holds a window of {length:g} s within [{t_start:g}, {t_end:g}] s")
    turns = []
    for j in range(max(len(p) for p in per)):
        turns += [p[j] for p in per if j < len(p)]
    return turns


@dataclass
class _Series:
    """The record's samples a window is cut from, the reference channel for its peak, and the
    excitation as an acceleration (the excitation transform) when it is on."""

    t: np.ndarray
    f: np.ndarray
    x: np.ndarray | None
    v: np.ndarray | None
    a: np.ndarray | None
    ref: np.ndarray
    accel_signal: np.ndarray | None


def _window(
    i: int, t0: float, t1: float, r: _Series, pool_size: int, min_peak: float, dtype: torch.dtype
) -> Window:
    """Window ``i`` over [t0, t1]: its samples, its collocation pool and excitation transform."""
    t, f, x, v, a = r.t, r.f, r.x, r.v, r.a
    T = lambda arr: None if arr is None else torch.as_tensor(np.asarray(arr, float), dtype=dtype)  # noqa: E731
    m = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
    tp = np.linspace(t0, t1, pool_size)
    peak = float(np.nanmax(np.abs(r.ref[m])))
    q = _transform(t, r.accel_signal, m, tp, t0)
    return Window(
        index=i,
        t0=t0,
        t1=t1,
        t_data=T(t[m]),
        f_data=T(np.asarray(f, float)[m]),
        x=None if x is None else T(x[m]),
        v=None if v is None else T(v[m]),
        a=None if a is None else T(a[m]),
        t_pool=T(tp),
        f_pool=T(_interp(tp, t, f)),
        peak_x=peak,
        informative=peak >= min_peak,
        **{k: T(val) for k, val in q.items()},
    )


def _interp(tq: np.ndarray, t: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The excitation between samples, linear; one column per input when there are several."""
    f = np.asarray(f, float)
    if f.ndim == 1:
        return np.interp(tq, t, f)
    return np.stack([np.interp(tq, t, f[:, j]) for j in range(f.shape[1])], axis=-1)


def window_bounds(
    t: np.ndarray, length: float, t_start: float, t_end: float, cover_tail: bool = False
) -> list[tuple[float, float]]:
    """Equal windows of ``length`` s over [t_start, t_end]; with ``cover_tail`` a shorter last
    window so that every sample is covered."""
    n_win = max(1, int(np.floor((t_end - t_start) / length + 1e-9)))
    bounds = [(t_start + i * length, t_start + (i + 1) * length) for i in range(n_win)]
    if cover_tail and t_end - bounds[-1][1] > 2 * (t[1] - t[0]):
        bounds.append((bounds[-1][1], t_end))
    return bounds


def _transform(
    t: np.ndarray, accel_signal: np.ndarray | None, m: np.ndarray, tp: np.ndarray, t0: float
) -> dict[str, np.ndarray | None]:
    """The excitation transform's q, q' on the window's samples and collocation pool (None: off)."""
    if accel_signal is None:
        return {"q_data": None, "qd_data": None, "q_pool": None, "qd_pool": None}
    acc = np.asarray(accel_signal, float)
    q_data, qd_data = double_integral(t, acc, t[m], t0)
    q_pool, qd_pool = double_integral(t, acc, tp, t0)
    return {"q_data": q_data, "qd_data": qd_data, "q_pool": q_pool, "qd_pool": qd_pool}
