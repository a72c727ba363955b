"""Signal processing every part shares (NumPy and SciPy only): integrating accelerations to
velocities and displacements, the transfer function of a measured structure, and the low-band
cross-correlation that times one sensor against another.

Integration is spectral, with one zero-phase high-pass applied to every signal alike. A
linear equation of motion holds after any linear time-invariant filter applied to all its
terms, so the same filter on the excitation, the acceleration and the integrated velocity and
displacement keeps a linear model exactly true of the filtered signals, while the drift an
integration of noise would bring is gone. (A rectangle-rule integration lags half a sample:
at 4 Hz and 50 Hz sampling that phase is 0.25 rad, more than the damping of a bridge; a
trapezoid rule warps the gain; the spectral one is exact in the band it keeps.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, csd, sosfiltfilt, welch


def highpass_gain(freq: np.ndarray, corner: float, order: int = 4) -> np.ndarray:
    """Zero-phase high-pass: the magnitude of a Butterworth filter of ``order`` at ``corner`` Hz."""
    f = np.maximum(np.abs(freq), 1e-12)
    return 1.0 / np.sqrt(1.0 + (corner / f) ** (2 * order))


def integrate(y: np.ndarray, dt: float, times: int, corner: float, order: int = 4) -> np.ndarray:
    """``y`` (N,) or (N, k) high-passed at ``corner`` Hz and integrated ``times`` times (0: the
    filter alone), spectrally on a zero-padded grid: the same operator for every signal."""
    y = np.asarray(y, float)
    n = y.shape[0]
    m = 2 * n
    Y = np.fft.rfft(y, m, axis=0)
    f = np.fft.rfftfreq(m, dt)
    g = highpass_gain(f, corner, order)
    w = 2j * np.pi * f
    w[0] = 1.0
    op = g / w**times
    op[0] = 0.0
    shape = (len(f),) + (1,) * (y.ndim - 1)
    return np.fft.irfft(Y * op.reshape(shape), m, axis=0)[:n]


#: half-power width of a pure tone seen through a Hann window, in frequency bins
HANN_HALF_POWER_BINS = 1.44


@dataclass
class TransferFunction:
    """H1 estimate of output / input (Welch), with the coherence."""

    freq: np.ndarray
    h: np.ndarray  # complex
    coherence: np.ndarray
    segments: int  # Welch averages (independent-ish segments)
    input_power: np.ndarray | None = None  # S_uu: where the input has no power, H is noise


def transfer_function(
    u: np.ndarray, y: np.ndarray, dt: float, nperseg: int | None = None
) -> TransferFunction:
    """H1 = S_uy / S_uu and the coherence, by Welch averaging (Hann windows, half overlap; by
    default segments of about a quarter of the record: a resolution of 4 / duration)."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    n = len(u)
    if nperseg is None:
        nperseg = int(min(n, max(256, 2 ** int(round(np.log2(max(n / 4, 2)))))))
    f, suu = welch(u, fs=1 / dt, nperseg=nperseg)
    _, syy = welch(y, fs=1 / dt, nperseg=nperseg)
    _, suy = csd(u, y, fs=1 / dt, nperseg=nperseg)
    with np.errstate(all="ignore"):
        h = suy / suu
        coh = np.abs(suy) ** 2 / (suu * syy)
    segments = max(1, int((n - nperseg) // (nperseg // 2) + 1))
    return TransferFunction(f, np.nan_to_num(h), np.nan_to_num(coh), segments, suu)


def transmissibility(freq: np.ndarray, fn: float, zeta: float) -> np.ndarray:
    """Absolute-acceleration transmissibility of a base-excited oscillator,
    (wn^2 + 2 i zeta wn w) / (wn^2 - w^2 + 2 i zeta wn w)."""
    w, wn = 2 * np.pi * np.asarray(freq, float), 2 * np.pi * fn
    return (wn**2 + 2j * zeta * wn * w) / (wn**2 - w**2 + 2j * zeta * wn * w)


def powered(tf: TransferFunction, sel: np.ndarray) -> np.ndarray:
    """The frequencies of ``sel`` where the input carries power, above 1e-3 of its peak there: a
    band-limited record's H beyond its band is noise over nothing."""
    if tf.input_power is None or not sel.any():
        return sel
    return sel & (tf.input_power >= 1e-3 * float(np.max(tf.input_power[sel])))


def dominant_peak(tf: TransferFunction, band: tuple[float, float]) -> tuple[float, float]:
    """(frequency, damping ratio by the half-power width; NaN when the peak is no wider than the
    frequency bins) of the largest |H| in ``band`` (Hz),
    on |H| weighted by the coherence, where the input carries power (above 1e-3 of its peak: a
    band-limited record's H beyond its band is noise over nothing), so that a peak of noise does
    not win; the frequency refined by a parabola through the log-magnitude's three top bins."""
    sel = powered(tf, (tf.freq >= band[0]) & (tf.freq <= band[1]))
    if not sel.any():
        raise ValueError(f"no frequency of the transfer function in {band} Hz")
    mag = np.abs(tf.h) * np.sqrt(np.clip(tf.coherence, 0.0, 1.0))
    idx = np.flatnonzero(sel)
    i = int(idx[np.argmax(mag[idx])])
    half = mag[i] / np.sqrt(2.0)
    lo, hi = i, i
    while lo > 0 and mag[lo] > half:
        lo -= 1
    while hi < len(mag) - 1 and mag[hi] > half:
        hi += 1
    f_lo = _cross(tf.freq[lo], tf.freq[lo + 1], mag[lo], mag[lo + 1], half)
    f_hi = _cross(tf.freq[hi - 1], tf.freq[hi], mag[hi - 1], mag[hi], half)
    df = float(tf.freq[1] - tf.freq[0])
    fn = float(tf.freq[i])
    if 0 < i < len(mag) - 1 and min(mag[i - 1], mag[i], mag[i + 1]) > 0:
        a, b, c = np.log(mag[i - 1]), np.log(mag[i]), np.log(mag[i + 1])
        den = a - 2 * b + c
        if den < 0:
            fn += df * float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    # the Hann window alone widens a line to 1.44 bins at half power: what is left is the resonance's
    width = float(np.sqrt(max((f_hi - f_lo) ** 2 - (HANN_HALF_POWER_BINS * df) ** 2, 0.0)))
    if width < df:  # no wider than the bins: the damping is below the resolution
        return fn, float("nan")
    return fn, float(width / (2 * fn))


def _cross(f0: float, f1: float, m0: float, m1: float, level: float) -> float:
    if m1 == m0:
        return 0.5 * (f0 + f1)
    return float(f0 + (level - m0) * (f1 - f0) / (m1 - m0))


def dominant_period(t: np.ndarray, x: np.ndarray) -> float:
    """Period of the largest peak of the displacement spectrum (Welch), DC excluded."""
    x = np.asarray(x, float).reshape(len(t), -1)[:, 0]
    dt = float(t[1] - t[0])
    nper = int(min(len(x), max(256, 2 ** int(np.log2(max(len(x) // 8, 2))))))
    f, p = welch(x - x.mean(), fs=1 / dt, nperseg=nper)
    p[0] = 0.0
    return float(1.0 / f[int(np.argmax(p))])


def band_limited(y: np.ndarray, dt: float, f_cut: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """y, y', y'' low-passed at ``f_cut`` (Hz) by FFT of the even extension of y.

    Spectral derivatives are exact for the band they keep, where a local polynomial filter
    needs many samples per period: at 9 samples per period (the Silverbox) a 5-point
    Savitzky-Golay x'' leaves 43 % of the force unexplained in a linear fit, the band-limited
    one 3.5 %. The even extension keeps the ends continuous; their few samples still ring.
    """
    n = len(y)
    ext = np.concatenate([y, y[::-1]])
    f = np.fft.rfftfreq(2 * n, dt)
    Y = np.fft.rfft(ext) * (f <= f_cut)
    w = 2j * np.pi * f
    out = [np.fft.irfft(Y * w**k, 2 * n)[:n] for k in range(3)]
    return out[0], out[1], out[2]


#: the damping ratio taken when the resonance peak is no wider than the frequency resolution
UNRESOLVED_DAMPING = 0.02


def fundamental(record) -> tuple[float, float] | None:
    """Frequency (Hz) and damping ratio of the fundamental resonance: the largest peak of the
    top measured floor's transmissibility from the (mean) input, coherence-weighted."""
    u, y = _input_output(record)
    if u is None or y is None or not np.any(y) or not np.any(u):
        return None
    dt = record.dt
    duration = float(record.t[-1] - record.t[0])
    tf = transfer_function(u, y, dt)
    band = (max(2.0 / duration, tf.freq[1]), 0.4 / dt)
    try:
        fn, zeta = dominant_peak(tf, band)
    except ValueError:
        return None
    if not np.isfinite(zeta):  # narrower than the frequency bins: light damping, its value unresolved
        zeta = UNRESOLVED_DAMPING
    return fn, float(np.clip(zeta, 0.005, 0.5))


def response_pair(record) -> tuple[str, np.ndarray]:
    """The top measured floor's response relative to the ground, and its kind (x, v or a): an
    accelerometer's absolute reading less the (mean) input acceleration."""
    u, y = _input_output(record)
    sensors = record.sensors()
    if "a" in sensors and record.excitation == "ground" and u is not None and y is not None:
        return "a", y - u
    kind = next(k for k in ("x", "v", "a") if k in sensors)
    return kind, getattr(record, kind)[:, max(sensors[kind]) - 1]


def _input_output(record) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The excitation (several inputs: their mean) and the top measured floor's response: its
    absolute acceleration where an accelerometer gives it (a transmissibility), else the
    displacement or velocity as measured (a receptance: its peak sits at the resonance too, and
    no noisy derivative is taken)."""
    f = np.asarray(record.f, float)
    u = f[:, : record.n_inputs].mean(axis=1) if f.ndim == 2 else f  # several: the supports' mean acceleration
    sensors = record.sensors()
    if "a" in sensors and record.excitation == "ground":
        y = record.a[:, max(sensors["a"]) - 1]
        return u, (y if f.ndim == 2 else y + f)
    kind = next((k for k in ("x", "v", "a") if k in sensors), None)
    return (u, None) if kind is None else (u, getattr(record, kind)[:, max(sensors[kind]) - 1])


def band(sig: np.ndarray, dt: float, lo: float, hi: float) -> np.ndarray:
    """Zero-phase band-pass (4th-order Butterworth, forward and back)."""
    sos = butter(4, [lo, min(hi, 0.45 / dt)], btype="bandpass", fs=1.0 / dt, output="sos")
    return sosfiltfilt(sos, sig, axis=0)


def lagged_correlation(
    ref: np.ndarray, sig: np.ndarray, dt: float, max_lag_s: float, band_hz: tuple[float, float]
) -> np.ndarray:
    """Normalised cross-correlation of the band-passed signals (cut to the shorter) at lags of
    -m..m samples, m = max_lag_s / dt: entry m + L compares ``ref`` at t with ``sig`` at t + L
    (a peak at L > 0: ``sig`` later)."""
    n = min(len(ref), len(sig))
    a, b = band(ref[:n], dt, *band_hz), band(sig[:n], dt, *band_hz)
    m = int(round(max_lag_s / dt))
    size = 1 << int(np.ceil(np.log2(2 * n)))
    cc = np.fft.irfft(np.conj(np.fft.rfft(a, size)) * np.fft.rfft(b, size), size)
    cc = np.concatenate([cc[-m:], cc[: m + 1]]) if m else cc[:1]
    return cc / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-300)


def peak_fraction(c: np.ndarray, i: int) -> float:
    """Where between samples the maximum at ``c[i]`` lies (-0.5..0.5): a parabola through it and its
    neighbours; 0 at either end or where the three do not bend down."""
    if not 0 < i < len(c) - 1:
        return 0.0
    den = c[i - 1] - 2 * c[i] + c[i + 1]
    return 0.5 * (c[i - 1] - c[i + 1]) / den if den < 0 else 0.0
