"""What an engineer reads first from an identified building: natural frequencies, damping
ratios and mode shapes of its linear part (about rest).

The undamped problem K phi = omega^2 M phi gives frequencies and mode shapes; each mode's
damping ratio is zeta_r = phi_r^T C phi_r / (2 omega_r phi_r^T M phi_r), exact for classically
damped structures and the usual modal estimate otherwise. Mode shapes are scaled to a unit
roof component and signed so that it is positive.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from scipy.linalg import eigh

from pidyn.errors import error_pct


def modal_properties(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> dict:
    """Frequencies (Hz), periods (s), damping ratios and mode shapes (columns) of M, C, K."""
    w2, phi = eigh(K, M)
    w2 = np.clip(w2, 0.0, None)
    omega = np.sqrt(w2)
    phi = phi / np.where(np.abs(phi[-1]) > 1e-12, phi[-1], 1.0)
    zeta = np.array([phi[:, r] @ C @ phi[:, r] / max(2 * omega[r] * (phi[:, r] @ M @ phi[:, r]), 1e-300)
                     for r in range(len(omega))])
    freq = omega / (2 * np.pi)
    return {
        "frequency_hz": freq.tolist(),
        "period_s": [float(1 / f) if f > 0 else float("inf") for f in freq],
        "damping_ratio": zeta.tolist(),
        "mode_shapes": phi.T.tolist(),  # one row per mode, one value per floor
    }


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """Modal assurance criterion of two mode shapes (1: the same shape)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float((a @ b) ** 2 / max((a @ a) * (b @ b), 1e-300))


def compare_modes(system, identified: Mapping[str, float], truth: Mapping[str, float] | None) -> dict:
    """The identified model's modal properties, and beside them the truth's with relative
    frequency and damping errors (%) and the MAC of each mode shape when the truth is known."""
    out = {"identified": modal_properties(*system.linear_matrices(identified))}
    if truth and all(v is not None for v in truth.values()):
        tr = modal_properties(*system.linear_matrices(truth))
        out["truth"] = tr
        idf = out["identified"]
        out["frequency_error_pct"] = [error_pct(a, b) for a, b in zip(idf["frequency_hz"], tr["frequency_hz"])]
        out["damping_error_pct"] = [error_pct(a, b) for a, b in zip(idf["damping_ratio"], tr["damping_ratio"])]
        out["mac"] = [mac(a, b) for a, b in zip(idf["mode_shapes"], tr["mode_shapes"])]
    return out


def modal_table(modes: dict) -> str:
    """A markdown table of the modes (identified, and the truth where known)."""
    idf, tr = modes["identified"], modes.get("truth")
    head = "| mode | f (Hz) | zeta (%) | shape (floor 1..N) |" + (" f true (Hz) | zeta true (%) | MAC |" if tr else "")
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for r, (f, z, ph) in enumerate(zip(idf["frequency_hz"], idf["damping_ratio"], idf["mode_shapes"])):
        row = f"| {r + 1} | {f:.4f} | {100 * z:.3f} | {', '.join(f'{v:.3f}' for v in ph)} |"
        if tr:
            row += f" {tr['frequency_hz'][r]:.4f} | {100 * tr['damping_ratio'][r]:.3f} | {modes['mac'][r]:.5f} |"
        rows.append(row)
    return "\n".join(rows)
