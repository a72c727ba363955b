"""Subperiod windows: the measured samples and collocation pool of one time slice."""

from __future__ import annotations

from dataclasses import dataclass

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
    x: torch.Tensor
    v: torch.Tensor | None
    a: torch.Tensor | None
    t_pool: torch.Tensor
    f_pool: torch.Tensor
    peak_x: float = 0.0
    informative: bool = True
    # excitation transform: q'' = s(t) (s = ag, or -u/m), q(t0) = q'(t0) = 0; None if unused
    q_data: torch.Tensor | None = None
    qd_data: torch.Tensor | None = None
    q_pool: torch.Tensor | None = None
    qd_pool: torch.Tensor | None = None

    def scales(self) -> dict[str, torch.Tensor]:
        """Per-window scales that make every loss term O(1) (x, v per channel; f overall)."""
        s = {"x": self.x.std(0).clamp_min(1e-12), "f": self.f_pool.std().clamp_min(1e-12)}
        s["v"] = self.v.std(0).clamp_min(1e-12) if self.v is not None else s["x"] * 2 * np.pi / (self.t1 - self.t0)
        s["a"] = self.a.std(0).clamp_min(1e-12) if self.a is not None else s["f"]
        return s


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
    x: np.ndarray,
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
) -> list[Window]:
    """Cut a record into equal windows of ``length`` seconds.

    ``accel_signal`` (the excitation as an acceleration: ag, or -u/m) switches on the
    excitation transform: each window carries q, q' with q'' = accel_signal, so that the
    network can represent the smooth y = x + q instead of x (see ``PIDynNet``).

    The collocation pool holds ``pool_size`` equally spaced times per window with the
    excitation linearly interpolated between samples. A window whose peak |x| is below
    ``min_peak_fraction`` of the record's peak is marked uninformative (it carries almost
    no information on stiffness nonlinearity) but still listed.
    """
    dtype = dtype or torch.get_default_dtype()
    t = np.asarray(t, float)
    x = np.asarray(x, float).reshape(len(t), -1)
    t_start = t[0] if t_start is None else t_start
    t_end = t[-1] if t_end is None else min(t_end, t[-1])
    n_win = max(1, int(np.floor((t_end - t_start) / length + 1e-9)))
    bounds = [(t_start + i * length, t_start + (i + 1) * length) for i in range(n_win)]
    if cover_tail and t_end - bounds[-1][1] > 2 * (t[1] - t[0]):
        bounds.append((bounds[-1][1], t_end))  # a shorter last window so that every sample is covered
    record_peak = float(np.max(np.abs(x[(t >= t_start) & (t <= t_end)])))
    T = lambda arr: None if arr is None else torch.as_tensor(np.asarray(arr, float), dtype=dtype)  # noqa: E731
    out = []
    for i, (t0, t1) in enumerate(bounds):
        m = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
        tp = np.linspace(t0, t1, pool_size)
        peak = float(np.max(np.abs(x[m])))
        qd_ = qdd_ = qp_ = qpd_ = None
        if accel_signal is not None:
            qd_, qdd_ = double_integral(t, np.asarray(accel_signal, float), t[m], t0)
            qp_, qpd_ = double_integral(t, np.asarray(accel_signal, float), tp, t0)
        out.append(
            Window(
                index=i,
                t0=t0,
                t1=t1,
                t_data=T(t[m]),
                f_data=T(np.asarray(f, float)[m]),
                x=T(x[m]),
                v=None if v is None else T(np.asarray(v, float).reshape(len(t), -1)[m]),
                a=None if a is None else T(np.asarray(a, float).reshape(len(t), -1)[m]),
                t_pool=T(tp),
                f_pool=T(np.interp(tp, t, f)),
                peak_x=peak,
                informative=peak >= min_peak_fraction * record_peak,
                q_data=T(qd_),
                qd_data=T(qdd_),
                q_pool=T(qp_),
                qd_pool=T(qpd_),
            )
        )
    return out
