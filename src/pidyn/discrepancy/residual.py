"""The force the nominal model cannot explain, sample by sample."""

from __future__ import annotations

import numpy as np

from pidyn.signals import band_limited
from pidyn.systems.sdof import SDOFSystem


def unexplained_force(
    system: SDOFSystem,
    values: dict[str, float],
    t: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    period: float,
) -> dict[str, np.ndarray]:
    """r(t) = excitation force - m x'' - nominal restoring force(x, x'), sample by sample.

    Everything (x, its derivatives and the excitation) is low-passed at the same band, three
    times the natural frequency (at most 0.9 x Nyquist): measurement noise above it is
    removed, and a linear model's terms stay consistent, so the residual shows only what
    the model lacks. Returns ``r`` and the band-limited ``x``, ``v``, ``a``.
    """
    dt = float(t[1] - t[0])
    f_cut = min(0.45 / dt, 3.0 / period)
    xl, vl, al = band_limited(np.asarray(x, float), dt, f_cut)
    m = values["m"]
    forcing = -m * f if system.excitation == "ground" else f
    fl = band_limited(np.asarray(forcing, float), dt, f_cut)[0]
    r = fl - m * al - system.restoring_force(t, xl, vl, None, values)
    return {"r": r, "x": xl, "v": vl, "a": al, "f_cut": np.array(f_cut)}
