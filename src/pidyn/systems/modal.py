"""What an engineer reads first from an identified building: natural frequencies, damping
ratios and mode shapes of its linear part (about rest).

For classically damped structures the undamped problem K phi = omega^2 M phi gives frequencies
and mode shapes, and each mode's damping ratio is zeta_r = phi_r^T C phi_r / (2 omega_r phi_r^T
M phi_r). Otherwise that projection can misreport a mode badly (a storey dashpot overdamped on
its own), and the state-space poles give them, as the model responds (``modal_properties``).
Mode shapes are scaled to a unit roof component.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.linalg import eigh

from pidyn.errors import error_pct
from pidyn.params import from_raw, in_range, to_raw
from pidyn.systems.terms import BoucWenHysteresis, LinearStiffness, ViscousDamping


def modal_properties(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> dict:
    """Frequencies (Hz), periods (s), damping ratios and mode shapes (rows, top floor 1) of M, C, K.

    Classically damped (K M^-1 C = C M^-1 K): the undamped modes and their modal damping. Else
    the state-space eigenvalues, as the model responds: each complex pair lambda a mode of natural
    frequency |lambda| / 2 pi and damping ratio -Re lambda / |lambda|, its shape the real part of
    the displacement eigenvector scaled to 1 on the top floor. Real eigenvalues pair up, slowest
    first, as an overdamped mode (s - l1)(s - l2): frequency sqrt(l1 l2) / 2 pi, damping ratio
    -(l1 + l2) / (2 sqrt(l1 l2)), above 1. Projecting a far from classical damping on the undamped
    modes misreports them: the stiff shake-table building's Northridge fit, its top storey's
    dashpot overdamped on its own, read 7.64 Hz and 4.05 % there and responds at 7.80 Hz with
    1.69 % (SRIM on the same record: 7.80 Hz)."""
    M, C, K = (np.atleast_2d(np.asarray(a, float)) for a in (M, C, K))
    if _classical(M, C, K):
        return _undamped_modes(M, C, K)
    try:
        lam, vec = np.linalg.eig(state_matrix(M, C, K))
    except np.linalg.LinAlgError:
        return _undamped_modes(M, C, K)
    if not np.all(np.isfinite(lam)):
        return _undamped_modes(M, C, K)
    n = M.shape[0]
    scale = np.maximum(np.abs(lam), 1e-300)
    pairs = [i for i in range(2 * n) if lam[i].imag > 1e-9 * scale[i]]
    real = sorted(
        (i for i in range(2 * n) if abs(lam[i].imag) <= 1e-9 * scale[i]), key=lambda i: -lam[i].real
    )
    modes = [(abs(lam[i]), -lam[i].real / abs(lam[i]), vec[:n, i]) for i in pairs]
    for a, b in zip(real[0::2], real[1::2]):  # an overdamped mode: its two real rates
        la, lb = lam[a].real, lam[b].real
        wn = float(np.sqrt(max(la * lb, 0.0)))
        modes.append((wn, -(la + lb) / (2 * wn) if wn > 0 else 0.0, vec[:n, a]))
    if len(modes) != n:
        return _undamped_modes(M, C, K)
    modes.sort(key=lambda m: m[0])
    omega = np.array([m[0] for m in modes])
    shapes = np.array([_top_scaled(m[2]) for m in modes]).T
    return _modal_dict(omega, np.array([m[1] for m in modes]), shapes)


def state_matrix(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """A in y' = A y for y = (x, x'): the linear part's rates are its eigenvalues."""
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])


def _classical(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> bool:
    """Caughey and O'Kelly's condition: the damping is diagonal in the undamped modes."""
    try:
        Minv = np.linalg.inv(M)
    except np.linalg.LinAlgError:
        return True
    a, b = K @ Minv @ C, C @ Minv @ K
    return bool(np.linalg.norm(a - b) <= 1e-9 * max(np.linalg.norm(a), 1e-300))


def _top_scaled(phi: np.ndarray) -> np.ndarray:
    """Scaled to 1 on the top floor, exactly: complex division leaves 1 - 1e-16 there on some CPUs."""
    ref = -1 if abs(phi[-1]) > 1e-12 else int(np.argmax(np.abs(phi)))
    out = np.real(phi / phi[ref])
    out[ref] = 1.0
    return out


def _undamped_modes(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> dict:
    w2, phi = eigh(K, M)
    w2 = np.clip(w2, 0.0, None)
    omega = np.sqrt(w2)
    phi = phi / np.where(np.abs(phi[-1]) > 1e-12, phi[-1], 1.0)
    zeta = np.array(
        [
            phi[:, r] @ C @ phi[:, r] / max(2 * omega[r] * (phi[:, r] @ M @ phi[:, r]), 1e-300)
            for r in range(len(omega))
        ]
    )
    return _modal_dict(omega, zeta, phi)


def _modal_dict(omega: np.ndarray, zeta: np.ndarray, phi: np.ndarray) -> dict:
    freq = omega / (2 * np.pi)
    return {
        "frequency_hz": freq.tolist(),
        "period_s": [float(1 / f) if f > 0 else float("inf") for f in freq],
        "damping_ratio": zeta.tolist(),
        "mode_shapes": phi.T.tolist(),  # one row per mode, one value per floor
    }


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """Modal assurance criterion of two mode shapes, real or complex (1: the same shape)."""
    a, b = np.asarray(a), np.asarray(b)
    den = float(np.real(np.vdot(a, a)) * np.real(np.vdot(b, b)))
    return float(abs(np.vdot(a, b)) ** 2 / max(den, 1e-300))


def compare_modes(system, identified: Mapping[str, float], truth: Mapping[str, float] | None) -> dict:
    """The identified model's modal properties, and beside them the truth's with relative
    frequency and damping errors (%) and the MAC of each mode shape when the truth is known."""
    out = {"identified": modal_properties(*system.linear_matrices(identified))}
    if truth and all(v is not None for v in truth.values()):
        tr = modal_properties(*system.linear_matrices(truth))
        out["truth"] = tr
        idf = out["identified"]
        out["frequency_error_pct"] = [
            error_pct(a, b) for a, b in zip(idf["frequency_hz"], tr["frequency_hz"])
        ]
        out["damping_error_pct"] = [
            error_pct(a, b) for a, b in zip(idf["damping_ratio"], tr["damping_ratio"])
        ]
        out["mac"] = [mac(a, b) for a, b in zip(idf["mode_shapes"], tr["mode_shapes"])]
    return out


def modal_table(modes: dict) -> str:
    """A markdown table of the modes (identified, and the truth where known)."""
    idf, tr = modes["identified"], modes.get("truth")
    head = "| mode | f (Hz) | zeta (%) | shape (floor 1..N) |" + (
        " f true (Hz) | zeta true (%) | MAC |" if tr else ""
    )
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for r, (f, z, ph) in enumerate(zip(idf["frequency_hz"], idf["damping_ratio"], idf["mode_shapes"])):
        row = f"| {r + 1} | {f:.4f} | {100 * z:.3f} | {', '.join(f'{v:.3f}' for v in ph)} |"
        if tr:
            row += (
                f" {tr['frequency_hz'][r]:.4f} | {100 * tr['damping_ratio'][r]:.3f} | {modes['mac'][r]:.5f} |"
            )
        rows.append(row)
    return "\n".join(rows)


def linear_matrices(system, values: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, C, K of a model's linear part about rest: a building's own (``linear_matrices``), or a
    single degree of freedom's mass, viscous damping and stiffness about rest (1 x 1)."""
    if hasattr(system, "linear_matrices"):
        return system.linear_matrices(values)
    k = sum(float(values[p]) for p in stiffness_params(system))
    c = sum(float(values[p]) for p in damping_params(system))
    if not stiffness_params(system):
        raise ValueError(f"{system.name}: no stiffness about rest to take modes of")
    return np.array([[float(values["m"])]]), np.array([[c]]), np.array([[k]])


def stiffness_params(system) -> list[str]:
    """A single degree of freedom's parameters that make up its stiffness about rest (a linear
    spring's k, a Bouc-Wen spring's k since dz/dx = 1 at rest)."""
    return [
        t.param for t in getattr(system, "terms", []) if isinstance(t, (LinearStiffness, BoucWenHysteresis))
    ]


def damping_params(system) -> list[str]:

    return [t.linear[0] for t in getattr(system, "terms", []) if isinstance(t, ViscousDamping)]


def modes_with_intervals(
    system,
    values: Mapping[str, float],
    names: list[str] | None = None,
    covariance: np.ndarray | None = None,
    draws: int = 4000,
    seed: int = 0,
) -> list[dict]:
    """The model's modes about rest, fundamental first: period, frequency, damping ratio and
    their 95 % intervals (the ``modal.json`` entries), and the mode shape.

    The intervals propagate the estimate's covariance (in the parameters' unconstrained
    coordinates, ``names`` order, as the refinement gives it) by drawing ``draws`` parameter
    sets and taking the 2.5 and 97.5 % quantiles of each modal quantity: exact through the
    nonlinear maps k -> period and (c, k) -> damping ratio, which a first-order rule is not for
    the wide intervals of a short record. Modes are matched by their order in frequency. Mode
    shapes are scaled to 1 on the top floor; ``mode_shape_ci95`` gives each floor's interval."""
    point = modal_properties(*linear_matrices(system, values))
    n = len(point["frequency_hz"])
    ci = {key: [[None, None]] * n for key in ("period_s", "damping_ratio", "frequency_hz")}
    shape_ci: list = [None] * n
    if names and covariance is not None and np.all(np.isfinite(covariance)):
        out, shapes = _drawn_modes(system, values, names, covariance, draws, seed)
        for key, rows in out.items():
            arr = np.asarray(rows, float)
            if len(arr) > 0.9 * draws:
                ci[key] = [_quantiles(arr[:, r], draws) for r in range(n)]
        if len(shapes) > 0.9 * draws:  # every floor's value, the top floor's being 1
            arr = np.asarray(shapes, float)
            shape_ci = [np.quantile(arr[:, r, :], [0.025, 0.975], axis=0).T.tolist() for r in range(n)]
    return [
        {
            "period_s": point["period_s"][r],
            "period_ci95": ci["period_s"][r],
            "frequency_hz": point["frequency_hz"][r],
            "frequency_ci95": ci["frequency_hz"][r],
            "damping_ratio": point["damping_ratio"][r],
            "damping_ci95": ci["damping_ratio"][r],
            "mode_shape": point["mode_shapes"][r],
            "mode_shape_ci95": shape_ci[r],
        }
        for r in range(n)
    ]


def _quantiles(col: np.ndarray, draws: int) -> list:
    """The 2.5 and 97.5 % quantiles of a modal quantity's draws, or none where more than a tenth
    of them are not finite (a draw whose mode is overdamped has no damping ratio): a NaN bound
    is no bound, and JSON has no NaN."""
    finite = col[np.isfinite(col)]
    if len(finite) <= 0.9 * draws:
        return [None, None]
    return [float(np.quantile(finite, 0.025)), float(np.quantile(finite, 0.975))]


def _drawn_modes(
    system, values: Mapping[str, float], names: list[str], covariance: np.ndarray, draws: int, seed: int
) -> tuple[dict[str, list], list]:
    """The modal quantities and mode shapes of ``draws`` parameter sets drawn from the estimate's
    covariance (unconstrained coordinates); a draw without modes (unstable) is left out."""
    import torch  # lazy: the NumPy core (simulation, refinement) runs without loading torch

    specs = {s.name: s for s in system.param_specs()}
    theta = np.array([to_raw(specs[k], float(values[k])) for k in names])
    rng = np.random.default_rng(seed)
    cov = np.asarray(covariance, float)
    sample = rng.multivariate_normal(theta, (cov + cov.T) / 2, size=draws, method="eigh")
    out: dict[str, list] = {key: [] for key in ("period_s", "damping_ratio", "frequency_hz")}
    shapes: list = []
    for row in sample:
        p = dict(values)
        p.update(
            {
                k: float(from_raw(specs[k], torch.tensor(float(row[i]), dtype=torch.float64)))
                for i, k in enumerate(names)
            }
        )
        try:
            m = modal_properties(*linear_matrices(system, p))
        except (ValueError, np.linalg.LinAlgError):
            continue
        for key in out:
            out[key].append(m[key])
        shapes.append(m["mode_shapes"])
    return out, shapes


def first_mode(system, values: Mapping[str, float]) -> tuple[float | None, float | None]:
    """The first mode's frequency (Hz) and damping ratio of the model at ``values``."""
    try:
        modes = modal_properties(*linear_matrices(system, values))
    except (KeyError, ValueError):
        return None, None
    return float(modes["frequency_hz"][0]), float(modes["damping_ratio"][0])


def scaled_to(system, fn: float, zeta: float) -> dict[str, float]:
    """The trainable parameters of the model's linear part scaled so that its first mode has the
    frequency ``fn`` (Hz) and damping ratio ``zeta``: a building's stiffness profile as the
    config gives it, with stiffness-proportional damping; a single degree of freedom's springs
    and dampers shared out alike; a modes model by its own ``start_at``."""
    specs = {s.name: s for s in system.param_specs()}
    init = {n: float(s.init) for n, s in specs.items()}
    w = 2 * np.pi * fn
    values: dict[str, float] = {}
    if hasattr(system, "start_at"):  # modes: the fundamental at the peak, the others in proportion
        values = system.start_at(fn, zeta)
    elif hasattr(system, "linear_matrices"):
        w0 = 2 * np.pi * modal_properties(*system.linear_matrices(init))["frequency_hz"][0]
        scale = (w / max(w0, 1e-12)) ** 2
        for term in system.terms:
            kp, cp = term.initial_stiffness_param, term.damping_param
            if kp and specs[kp].trainable:
                values[kp] = init[kp] * scale
        for term in system.terms:  # stiffness-proportional: every mode's ratio grows with its frequency
            cp = term.damping_param
            if cp and specs[cp].trainable:
                kp = next(
                    t.initial_stiffness_param
                    for t in system.terms
                    if t.storey == term.storey and t.initial_stiffness_param
                )
                values[cp] = 2 * zeta / w * values.get(kp, init[kp])
    else:
        m = init.get("m", 1.0)
        ks, cs = stiffness_params(system), damping_params(system)
        for p in ks:
            if specs[p].trainable:
                values[p] = m * w**2 / len(ks)
        for p in cs:
            if specs[p].trainable:
                values[p] = 2 * zeta * m * w / len(cs)
    return {n: v for n, v in values.items() if np.isfinite(v) and in_range(specs[n], v)}
