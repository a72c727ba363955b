"""The field's linear identification on the same channels and span: modes, and the prediction of
the held-out part by the identified model simulated from rest.

* ``srim`` and ``okid_era``: the state-space realizations of ``mdof`` (the open-source toolbox
  structural monitoring uses; ``pip install 'pidyn[peer]'``). A realization of order n holds n/2
  modes; the order is chosen among ``orders`` by the fitting part's simulation error, among the
  realizations that do not diverge when simulated from rest (spectral radius of A below 1).
  Every order's numbers are kept in the row, so a reader sees how the modes move with it.
* ``transfer_function``: the fundamental mode from the H1 transfer function of the top output
  from the (mean) input: an oscillator's absolute-acceleration transmissibility fitted to the
  complex H1 around its peak by weighted least squares, each frequency weighted by
  2 n_d gamma^2 / (1 - gamma^2), the inverse variance of H1 (Bendat and Piersol), which gives
  the intervals. No model is simulated: it says nothing about the held-out part.

Found on the Painter Street records: mdof's OKID with its default number of Markov parameters
(min(1000, N)) is underdetermined on a fitting part of a few hundred samples and returns
unstable realizations (spectral radius 1.02-1.27 on the 2012 record); 60 Markov parameters,
an ERA Hankel of 20 x 20 blocks and ``rcond`` 1e-2 give stable ones. SRIM above order 2-6
diverges from rest on several events.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import dlsim

from pidyn.baselines.realization import realization_params
from pidyn.baselines.registry import estimator
from pidyn.baselines.subspace import real_shape
from pidyn.reporting import nrmse
from pidyn.signals import dominant_peak, transfer_function, transmissibility

Z95 = 1.959963984540054


@dataclass
class PeerResult:
    """A peer's modes (fundamental first) and, for a simulated model, its prediction errors."""

    method: str
    modes: list[dict]
    seconds: float
    note: str = ""
    order: int | None = None
    stable: bool | None = None
    fit_nrmse_a: float | None = None
    heldout_nrmse_a: float | None = None
    orders: list[dict] = field(default_factory=list)
    realization: tuple | None = field(
        default=None, repr=False
    )  # (A, B, C, D) of the chosen order, to simulate other records
    params: dict = field(default_factory=dict)  # the order-2 realization as the model's parameters
    stable_realizations: dict = field(default_factory=dict, repr=False)  # order -> (A, B, C, D)

    def to_row(self) -> dict:
        return {
            "method": self.method,
            "params": dict(self.params),
            "seconds": self.seconds,
            "note": self.note,
            "modes": self.modes,
            "order": self.order,
            "stable": self.stable,
            "fit_nrmse_a": self.fit_nrmse_a,
            "heldout_nrmse_a": self.heldout_nrmse_a,
            "orders": self.orders,
        }


def io_arrays(record) -> tuple[np.ndarray, np.ndarray]:
    """Inputs (q, N) and the outputs as the accelerometers read them, absolute (p, N)."""
    f = np.asarray(record.f, float)
    U = (
        f[:, : record.n_inputs].T if f.ndim == 2 else f[None, :]
    )  # the supports' accelerations (not velocities)
    if record.a is None:
        raise ValueError(f"record '{record.name}': the peers need accelerometer outputs")
    cols = [j - 1 for j in record.sensors().get("a", [])]
    Y = record.a[:, cols].T
    if f.ndim == 1 and record.excitation == "ground":
        Y = Y + f[None, :]  # one input: the record keeps a relative to it
    return U, Y


def spans(record) -> tuple[np.ndarray, np.ndarray | None]:
    """Masks of the fitting part and of the held-out part (None: the record has no split)."""
    sp = record.meta.split
    if not sp:
        return np.ones(len(record.t), bool), None
    t = record.t
    held = t > sp.fit[1] + 1e-9
    # a record cut to its fitting part keeps its split: no held-out part, not an empty one (whose
    # mean warned, "Mean of empty slice", on every diagnosis of a strong-motion record)
    return (t >= sp.fit[0] - 1e-9) & (t <= sp.fit[1] + 1e-9), held if held.any() else None


def _require_mdof():
    try:
        import mdof  # noqa: F401
    except ImportError:
        raise RuntimeError("mdof is not installed: pip install 'pidyn[peer]'") from None
    return mdof


def srim(record, orders: Sequence[int] = (2, 4, 6), horizon: int = 100) -> PeerResult:
    """mdof's SRIM on the fitting part, the order chosen as the module says."""
    return _realize(record, "srim", orders, dict(horizon=int(horizon)))


def okid_era(
    record, orders: Sequence[int] = (2, 4, 6), markov: int = 60, horizon: int = 20, rcond: float = 1e-2
) -> PeerResult:
    """mdof's OKID (``markov`` Markov parameters, pseudo-inverse ``rcond``) then ERA
    (``horizon`` x ``horizon`` Hankel blocks) on the fitting part."""
    return _realize(
        record,
        "okid-era",
        orders,
        dict(m=int(markov), horizon=int(horizon), nc=int(horizon), rcond=float(rcond)),
    )


def _realize(record, method: str, orders: Sequence[int], options: dict) -> PeerResult:
    mdof = _require_mdof()
    t0 = time.perf_counter()
    U, Y = io_arrays(record)
    fit, held = spans(record)
    rows = [_order_row(mdof, method, int(order), U, Y, fit, held, record.dt, options) for order in orders]
    ok = [r for r in rows if r.get("stable") and r["modes"] and np.isfinite(r["fit_nrmse_a"])]
    stable = {r["order"]: r["realization"] for r in ok}
    name = method.replace("-", "_")
    if not ok:
        for r in rows:
            r.pop("realization", None)
        return PeerResult(
            name,
            [],
            time.perf_counter() - t0,
            note="no stable realization at orders "
            f"{list(orders)}: every one diverges when simulated from rest",
            orders=rows,
        )
    best = min(ok, key=lambda r: r["fit_nrmse_a"])
    unstable = [r["order"] for r in rows if r.get("stable") is False]
    note = f"order {best['order']} (lowest fitting-part error of the stable orders)"
    if unstable:
        note += f"; order(s) {unstable} diverge from rest (spectral radius of A above 1)"
    realization = best["realization"]
    for r in rows:
        r.pop("realization", None)
    return PeerResult(
        name,
        best["modes"],
        time.perf_counter() - t0,
        note=note,
        order=best["order"],
        stable=True,
        fit_nrmse_a=best["fit_nrmse_a"],
        heldout_nrmse_a=best["heldout_nrmse_a"],
        orders=rows,
        realization=realization,
        stable_realizations=stable,
    )


def _order_row(mdof, method: str, order: int, U, Y, fit, held, dt: float, options: dict) -> dict:
    """One order's realization on the fitting part: stability, modes, and the simulated
    outputs' error on the fitting and held-out parts (or the error the method raised)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            real = mdof.system(U[:, fit], Y[:, fit], dt=dt, method=method, order=order, **options)
            modes = _modes(real)
        A, B, C, D = real
        rho = float(np.max(np.abs(np.linalg.eigvals(A))))
        out = simulate_realization(A, B, C, D, U)
        return {
            "order": order,
            "spectral_radius": rho,
            "stable": bool(rho < 1.0),
            "modes": modes,
            "realization": (A, B, C, D),
            "fit_nrmse_a": _mean_nrmse(out, Y, fit),
            "heldout_nrmse_a": None if held is None else _mean_nrmse(out, Y, held),
        }
    except Exception as exc:  # an order the method cannot realise on this record
        return {"order": order, "error": f"{type(exc).__name__}: {exc}"}


def _modes(real) -> list[dict]:
    """The realization's modes, longest period first (mdof's own modal analysis), with the shape
    at the outputs (made real: ``subspace.real_shape``), its modal phase collinearity (MPC) and
    mdof's energy-condensed output EMAC, by which a mode is told from a noise pole."""
    rows = []
    for m in real.modes().values():
        freq = float(m["freq"])
        if freq > 0:
            rows.append(
                {
                    "period_s": 1.0 / freq,
                    "period_ci95": [None, None],
                    "frequency_hz": freq,
                    "damping_ratio": float(m["damp"]),
                    "damping_ci95": [None, None],
                    "mode_shape": real_shape(np.asarray(m["modeshape"])).tolist(),
                    "mpc": float(m["mpc"]),
                    "emac": float(m["energy_condensed_emaco"]),
                }
            )
    return sorted(rows, key=lambda r: -r["period_s"])


def simulate_realization(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, U: np.ndarray
) -> np.ndarray:
    """y_k = C x_k + D u_k, x_{k+1} = A x_k + B u_k from rest: (p, N), by ``scipy.signal.dlsim``
    (an unstable realization overflows to inf, which the caller scores as a failed fit)."""
    with np.errstate(all="ignore"):
        _, y, _ = dlsim((A, B, C, D, 1.0), np.asarray(U, float).T)
    return np.asarray(y, float).reshape(U.shape[1], C.shape[0]).T


def _mean_nrmse(out: np.ndarray, Y: np.ndarray, mask: np.ndarray) -> float:
    if not np.all(np.isfinite(out[:, mask])):
        return float("inf")
    return float(np.mean([nrmse(out[j, mask], Y[j, mask]) for j in range(Y.shape[0])]))


def transfer_function_estimate(record, band_halfwidth: float = 0.35) -> PeerResult:
    """The fundamental mode from the transmissibility (see the module's docstring)."""
    t0 = time.perf_counter()
    U, Y = io_arrays(record)
    fit, _ = spans(record)
    u, y = U.mean(axis=0)[fit], Y[0][fit]
    tf = transfer_function(u, y, record.dt)
    duration = float(record.t[fit][-1] - record.t[fit][0])
    fn0, z0 = dominant_peak(tf, (max(2.0 / duration, tf.freq[1]), 0.4 / record.dt))
    z0 = 0.05 if not np.isfinite(z0) else z0
    sel = (
        (tf.freq >= fn0 * (1 - band_halfwidth))
        & (tf.freq <= fn0 * (1 + band_halfwidth))
        & (tf.coherence > 0.05)
    )
    f_sel, h_sel = tf.freq[sel], tf.h[sel]
    gam = np.clip(tf.coherence[sel], 1e-6, 1 - 1e-6)
    w = np.sqrt(2 * tf.segments * gam / (1 - gam)) / np.maximum(
        np.abs(h_sel), 1e-12
    )  # 1 / std of H1, relative
    if sel.sum() < 4:
        return PeerResult(
            "transfer_function",
            [],
            time.perf_counter() - t0,
            note=f"too few coherent frequencies around the peak at {fn0:.3g} Hz",
        )

    def resid(p: np.ndarray) -> np.ndarray:
        g, (fn, zeta) = p[2] + 1j * p[3], (p[0], p[1])
        e = (g * transmissibility(f_sel, fn, zeta) - h_sel) * w
        return np.concatenate([e.real, e.imag])

    sol = least_squares(
        resid, [fn0, z0, 1.0, 0.0], bounds=([0.5 * fn0, 1e-4, -10, -10], [2 * fn0, 0.9, 10, 10])
    )
    J = sol.jac
    dof = max(len(sol.fun) - 4, 1)
    cov = np.linalg.pinv(J.T @ J) * float(sol.fun @ sol.fun) / dof
    fn, zeta = float(sol.x[0]), float(sol.x[1])
    sf, sz = (float(np.sqrt(max(cov[i, i], 0.0))) for i in (0, 1))
    mode = {
        "period_s": 1.0 / fn,
        "period_ci95": [1.0 / (fn + Z95 * sf), 1.0 / max(fn - Z95 * sf, 1e-12)],
        "frequency_hz": fn,
        "damping_ratio": zeta,
        "damping_ci95": [max(zeta - Z95 * sz, 0.0), zeta + Z95 * sz],
    }
    return PeerResult(
        "transfer_function",
        [mode],
        time.perf_counter() - t0,
        note=f"H1 of the top output from the mean input, {tf.segments} Welch segments, "
        f"{int(sel.sum())} frequencies around {fn0:.3g} Hz",
    )


@estimator("transfer_function", transfer_function_estimate, "TF", order=10)
def _transfer_function_row(record, system, settings: dict, noise: float) -> dict:
    return transfer_function_estimate(record, **settings).to_row()


def _with_start(result: PeerResult, system, dt: float) -> dict:
    """The peer's row, carrying its stable realization of twice the model's modes (order 2 for a
    single degree of freedom) as the model's parameters (a start of the refinement) when it maps
    onto the system."""
    result.params = realization_start(result, system, dt)
    return result.to_row()


def realization_start(result: PeerResult, system, dt: float) -> dict[str, float]:
    """The peer's stable realization of twice the model's modes mapped onto ``system``'s
    parameters; empty when there is none or it does not map (``realization_params``)."""
    real = result.stable_realizations.get(2 * system.n_dof)
    return realization_params(system, real, dt) if real is not None else {}


@estimator("srim", srim, "SRIM", order=11, starts=True)
def _srim_row(record, system, settings: dict, noise: float) -> dict:
    return _with_start(srim(record, **settings), system, record.dt)


@estimator("okid_era", okid_era, "OKID-ERA", order=12, starts=True)
def _okid_era_row(record, system, settings: dict, noise: float) -> dict:
    return _with_start(okid_era(record, **settings), system, record.dt)
