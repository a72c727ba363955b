"""The force the nominal model cannot explain, sample by sample, and the record's time scale."""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter, welch

from pidyn.data.windows import double_integral
from pidyn.systems.sdof import SDOFSystem


def dominant_period(t: np.ndarray, x: np.ndarray) -> float:
    """Period of the largest peak of the displacement spectrum (Welch), DC excluded."""
    x = np.asarray(x, float).reshape(len(t), -1)[:, 0]
    dt = float(t[1] - t[0])
    nper = int(min(len(x), max(256, 2 ** int(np.log2(max(len(x) // 8, 2))))))
    f, p = welch(x - x.mean(), fs=1 / dt, nperseg=nper)
    p[0] = 0.0
    return float(1.0 / f[int(np.argmax(p))])


def unexplained_force(
    system: SDOFSystem, values: dict[str, float], t: np.ndarray, x: np.ndarray, xs: np.ndarray, vs: np.ndarray,
    f: np.ndarray, period: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(r, x''): r(t) = excitation force - m x'' - nominal restoring force(x, x').

    x'' comes from the smooth part: the networks' change of variable y = x + q with
    q'' = the excitation as an acceleration makes y smooth (the absolute displacement of a
    base-excited mass), so a Savitzky-Golay second derivative of y loses nothing of a
    broadband ground motion; then x'' = y'' - q''.
    """
    dt = float(t[1] - t[0])
    win = max(5, int(round(period / 6 / dt)) | 1)
    accel = system.excitation_as_acceleration(f)
    q, _ = double_integral(t, accel, t, float(t[0]))
    a = savgol_filter(x + q, win, 3, deriv=2, delta=dt) - accel
    m = values["m"]
    forcing = -m * f if system.excitation == "ground" else f
    return forcing - m * a - system.restoring_force(t, xs, vs, None, values), a
