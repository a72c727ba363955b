"""The equation of motion in weak form: regression rows without differentiating noisy data.

Multiply m x'' + sum_j theta_j phi_j(t, x, x') = F(t) by a smooth bump psi that vanishes with
its slope at both ends of a window and integrate; integration by parts moves both
derivatives onto psi:

    m int x psi'' dt + sum_j theta_j int phi_j psi dt = int F psi dt.

One row per window position. The measured x enters only through integrals, so measurement
noise is averaged rather than amplified, and the excitation enters exactly (no smoothing of a
broadband ground acceleration). This is the modulating-function method (Shinbrot 1957) and
the weak form of weak SINDy (Messenger and Bortz 2021).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_coeffs, savgol_filter


def bump(half: int, dt: float, power: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """psi(s) = (1 - s^2)^power on 2 half + 1 samples, and psi'' in physical time."""
    s = np.linspace(-1.0, 1.0, 2 * half + 1)
    L = half * dt  # half width in seconds; s = tau / L
    psi = (1 - s**2) ** power
    p = power
    d2 = (-2 * p * (1 - s**2) ** (p - 1) + 4 * p * (p - 1) * s**2 * (1 - s**2) ** (p - 2)) / L**2
    return psi, d2


def _window_integrals(y: np.ndarray, kernel: np.ndarray, dt: float, starts: np.ndarray) -> np.ndarray:
    """Trapezoid-free Riemann sums of y * kernel over windows starting at ``starts`` (the kernel
    vanishes at both ends, so the rectangle and trapezoid rules agree)."""
    y = np.asarray(y, float)
    if y.ndim == 1:
        y = y[:, None]
    full = np.stack([np.convolve(y[:, j], kernel[::-1], mode="valid") for j in range(y.shape[1])], axis=1)
    return dt * full[starts] if len(full) else np.zeros((0, y.shape[1]))


@dataclass
class WeakForm:
    """Windows (half width, stride) on a record and the rows they produce."""

    t: np.ndarray
    half: int
    stride: int

    @classmethod
    def for_record(cls, t: np.ndarray, period: float, windows_per_period: float = 1.0) -> WeakForm:
        """Windows one natural period wide (at least 7 samples), four rows per window width."""
        dt = float(t[1] - t[0])
        half = max(3, int(round(0.5 * period / windows_per_period / dt)))
        stride = max(1, (2 * half + 1) // 4)
        return cls(np.asarray(t, float), half, stride)

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def starts(self) -> np.ndarray:
        w = 2 * self.half + 1
        return np.arange(0, len(self.t) - w + 1, self.stride)

    @property
    def centers(self) -> np.ndarray:
        return self.t[self.starts + self.half]

    @property
    def rows_per_independent(self) -> float:
        """Overlapping rows per independent row, for honest information criteria.

        Rows ``stride`` samples apart integrate white noise against the same bump psi, so row
        j and j + m correlate as sum_i psi_i psi_{i + m stride} / sum_i psi_i^2. A sum over
        the rows varies as if there were N / sum_m rho_m independent ones, and
        sum_m rho_m = (sum psi)^2 / (stride sum psi^2): about 1.1 half / stride for this bump.
        Counting one row per non-overlapping window, (2 half + 1) / stride, undercounts by
        1.8x: on noise-only records a two-sided one-column effect's likelihood ratio then
        averaged 0.67 instead of chi2_1's 1 (``test_information_count_is_calibrated_on_noise``).
        """
        psi, _ = bump(self.half, self.dt)
        return float(np.sum(psi) ** 2 / np.sum(psi**2)) / self.stride

    def project(self, y: np.ndarray) -> np.ndarray:
        psi, _ = bump(self.half, self.dt)
        return _window_integrals(y, psi, self.dt, self.starts)

    def inertia(self, x: np.ndarray, mass: float) -> np.ndarray:
        _, d2 = bump(self.half, self.dt)
        return mass * _window_integrals(x, d2, self.dt, self.starts)[:, 0]


def smooth_signals(
    t: np.ndarray, x: np.ndarray, v: np.ndarray | None, period: float
) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay smoothed x and x' (x' from the measured velocity when there is one).

    The window is a sixth of the natural period (at least 5 samples): it removes
    measurement noise and keeps the structural response.
    """
    win = _sg_window(t, period)
    dt = float(t[1] - t[0])
    xs = savgol_filter(x, win, 3)
    vs = savgol_filter(v, win, 3) if v is not None else savgol_filter(x, win, 3, deriv=1, delta=dt)
    return xs, vs


def _sg_window(t: np.ndarray, period: float) -> int:
    dt = float(t[1] - t[0])
    win = max(5, int(round(period / 6 / dt)) | 1)
    return min(win, len(t) - 1 if len(t) % 2 == 0 else len(t))


def velocity_noise(t: np.ndarray, x: np.ndarray, v: np.ndarray | None, period: float) -> float:
    """Standard deviation of the measurement noise left in the smoothed velocity.

    The raw-minus-smoothed signal estimates the white measurement noise; the smoothing
    filter's noise gain (the 2-norm of its coefficients) carries it to the smoothed x'.
    """
    win = _sg_window(t, period)
    dt = float(t[1] - t[0])
    raw = v if v is not None else x
    sigma = measurement_noise(t, raw, period)
    h = savgol_coeffs(win, 3) if v is not None else savgol_coeffs(win, 3, deriv=1, delta=dt)
    return sigma * float(np.sqrt(np.sum(h**2)))


def measurement_noise(t: np.ndarray, raw: np.ndarray, period: float) -> float:
    """Standard deviation of the white measurement noise in ``raw``.

    The raw-minus-smoothed signal holds the noise less the share the smoother keeps, ||h||^2
    of its variance (h: the filter's coefficients; a least-squares smoother is a projection);
    uncorrected, the estimate is low by that share, and in a quiet part of a record, where the
    noise is a large share of the signal, the shortfall reads as model error."""
    win = _sg_window(t, period)
    h0 = savgol_coeffs(win, 3)
    return float(np.std(raw - savgol_filter(raw, win, 3))) / np.sqrt(max(1 - np.sum(h0**2), 1e-12))
