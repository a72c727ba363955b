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

    def scales(self) -> dict[str, torch.Tensor]:
        """Per-window scales that make every loss term O(1) (x, v per channel; f overall)."""
        s = {"x": self.x.std(0).clamp_min(1e-12), "f": self.f_pool.std().clamp_min(1e-12)}
        s["v"] = self.v.std(0).clamp_min(1e-12) if self.v is not None else s["x"] * 2 * np.pi / (self.t1 - self.t0)
        s["a"] = self.a.std(0).clamp_min(1e-12) if self.a is not None else s["f"]
        return s


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
) -> list[Window]:
    """Cut a record into equal windows of ``length`` seconds.

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
    record_peak = float(np.max(np.abs(x[(t >= t_start) & (t <= t_end)])))
    T = lambda arr: None if arr is None else torch.as_tensor(np.asarray(arr, float), dtype=dtype)  # noqa: E731
    out = []
    for i in range(n_win):
        t0 = t_start + i * length
        t1 = t0 + length
        m = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
        tp = np.linspace(t0, t1, pool_size)
        peak = float(np.max(np.abs(x[m])))
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
            )
        )
    return out
