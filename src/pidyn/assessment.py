"""What a run says about the structure beyond its parameters: its modes with 95 % intervals
(``modal.json``) and how well the identified model predicts data it was not fitted on."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.reporting import nrmse, write_json
from pidyn.systems.modal import modes_with_intervals

#: what a strong-motion record says of itself, kept in metrics.json
RECORD_META = (
    "path",
    "station",
    "direction",
    "input_channels",
    "output_channels",
    "pga",
    "span",
    "t_offset",
    "dt",
    "notes",
    "pre_event_rms",
    "band_hz",
)
IMU_META = (
    "path",
    "run",
    "floors",
    "devices",
    "alignment",
    "align",
    "dt",
    "span",
    "pga",
    "notes",
    "pre_event_rms",
)


def assess(
    system,
    record,
    final: dict[str, float],
    refined: Any,
    sim: dict[str, np.ndarray],
    hold_out: bool,
    run_dir: Path,
    adequate: bool = True,
) -> dict[str, Any]:
    """modal.json, and the metrics to add: the modes, the held-out scores (a record identified on
    its fitting part only), what a strong-motion record says of itself. The modes of a model that
    does not describe its record (``pidyn.adequacy``) are marked as the fit's, not the structure's."""
    out: dict[str, Any] = {}
    modes = modal_summary(system, final, refined)
    if modes is not None:
        for m in modes if not adequate else []:
            m["describes_structure"] = False
        extra = None if adequate else {"adequate": False, "warning": NOT_ADEQUATE}
        write_modal(run_dir, modes, extra)
        out["modal"] = [{k: v for k, v in m.items() if not k.startswith("mode_shape")} for m in modes]
    meta = record.meta
    if meta.station is not None:
        out["record_meta"] = meta.to_dict(RECORD_META)
    elif meta.alignment is not None:  # an IMU set
        out["record_meta"] = meta.to_dict(IMU_META)
    # what the record measures: a prediction of another record must measure the same
    out.setdefault("record_meta", {}).update({"sensors": record.sensors(), "inputs": record.inputs})
    if meta.pieces:  # several records of the structure (pidyn.data.multi)
        out.setdefault("record_meta", {})["records"] = [
            {
                "name": q.name,
                "t0": float(record.t[q.i0]),
                "t1": float(record.t[q.i1 - 1]),
                **(q.origin.to_dict() if q.origin else {}),
            }
            for q in meta.pieces
        ]
    split = meta.split if hold_out else None
    if split:
        out["heldout"] = heldout_scores(sim, record, split.heldout, split.fit)
        logging.getLogger(__name__).info(
            "held-out part %.4g-%.4g s: NRMSE %s",
            *split.heldout,
            ", ".join(f"{k} {v:.3g}" for k, v in out["heldout"]["nrmse"].items()),
        )
    return out


NOT_ADEQUATE = "the identified model does not describe the record (metrics.json adequacy)"

#: a damping ratio outside this range is the fit's, not a structure's (a bridge, a building)
DAMPING_RANGE = (0.005, 0.30)
#: nor is one whose 95 % interval spans more than this factor
DAMPING_SPAN = 3.0


def judge_damping(mode: dict) -> None:
    """Mark a mode whose damping no structure has, or that the record does not determine, as the
    fit's: ``describes_structure: false`` with the reason in ``not_a_property``."""
    zeta, ci = mode.get("damping_ratio"), mode.get("damping_ci95") or [None, None]
    lo, hi = DAMPING_RANGE
    why = None
    if zeta is None or not np.isfinite(zeta):
        why = "no damping ratio"
    elif not lo <= zeta <= hi:
        why = f"damping ratio {100 * zeta:.3g} % outside {100 * lo:g}-{100 * hi:g} %"
    elif any(v is None or not np.isfinite(v) for v in ci):
        why = "no interval of the damping ratio"
    elif ci[0] <= 0 or ci[1] / ci[0] > DAMPING_SPAN:
        why = f"damping interval [{100 * ci[0]:.3g}, {100 * ci[1]:.3g}] % spans more than a factor {DAMPING_SPAN:g}"
    if why is not None:
        mode["describes_structure"] = False
        mode["not_a_property"] = why


def reported_damping(mode: dict | None) -> tuple[float | None, list | None]:
    """(damping ratio, its interval) as a table reports them: none for a mode that does not
    describe the structure (``judge_damping``, or a model the data reject)."""
    if not mode or mode.get("describes_structure") is False:
        return None, None
    return mode.get("damping_ratio"), mode.get("damping_ci95")


def modal_summary(system, values: dict[str, float], refined: Any = None) -> list[dict] | None:
    """The identified model's modes about rest, fundamental first, with intervals from the
    refinement's covariance (None for a model without a stiffness about rest)."""
    cov = getattr(refined, "covariance", None) if refined is not None else None
    names = getattr(refined, "names", None) if refined is not None else None
    try:
        modes = modes_with_intervals(system, values, names, None if not cov else np.asarray(cov))
    except (ValueError, KeyError, np.linalg.LinAlgError):
        return None
    profile = getattr(refined, "period_profile", None) or {}
    if profile and len(modes) == 1:  # the period's profile-likelihood set (``pidyn.refine.period_profile``)
        modes[0]["period_profile_ci95"] = list(profile["ci95"])
    for m in modes:
        judge_damping(m)
    if getattr(system, "modal_coordinates", False):  # a modes model's own coordinates: no shapes to read
        for m in modes:
            m.pop("mode_shape", None)
            m.pop("mode_shape_ci95", None)
    return modes


def write_modal(run_dir: Path, modes: list[dict] | None, extra: dict | None = None) -> None:
    """``modal.json``: ``{"modes": [{period_s, period_ci95, frequency_hz, damping_ratio, damping_ci95}, ...]}``."""
    if modes is not None:
        write_json(run_dir / "modal.json", {"modes": modes, **(extra or {})})


def heldout_scores(
    sim: dict[str, np.ndarray],
    record,
    span: tuple[float, float] | list[float],
    fit: tuple[float, float] | list[float] | None = None,
) -> dict[str, Any]:
    """NRMSE of the simulated response on the held-out ``span`` per measured channel (``a1``,
    ``x``...; accelerations as the sensors read them), their mean, and the same on ``fit``."""

    def scores(lo: float, hi: float) -> dict[str, float]:
        m = (record.t >= lo - 1e-9) & (record.t <= hi + 1e-9)
        out = {}
        for kind, floors in record.sensors().items():
            meas = getattr(record, kind)
            for fl in floors:
                pred = measured_convention(sim, record, kind)[:, fl - 1]
                truth = meas[:, fl - 1] + (ground_acceleration(record) if kind == "a" else 0.0)
                out[f"{kind}{fl}"] = (
                    nrmse(pred[m], truth[m]) if np.all(np.isfinite(pred[m])) else float("inf")
                )
        return out

    held = scores(*span)
    out: dict[str, Any] = {
        "span": [float(span[0]), float(span[1])],
        "nrmse": held,
        "mean_nrmse_a": _mean([v for k, v in held.items() if k.startswith("a")]),
    }
    if fit is not None:
        fitted = scores(*fit)
        out["fit_span"] = [float(fit[0]), float(fit[1])]
        out["fit_nrmse"] = fitted
        out["fit_mean_nrmse_a"] = _mean([v for k, v in fitted.items() if k.startswith("a")])
    return out


def measured_convention(sim: dict[str, np.ndarray], record, kind: str) -> np.ndarray:
    """The simulated channel as the sensor reads it: an accelerometer's absolute acceleration
    (the record keeps one input's relative; ``_ground`` adds it back on both sides)."""
    g = ground_acceleration(record)
    return sim[kind] + (g[:, None] if kind == "a" and isinstance(g, np.ndarray) else 0.0)


def ground_acceleration(record) -> np.ndarray | float:
    """The ground acceleration to add back to a relative acceleration (one input), else 0."""
    return np.asarray(record.f, float) if record.excitation == "ground" and record.n_inputs == 1 else 0.0


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None
