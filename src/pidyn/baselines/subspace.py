"""Subspace identification of a linear state-space model from inputs and outputs (PO-MOESP,
Verhaegen 1994), at every order from one singular value decomposition.

A stabilisation diagram asks for the modes at many model orders. mdof's SRIM builds and
decomposes its matrices anew at each order (0.4-1 s each on a Painter Street record); here the
extended observability matrix is estimated once, and each order's A and C are read from its
leading columns (a least-squares shift), so twenty orders cost one decomposition. No new
dependency: NumPy only.

The modes of order n are the eigenvalues of A (discrete time, step dt): s = log(lambda) / dt,
frequency |s| / 2 pi, damping ratio -Re(s) / |s|; their shapes are C psi at the outputs, and the
modal phase collinearity (MPC, Pappa et al. 1993) says how close each shape is to a real one (1:
a classically damped mode's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Pole:
    """One mode of one model order: frequency (Hz), damping ratio, shape at the outputs (complex),
    and its modal phase collinearity."""

    order: int
    frequency_hz: float
    damping_ratio: float
    shape: np.ndarray
    mpc: float


def _hankel(w: np.ndarray, rows: int, cols: int, start: int) -> np.ndarray:
    """Block Hankel matrix of the signals ``w`` (channels, N): block row i holds w[:, start+i : start+i+cols]."""
    return np.vstack([w[:, start + i : start + i + cols] for i in range(rows)])


def observability(u: np.ndarray, y: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Left singular vectors and singular values of the PO-MOESP matrix: the extended
    observability matrix's column space, ordered by how much of the outputs each direction carries.

    ``u`` (inputs, N) and ``y`` (outputs, N); ``horizon`` block rows of past and of future."""
    u, y = np.atleast_2d(np.asarray(u, float)), np.atleast_2d(np.asarray(y, float))
    s = int(horizon)
    cols = u.shape[1] - 2 * s + 1
    if cols < 4 * s * (u.shape[0] + y.shape[0]):
        raise ValueError(f"a subspace fit with {s} block rows needs a longer record ({u.shape[1]} samples)")
    scale_u = np.std(u, axis=1, keepdims=True) + 1e-300
    scale_y = np.std(y, axis=1, keepdims=True) + 1e-300
    u, y = u / scale_u, y / scale_y
    Uf, Yf = _hankel(u, s, cols, s), _hankel(y, s, cols, s)
    Zp = np.vstack([_hankel(u, s, cols, 0), _hankel(y, s, cols, 0)])
    # LQ of [Uf; Zp; Yf] (the QR of its transpose): L32 is the future outputs' part that the past
    # explains beyond the future inputs, whose column space is the observability matrix's
    m_u, m_z = Uf.shape[0], Zp.shape[0]
    R = np.linalg.qr(np.vstack([Uf, Zp, Yf]).T / np.sqrt(cols), mode="r")
    L = R.T
    L32 = L[m_u + m_z :, m_u : m_u + m_z]
    U, sv, _ = np.linalg.svd(L32, full_matrices=False)
    # back to the outputs' own units, so that C reads the sensors as they measured
    return U * np.tile(scale_y[:, 0], s)[:, None], sv


def default_horizon(n_samples: int, n_in: int, n_out: int, max_order: int) -> int:
    """Block rows: enough for the highest order (s l > n), as many as the record allows up to 30
    (more rows average more noise out; the Hankel matrices need about 4 s (m + l) columns)."""
    most = (n_samples + 1) // (2 + 4 * (n_in + n_out))
    return int(max(min(30, most), max_order // n_out + 2))


def poles(
    u: np.ndarray, y: np.ndarray, dt: float, orders: list[int], horizon: int | None = None
) -> dict[int, list[Pole]]:
    """The modes (complex-conjugate pairs, one of each) of every order in ``orders``."""
    n_in, n_out = np.atleast_2d(u).shape[0], np.atleast_2d(y).shape[0]
    horizon = int(horizon or default_horizon(np.atleast_2d(u).shape[1], n_in, n_out, max(orders)))
    U, _ = observability(u, y, horizon)
    out: dict[int, list[Pole]] = {}
    for n in orders:
        if n > U.shape[1]:
            continue
        G = U[:, :n]
        A = np.linalg.lstsq(G[:-n_out], G[n_out:], rcond=None)[0]
        out[int(n)] = modes_of(A, G[:n_out], dt, int(n))
    return out


def modes_of(A: np.ndarray, C: np.ndarray, dt: float, order: int) -> list[Pole]:
    """The oscillating modes of a discrete-time (A, C), lowest frequency first."""
    lam, psi = np.linalg.eig(A)
    rows = []
    for i in np.flatnonzero(np.imag(lam) > 1e-12):  # one of each conjugate pair
        s = np.log(lam[i]) / dt
        w = abs(s)
        shape = C @ psi[:, i]
        rows.append(Pole(order, float(w / (2 * np.pi)), float(-s.real / w), shape, mpc(shape)))
    return sorted(rows, key=lambda p: p.frequency_hz)


def mpc(shape: np.ndarray) -> float:
    """Modal phase collinearity of a complex shape: 1 when its components share one phase (the
    spread of its components in the complex plane along their principal axis)."""
    re, im = np.real(shape), np.imag(shape)
    lam = np.linalg.eigvalsh(np.array([[re @ re, re @ im], [re @ im, im @ im]]))
    total = float(lam.sum())
    return float(((lam[1] - lam[0]) / total) ** 2) if total > 0 else 0.0


def real_shape(shape: np.ndarray) -> np.ndarray:
    """A complex shape turned real: rotated so its largest component is real and positive, then
    scaled to 1 at the last output (the roof, where a building's sensors end)."""
    shape = np.asarray(shape, complex)
    rotated = shape * np.exp(-1j * np.angle(shape[np.argmax(np.abs(shape))]))
    re = np.real(rotated)
    return re / re[-1] if abs(re[-1]) > 1e-12 * np.max(np.abs(re)) else re / np.max(np.abs(re))
