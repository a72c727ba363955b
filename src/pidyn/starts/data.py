"""A start read from the record itself, not from the config's numbers.

A real structure's stiffness is rarely known to within a factor of ten (the Painter Street
deck's k per unit mass is about 700 s^-2; a config's 10 is a two-second period), and from a
start that far away the identification ends anywhere. Three estimates, all milliseconds:

* **equation error on integrated signals** (``pidyn.baselines.integrated``) when every degree
  of freedom carries a sensor and the model has no unmeasured latent state;
* **a frequency scan** for a building the equation error cannot take (floors without sensors, a
  hysteretic storey): the config's stiffness profile scaled to a grid of fundamental
  frequencies and damping ratios, each linear part simulated freely, the best fit taken;
* **the transfer function's peak and width** otherwise: the fundamental frequency and damping
  ratio of the top measured floor's transmissibility; the config's stiffness profile is scaled
  so the model's first frequency matches, and stiffness-proportional damping gives its damping
  ratio.

The train task uses it for PIDynNet's start on measured records (``model.start``) and offers
it to the refinement as one more starting estimate.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import cont2discrete, dlsim

from pidyn.baselines.integrated import corner_of, fit_integrated, integrated_applies
from pidyn.data.checks import record_where
from pidyn.data.errors import DataError
from pidyn.signals import fundamental, response_pair
from pidyn.systems.modal import first_mode, scaled_to

log = logging.getLogger(__name__)

#: a building's frequency scan: fundamental frequencies per octave, and the damping ratios tried
#: beside the transmissibility's
SCAN_PER_OCTAVE, SCAN_DAMPING = 12, (0.02, 0.05)


@dataclass
class DataStart:
    """Starting values of the trainable parameters and how they were read from the record."""

    values: dict[str, float]
    method: str  # equation_error | frequency_scan | transfer_function
    frequency_hz: float | None
    damping_ratio: float | None
    note: str = ""
    seconds: float = 0.0
    rejected: dict[str, float] = field(default_factory=dict)

    @property
    def period_s(self) -> float | None:
        return None if not self.frequency_hz else 1.0 / self.frequency_hz

    def to_dict(self) -> dict:
        return {
            "values": self.values,
            "method": self.method,
            "frequency_hz": self.frequency_hz,
            "period_s": self.period_s,
            "damping_ratio": self.damping_ratio,
            "note": self.note,
            "seconds": self.seconds,
            "rejected": self.rejected,
        }


#: a system's settings that are the structure's scale, not identified: null in its config reads
#: them from the records (``structure_scale``)
DATA_SCALES = ("w0", "a_ref")


def structure_scale(record) -> dict[str, float]:
    """The structure's own scale from its records: ``w0``, the circular frequency of the
    fundamental resonance (rad/s), and ``a_ref``, a typical response amplitude of the strongest
    shaking (m): the largest relative response of the top measured floor as a displacement
    amplitude at w0 (an acceleration over w0^2, a velocity over w0). Over several records laid
    end to end, both are the joined records': the strongest records set them. (The median of the
    records' own resonances, steadier from one set of records to the next, predicted 16 of 18
    unseen Painter Street events worse: experiments/results/real/amplitude_scale_check.md.)"""
    peak = fundamental(record)
    if peak is None:
        raise DataError(
            f"{record_where(record)}: no resonance to read the structure's scale from; "
            f"set {' and '.join(f'system.{k}' for k in DATA_SCALES)}"
        )
    w0 = 2.0 * np.pi * float(peak[0])
    kind, relative = response_pair(record)
    power = {"x": 0, "v": 1, "a": 2}[kind]
    a_ref = float(np.max(np.abs(relative))) / w0**power
    log.info(
        "the structure's scale from the record: w0 = %.4g rad/s (%.3g s), a_ref = %.3g",
        w0,
        2 * np.pi / w0,
        a_ref,
    )
    return {"w0": w0, "a_ref": a_ref}


def start_from_data(record, system) -> DataStart | None:
    """The data's start for ``system`` on ``record`` (None when the record shows no resonance)."""
    t0 = time.perf_counter()
    peak = fundamental(record)
    if peak is None:
        return None
    fn, zeta = peak
    out = None
    if integrated_applies(record, system):
        try:
            out = _from_equation_error(record, system, fn, zeta)
        except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
            log.info("equation-error start failed (%s); the transfer function's peak is used", exc)
    if _scan_applies(record, system):
        out = _from_scan(record, system, fn, zeta, rival=out) or out
    if out is None:
        out = _from_peak(system, fn, zeta)
    out.seconds = time.perf_counter() - t0
    log.info(
        "start from the data (%s): %s", out.method, ", ".join(f"{k}={v:.5g}" for k, v in out.values.items())
    )
    return out


def _from_equation_error(record, system, fn: float, zeta: float) -> DataStart | None:
    fit = fit_integrated(record, system, corner_of(record, fn), fn, zeta)
    if fit is None:
        return None
    init = {s.name: float(s.init) for s in system.param_specs()}
    freq, zeta = first_mode(system, {**init, **fit.values})
    return DataStart(fit.values, "equation_error", freq, zeta, note=fit.note)


def _scan_applies(record, system) -> bool:
    """A building (several degrees of freedom, no modal start) on one ground."""
    return (
        getattr(system, "n_dof", 1) > 1
        and hasattr(system, "linear_matrices")
        and not hasattr(system, "start_at")
        and record.excitation == "ground"
        and np.asarray(record.f).ndim == 1
    )


def _from_scan(
    record, system, peak_hz: float, peak_zeta: float, rival: DataStart | None = None
) -> DataStart | None:
    """A building the equation error cannot take (floors without a sensor): the config's
    stiffness profile scaled to each fundamental frequency of a grid (``SCAN_PER_OCTAVE`` per
    octave, from the record's lowest resolvable frequency to a fifth of the sampling rate) and
    each damping ratio (``SCAN_DAMPING`` and the transmissibility's), its linear part simulated
    freely (an exact discretization, milliseconds), and the best fit of the measured channels
    taken. A 20 s record resolves its transmissibility to 0.2 Hz: on the building benchmark's
    sparse-sensor cases the peak sat on the second mode, 2.3-2.9 times the fundamental, and a
    4-storey start there ended at a fifth of the fundamental's stiffness elsewhere.

    ``rival`` (the equation error's start, every floor measured) is returned instead when it
    simulates the record at least as well. Twice-integrated accelerations high-passed at a fifth
    of the fundamental put the storeys 13-58 % below the truth on Kobe records of the building
    benchmark (misfit 0.42-0.95 against the scan's 0.13-0.22), and the refinement from there
    diverged; under El Centro the equation error was within 1 % (misfit 0.011 against 0.24)."""
    duration = float(record.t[-1] - record.t[0])
    lo, hi = max(2.0 / max(duration, 1e-9), 0.05), 0.2 / record.dt
    if not lo < hi:
        return None
    grid = lo * 2.0 ** (np.arange(int(np.log2(hi / lo) * SCAN_PER_OCTAVE) + 1) / SCAN_PER_OCTAVE)
    measured = {k: [j - 1 for j in v] for k, v in record.sensors().items() if v}
    init = {s.name: float(s.init) for s in system.param_specs()}
    best = None
    for fn in [*grid, peak_hz]:
        for zeta in sorted({*SCAN_DAMPING, peak_zeta}):
            cand = _from_peak(system, float(fn), float(zeta))
            score = _linear_misfit(record, system, {**init, **cand.values}, measured)
            if best is None or score < best[0]:
                best = (score, cand, fn, zeta)
    if best is None or not np.isfinite(best[0]):
        return None
    score, cand, fn, zeta = best
    note = f"free-simulation scan: fundamental {fn:.4g} Hz, damping {100 * zeta:.2g} % (misfit {score:.3g}); "
    note += f"transmissibility peak {peak_hz:.4g} Hz"
    if rival is not None:
        own = _linear_misfit(record, system, {**init, **rival.values}, measured)
        if own <= score:
            return rival
        log.info("equation-error start (misfit %.3g) replaced by the frequency scan's (%.3g)", own, score)
        note += f"; the equation-error start simulated the record worse (misfit {own:.3g})"
    return DataStart(cand.values, "frequency_scan", float(fn), float(zeta), note=note)


def _linear_misfit(record, system, values: dict[str, float], measured: dict[str, list[int]]) -> float:
    """The linear part's free response from rest against the measured channels: the sum over
    channels of the squared error over the squared signal (relative motion, one ground)."""
    m, c, k = system.linear_matrices(values)
    n = m.shape[0]
    minv = np.linalg.inv(m)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ k, -minv @ c]])
    b = np.concatenate([np.zeros(n), -np.ones(n)])[:, None]
    outputs = {"x": np.hstack([np.eye(n), np.zeros((n, n))]), "v": np.hstack([np.zeros((n, n)), np.eye(n)])}
    outputs["a"] = a[n:]
    cc = np.vstack(list(outputs.values()))
    dd = np.vstack([np.zeros((2 * n, 1)), b[n:]])
    with np.errstate(all="ignore"):
        ad, bd, cd, ddd, _ = cont2discrete((a, b, cc, dd), record.dt, method="foh")
        _, y, _ = dlsim((ad, bd, cd, ddd, record.dt), np.asarray(record.f, float))
    total = 0.0
    for i, kind in enumerate(outputs):
        if kind in measured:
            meas = getattr(record, kind)[:, measured[kind]]
            sim = y[:, i * n : (i + 1) * n][:, measured[kind]]
            total += float(np.sum((meas - sim) ** 2) / max(np.sum(meas**2), 1e-300))
    return total if np.isfinite(total) else float("inf")


def _from_peak(system, fn: float, zeta: float) -> DataStart:
    """The model's linear part scaled to the measured fundamental frequency and damping ratio."""
    return DataStart(
        scaled_to(system, fn, zeta),
        "transfer_function",
        fn,
        zeta,
        note=f"transmissibility peak {fn:.4g} Hz, half-power damping {100 * zeta:.2g} %",
    )
