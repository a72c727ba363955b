"""Whether an identified model describes its record at all, before any of its numbers is read.

A fit always returns parameters and intervals, also on a record the model cannot explain (a
response unrelated to the input, an input in the wrong units, a model that diverges). The
intervals then only say how well the misfit's minimum is located, not what the structure is. The
test here is what an engineer checks first:

- **simulates**: the identified model's free run stays finite over the record;
- **explains**: its simulated response reproduces most of the measured response on the part it
  was fitted on (NRMSE at most ``max_fit_nrmse``, 0.5: three quarters of the variance), and
  better than the prediction that knows nothing;
- **predicts**: on a held-out part, it beats the prediction that knows nothing on the same span;
- **within noise** (only where the record declares its noise, as a simulation does): the misfit
  on the fitting part, and on the held-out part, is what that noise allows there, up to
  ``noise_tolerance`` times it and a floor ``noise_floor_nrmse``.

The prediction that knows nothing is the structure at rest relative to its support (``x``,
``v``), or moving with its support (an accelerometer reads the support's acceleration; with
several supports, the one or the mean that best predicts the fitting part). The residuals'
whiteness (Ljung-Box over 20 lags, and the largest correlation with the input) is reported with
the test: real structures leave correlated residuals under any model of few parameters, so it
describes the misfit rather than decide.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats

from pidyn.assessment import ground_acceleration, measured_convention
from pidyn.reporting import nrmse


@dataclass(frozen=True)
class AdequacySettings:
    """The test's limits (see the module's docstring); calibrated by ``experiments/adequacy_calibration.py``."""

    max_fit_nrmse: float = 0.5
    noise_tolerance: float = 1.5
    noise_floor_nrmse: float = 0.02
    whiteness_lags: int = 20


def _span_mask(t: np.ndarray, span) -> np.ndarray:
    return (t >= float(span[0]) - 1e-9) & (t <= float(span[1]) + 1e-9)


def _support_candidates(record) -> dict[str, np.ndarray]:
    """What an accelerometer on a structure that moves with its support reads: the one ground, or
    each support's acceleration and their mean."""
    f = np.asarray(record.f, float)
    if record.excitation != "ground":
        return {}
    if f.ndim == 1:
        return {"ground": f}
    n = record.n_inputs
    names = record.inputs or [f"support {i + 1}" for i in range(n)]
    out = {str(names[i]): f[:, i] for i in range(n)}
    out["mean of the supports"] = f[:, :n].mean(axis=1)
    return out


def trivial_predictions(record, fit_span) -> dict[str, tuple[str, np.ndarray]]:
    """Per measured channel (``x``, ``a3``...), the prediction that knows nothing, in the sensor's
    convention (absolute accelerations): its label and series. With several supports, the support
    (or their mean) is chosen on the fitting part only."""
    multi = record.n_dof > 1
    m_fit = _span_mask(record.t, fit_span)
    supports = _support_candidates(record)
    out: dict[str, tuple[str, np.ndarray]] = {}
    for kind, floors in record.sensors().items():
        meas = getattr(record, kind)
        for fl in floors:
            name = f"{kind}{fl}" if multi else kind
            if kind != "a" or not supports:
                out[name] = ("at rest", np.zeros(len(record.t)))
                continue
            truth = meas[:, fl - 1] + ground_acceleration(record)
            best = min(supports, key=lambda s: _rms(truth[m_fit] - supports[s][m_fit]))
            out[name] = (f"moving with {best}", supports[best])
    return out


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else float("nan")


def _measured(record, kind: str, fl: int) -> np.ndarray:
    return getattr(record, kind)[:, fl - 1] + (ground_acceleration(record) if kind == "a" else 0.0)


def ljung_box(r: np.ndarray, lags: int) -> tuple[float, float]:
    """Ljung-Box Q over ``lags`` lags and its p-value (chi-square, ``lags`` degrees of freedom)."""
    r = np.asarray(r, float) - np.mean(r)
    n = len(r)
    den = float(np.dot(r, r))
    if n <= lags + 1 or den <= 0:
        return float("nan"), float("nan")
    rho = np.array([np.dot(r[:-k], r[k:]) / den for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return q, float(stats.chi2.sf(q, lags))


def _input_correlation(r: np.ndarray, u: np.ndarray, lags: int) -> float:
    """The largest |correlation| of the residual with the input at lags 0..``lags`` (input first)."""
    r = np.asarray(r, float) - np.mean(r)
    u = np.asarray(u, float) - np.mean(u)
    den = float(np.sqrt(np.dot(r, r) * np.dot(u, u)))
    if den <= 0:
        return float("nan")
    return float(max(abs(np.dot(r[k:], u[: len(u) - k])) / den for k in range(lags + 1)))


def declared_noise(record) -> dict[str, float] | None:
    """The noise the record declares per channel kind, as a fraction of each channel's RMS (a
    simulated record's), or None for a measurement."""
    levels = record.meta.noise_levels
    if record.clean is None or not levels:
        return None
    return {str(k): float(v) for k, v in levels.items()}


def check_adequacy(
    sim: dict[str, np.ndarray],
    record,
    fit_span,
    heldout_span=None,
    settings: AdequacySettings | None = None,
    stability: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The adequacy test of the simulated response ``sim`` (the identified model's free run over
    the record) on the fitting span, and on the held-out span when there is one. ``stability``:
    ``rk4_stability`` of the model at the record's step (an unstable one does not simulate)."""
    s = settings or AdequacySettings()
    t = record.t
    m_fit = _span_mask(t, fit_span)
    m_held = None if heldout_span is None else _span_mask(t, heldout_span)
    trivial = trivial_predictions(record, fit_span)
    noise = declared_noise(record)
    u = np.asarray(record.f, float)
    u = u if u.ndim == 1 else u[:, : record.n_inputs].mean(axis=1)
    channels: dict[str, dict[str, Any]] = {}
    multi = record.n_dof > 1
    finite = all(np.all(np.isfinite(v)) and np.all(np.abs(v) < 1e100) for v in sim.values())
    finite = finite and (stability is None or stability["stable"])
    for kind, floors in record.sensors().items():
        pred_all = measured_convention(sim, record, kind) if finite else None
        for fl in floors:
            name = f"{kind}{fl}" if multi else kind
            meas = _measured(record, kind, fl)
            label, triv = trivial[name]
            row: dict[str, Any] = {"trivial": label}
            row["trivial_fit_nrmse"] = nrmse(triv[m_fit], meas[m_fit])
            if pred_all is None:
                row["fit_nrmse"] = float("inf")
            else:
                pred = pred_all[:, fl - 1]
                res = meas[m_fit] - pred[m_fit]
                row["fit_nrmse"] = nrmse(pred[m_fit], meas[m_fit])
                q, p = ljung_box(res, s.whiteness_lags)
                row["whiteness_q"], row["whiteness_p"] = q, p
                row["input_correlation"] = _input_correlation(res, u[m_fit], s.whiteness_lags)
            # the declared noise is a share of the channel's RMS over the record: one level in
            # absolute terms, a larger share of a quieter part
            sigma = None if noise is None or kind not in noise else noise[kind] * _rms(meas)
            if sigma is not None:
                row["noise_nrmse"] = sigma / max(float(np.std(meas[m_fit])), 1e-300)
            if m_held is not None:
                row["trivial_heldout_nrmse"] = nrmse(triv[m_held], meas[m_held])
                row["heldout_nrmse"] = (
                    float("inf") if pred_all is None else nrmse(pred_all[m_held, fl - 1], meas[m_held])
                )
                if sigma is not None:
                    row["heldout_noise_nrmse"] = sigma / max(float(np.std(meas[m_held])), 1e-300)
            channels[name] = row
    out = _verdict(channels, finite, fit_span, heldout_span, s, stability)
    out["integrator"] = stability
    return out


def _verdict(
    channels: dict, finite: bool, fit_span, heldout_span, s: AdequacySettings, stability: dict | None
) -> dict[str, Any]:
    """The four checks from the channels' figures, and the reasons in words."""

    def mean(key: str) -> float | None:
        vals = [r[key] for r in channels.values() if key in r]
        return float(np.mean(vals)) if vals else None

    fit, triv_fit = mean("fit_nrmse"), mean("trivial_fit_nrmse")
    held, triv_held = mean("heldout_nrmse"), mean("trivial_heldout_nrmse")
    limit = _fit_limit(channels, s)
    explains = finite and fit is not None and fit <= limit and fit < (triv_fit or np.inf)
    predicts = None if held is None else bool(finite and held < triv_held)
    noisy = [r for r in channels.values() if "noise_nrmse" in r]
    within = all(_excess(r, s) <= 0 for r in noisy) if noisy and finite else None
    adequate = bool(finite and explains and predicts is not False and within is not False)
    return {
        "adequate": adequate,
        "simulates": bool(finite),
        "explains": bool(explains),
        "predicts": predicts,
        "within_noise": within,
        "fit_span": [float(fit_span[0]), float(fit_span[1])],
        "heldout_span": None if heldout_span is None else [float(heldout_span[0]), float(heldout_span[1])],
        "fit_nrmse": fit,
        "trivial_fit_nrmse": triv_fit,
        "heldout_nrmse": held,
        "trivial_heldout_nrmse": triv_held,
        "trivial": _trivial_label(channels),
        "whiteness_p_min": _min_finite([r.get("whiteness_p") for r in channels.values()]),
        "input_correlation_max": _max_finite([r.get("input_correlation") for r in channels.values()]),
        "channels": channels,
        "reasons": _reasons(channels, finite, explains, predicts, within, stability, s),
        "settings": asdict(s),
    }


def _fit_limit(channels: dict, s: AdequacySettings) -> float:
    """The largest fitting-part NRMSE that still describes the record: ``max_fit_nrmse``, or what a
    declared noise allows where the fitting part is so quiet that its noise alone misses more
    (a record whose first seconds barely move)."""
    noisy = [_allowed(r["noise_nrmse"], s) for r in channels.values() if "noise_nrmse" in r]
    return max(s.max_fit_nrmse, float(np.mean(noisy))) if noisy else s.max_fit_nrmse


def _reasons(
    channels: dict,
    finite: bool,
    explains: bool,
    predicts,
    within,
    stability: dict | None,
    s: AdequacySettings,
) -> list[str]:
    """Why a model is not adequate, in words (empty when it is)."""
    rows = list(channels.values())
    fit = float(np.mean([r["fit_nrmse"] for r in rows]))
    out: list[str] = []
    if stability is not None and not stability["stable"]:
        out.append(
            f"the identified model cannot be simulated stably at the record's step: an eigenvalue with "
            f"|lambda h| = {stability['max_abs_lambda_h']:.3g} lies outside the RK4 stability region at "
            f"{stability.get('substeps', 4)} steps per sample (a mass near zero or a damping far beyond "
            "the structure's, not a structure)"
        )
    elif not finite:
        out.append("the identified model diverges when simulated over the record")
        return out
    if finite and not explains:
        triv = float(np.mean([r["trivial_fit_nrmse"] for r in rows]))
        out.append(
            f"its simulated response misses the fitting part by NRMSE {fit:.3g} (at most "
            f"{_fit_limit(channels, s):.3g} describes the record; knowing nothing gives {triv:.3g})"
        )
    if finite and predicts is False:
        held = float(np.mean([r["heldout_nrmse"] for r in rows]))
        triv = float(np.mean([r["trivial_heldout_nrmse"] for r in rows]))
        out.append(
            f"it predicts the held-out part worse than knowing nothing (NRMSE {held:.3g} against "
            f"{triv:.3g}, {_trivial_label(channels)})"
        )
    if within is False:
        worst = max((r for r in rows if "noise_nrmse" in r), key=lambda r: _excess(r, s))
        held = _excess(worst, s, "heldout") > _excess(worst, s, "fit")
        key, noise = ("heldout_nrmse", "heldout_noise_nrmse") if held else ("fit_nrmse", "noise_nrmse")
        out.append(
            f"its misfit on the {'held-out' if held else 'fitting'} part (NRMSE {worst[key]:.3g}) exceeds "
            f"what the record's declared noise allows there ({_allowed(worst[noise], s):.3g})"
        )
    return out


def _excess(row: dict, s: AdequacySettings, part: str = "both") -> float:
    """How far a channel's misfit exceeds what its declared noise allows, on the fitting part, the
    held-out part, or the larger of the two (in NRMSE; at most 0 passes)."""
    fit = row["fit_nrmse"] - _allowed(row["noise_nrmse"], s)
    held = (
        row["heldout_nrmse"] - _allowed(row["heldout_noise_nrmse"], s)
        if "heldout_noise_nrmse" in row
        else -np.inf
    )
    return {"fit": fit, "heldout": held}.get(part, max(fit, held))


def _allowed(noise_nrmse: float, s: AdequacySettings) -> float:
    return float(np.hypot(s.noise_tolerance * noise_nrmse, s.noise_floor_nrmse))


def _trivial_label(channels: dict) -> str:
    labels = sorted({r["trivial"] for r in channels.values()})
    return "; ".join(labels)


def _min_finite(vals) -> float | None:
    v = [x for x in vals if x is not None and np.isfinite(x)]
    return float(min(v)) if v else None


def _max_finite(vals) -> float | None:
    v = [x for x in vals if x is not None and np.isfinite(x)]
    return float(max(v)) if v else None


def describe(result: dict[str, Any]) -> str:
    """One paragraph in words for the log and the report."""
    if result["adequate"]:
        text = f"the model describes the record: fitting-part NRMSE {result['fit_nrmse']:.3g}"
        if result["heldout_nrmse"] is not None:
            text += (
                f", held-out {result['heldout_nrmse']:.3g} against {result['trivial_heldout_nrmse']:.3g} "
                f"knowing nothing ({result['trivial']})"
            )
        return text
    return (
        "THE MODEL DOES NOT DESCRIBE THE RECORD: "
        + "; ".join(result["reasons"])
        + ". Its parameters and intervals are those of the best fit of a model the data reject, not "
        "the structure's properties."
    )
