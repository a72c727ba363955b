"""The diagnosis of an accelerometer record: the relative motion it needs, from accelerations.

The screening regresses the structure's restoring force on its relative displacement and
velocity, which accelerometers do not measure. So the record is first seen as the motion it
implies:

1. the nominal model (one input per support) is started from the data and fitted by output
   error to the accelerations of the fitting part: its influence coefficients combine the
   supports into the one ground motion the structure feels, ``ag = sum_j r_j ag_j``;
2. the relative acceleration (absolute minus that ground) and the ground are high-passed alike,
   and the relative acceleration integrated spectrally to velocity and displacement
   (``pidyn.signals.integrate``): one linear filter on every term, so a linear model holds
   exactly for the filtered signals, and the drift of integrated noise is gone.

The diagnosis then runs on that record: one effective input, the relative acceleration as its
only measured channel (identification, output error and every held-out judgement use it, as the
sensors read it), and the integrated motion in ``meta.motion`` for the weak-form screening,
which needs x and x'. On a stiff structure the relative motion is a small difference of two large
accelerations and its integral is a poor measurement: the screening then only proposes, and an
output-error fit of each candidate to the accelerations decides (``sdof_steps``). The combination
and the filter are kept in the record's ``meta.accelerometers``.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

import numpy as np

from pidyn.data.meta import AccelerometerView, Motion
from pidyn.data.sources import Record
from pidyn.discrepancy.heteroscedastic import envelope, scale_test
from pidyn.parallel import map_ordered
from pidyn.refine.output_error import fit_output_error, output_error_problem
from pidyn.refine.period_scan import scan_period
from pidyn.reporting import nrmse
from pidyn.signals import fundamental, integrate
from pidyn.starts.data import start_from_data
from pidyn.starts.peers import peer_starts
from pidyn.starts.policy import with_start
from pidyn.starts.score import cheapest
from pidyn.systems.modal import linear_matrices, modal_properties

log = logging.getLogger(__name__)


def needs_view(record: Record) -> bool:
    """A record without a displacement sensor on its one degree of freedom (and not a view already)."""
    return record.meta.motion is None and (record.x is None or bool(np.isnan(record.x[:, 0]).all()))


def motion_view(
    record: Record, system, fit: tuple[float, float], *, tol: float, corner_share: float = 0.1
) -> Record:
    """The record as the relative motion of an accelerometer-measured structure (see the module's
    docstring); ``system``: the nominal model with the record's inputs (influence coefficients);
    ``tol``: the supports' output-error fits stop there (``DiagnosisSettings.polish_tol``)."""
    if record.a is None:
        raise ValueError(f"record '{record.name}': neither a displacement nor an acceleration channel")
    peak = fundamental(record)
    if peak is None:
        raise ValueError(f"record '{record.name}': the accelerations show no resonance to integrate around")
    fn = peak[0]
    system, values, note, weights = _nominal_influence(record, system, fit, tol)
    f = np.asarray(record.f, float)
    several = system.n_inputs > 1
    # the motion relative to the supports weighted by their influence (what the sensor reads of them
    # directly taken off too), driven by the supports' weighted accelerations and their dashpots' share:
    # the linear model with several inputs, written for one input. Its r, g, e stay as fitted
    zero = np.zeros((len(f), 1))
    ground = system.acceleration_output(zero, f, values)[:, 0] if several else f
    drive = -system.forcing(f, values) / values["m"] if several else f
    absolute = record.a[:, 0] if several else record.a[:, 0] + f
    relative = absolute - ground
    corner = max(corner_share * fn, 2.0 / float(record.t[-1] - record.t[0]))
    x, v = (integrate(relative, record.dt, k, corner) for k in (2, 1))
    g = integrate(drive, record.dt, 0, corner)  # the weak form's excitation, filtered as x and v are
    influence = {k: v for k, v in values.items() if k.startswith(("r_", "g_", "e_"))}
    nominal = {k: float(v) for k, v in values.items() if k not in influence}
    meta = record.meta.with_(
        inputs=[],
        sensor_ground=ground,
        motion=Motion(x, v, g),
        accelerometers=AccelerometerView(
            influence=influence,
            nominal=nominal,
            highpass_hz=corner,
            resonance_hz=fn,
            note=note,
            weights=weights,
            inputs=list(record.inputs),
        ),
    )
    if influence:
        log.info(
            "accelerometer record: the supports combined by %s (%s); relative motion high-passed at %.3g Hz",
            ", ".join(f"{k}={val:.4g}" for k, val in influence.items()),
            note,
            corner,
        )
    else:
        log.info("accelerometer record: relative motion integrated, high-passed at %.3g Hz", corner)
    # the noise-free truth is no reference for filtered signals: left out (the parameters' truth stays)
    # identification, output error and the held-out judgements: the relative acceleration and its
    # drive as measured (unfiltered: a nonlinear structure's response to a filtered ground is not the
    # filtered response)
    return replace(record, f=drive, x=None, v=None, a=relative[:, None], meta=meta, clean=None)


def _nominal_influence(
    record: Record, system, fit: tuple[float, float], tol: float
) -> tuple[Any, dict[str, float], str, dict | None]:
    """The nominal model's values from the best start and, with several inputs, the supports'
    influence by output error on the fitting part; with a sentence that says where they came from,
    and the test of the residuals' scale (``_envelope_refit``; None with one input).
    Starts: the data's, and the peers' realizations mapped onto the model (``pidyn.starts.peers``). The
    peer's that simulates the fitting part best is fitted beside the data's, and the lower fitted
    cost is kept: a start's own cost does not rank where its fit ends (on a Painter Street record
    SRIM's start cost half the data's and its fit ended 7 % higher). The kept fit is then checked
    against the other basins of the period (``pidyn.refine.period_scan``): no start need lie in the
    lowest one. With one input nothing is fitted here (the start is ranked by its own cost, and the
    refits after it take the identification's refinement, which scans the period itself)."""
    seg = record.segment(*fit)
    values = {s.name: float(s.init) for s in system.param_specs()}
    start = start_from_data(record, system)
    name = "the config's"
    if start is not None:
        values.update(start.values)
        name = f"the data ({start.method})"
    options = {name: values, **_peer_options(seg, system, values)}
    if system.n_inputs == 1:
        best = cheapest(seg, system, options)
        return with_start(system, options[best]), options[best], f"start from {best}", None
    fitted = map_ordered(
        lambda v: _influence_fit(seg, system, v, tol), list(options.values())
    )  # side by side
    fits = dict(zip(options, fitted))
    best = min(fits, key=lambda k: fits[k][1].cost)
    best = _moved_by_scan(seg, system, fits, options, best, tol)
    if len(fits) > 1:
        log.info(
            "the nominal model fitted from each start (output-error cost on the fitting part): %s; kept %s",
            ", ".join(f"{k} {f[1].cost:.4g}" for k, f in fits.items()),
            best,
        )
    values, res = fits[best]
    note = f"start from {best}, then output error on the accelerations of {fit[0]:.4g}-{fit[1]:.4g} s ({res.note})"
    values, test = _envelope_refit(seg, system, values, tol)
    if test.follows:
        note += (
            f"; the residuals' scale follows the response's envelope (log-likelihood gain {test.statistic:.3g} "
            f"over {test.independent_samples:.0f} independent samples): refitted with each residual divided by it"
        )
    return with_start(system, options[best]), values, note, test.to_dict()


def _envelope_refit(seg: Record, system, values: dict[str, float], tol: float):
    """The supports' fit under the noise model its residuals support (``pidyn.discrepancy.heteroscedastic``):
    where their scale follows the measured response's envelope (over four periods), the fit redone
    from ``values`` with each residual divided by it; else ``values`` as they are. (values, the test)."""
    window = 4.0 * float(modal_properties(*linear_matrices(system, values))["period_s"][0])
    w = envelope(seg.a, seg.dt, window)
    trainable = {s.name for s in system.param_specs() if s.trainable}
    init = {k: v for k, v in values.items() if k in trainable}
    problem, theta = output_error_problem(seg, system, init, 4)
    r = problem.fd_fun_and_jac(columns=np.array([], int))[0](theta)  # the residuals alone
    test = scale_test(r, np.tile(w, len(problem.channel_slices())), window)
    log.info(
        "the supports' fit: residual scale against the response's envelope: gain %.3g over %.0f samples (%s)",
        test.statistic,
        test.independent_samples,
        "refitted with its weights" if test.follows else "one noise level kept",
    )
    if not test.follows:
        return values, test
    res = fit_output_error(seg, system, init=init, max_nfev=100, tol=tol, weights=1.0 / w)
    return {**values, **res.params}, test


def _moved_by_scan(seg: Record, system, fits: dict, options: dict, best: str, tol: float) -> str:
    """The kept fit checked against the other basins of the period; where the scan's start fits
    the fitting part lower, it is added to ``fits`` and ``options`` under a label that says so."""
    scan = scan_period(system, seg, fits[best][0])
    if scan is None or scan.values is None:
        return best
    moved = _influence_fit(seg, system, {**fits[best][0], **scan.values}, tol)
    if not moved[1].cost < fits[best][1].cost:
        return best
    label = f"{best}, moved by {_scan_words(scan)}"
    fits[label], options[label] = moved, moved[0]
    return label


def _scan_words(scan) -> str:
    return (
        f"a scan of the period to {scan.best_ratio:.3g} times it "
        f"(output-error cost {scan.cost:.4g} against {scan.estimate_cost:.4g})"
    )


def _influence_fit(seg: Record, system, values: dict[str, float], tol: float):
    """Output error on ``seg`` from ``values``: (the fitted values, the fit)."""
    trainable = {s.name for s in system.param_specs() if s.trainable}
    res = fit_output_error(
        seg, system, init={k: v for k, v in values.items() if k in trainable}, max_nfev=100, tol=tol
    )
    return {**values, **res.params}, res


def _peer_options(seg: Record, system, values: dict[str, float]) -> dict[str, dict[str, float]]:
    """The peer whose realization on ``seg`` simulates it best (its other parameters from
    ``values``), or none without mdof or a realization that maps onto the model."""
    peers = {f"{k}'s realization": {**values, **v} for k, v in peer_starts(seg, system).items()}
    if not peers:
        return {}
    best = cheapest(seg, system, peers)
    return {best: peers[best]}


def acceleration_gain(record: Record, sims: dict[str, dict | None], held: np.ndarray) -> dict:
    """``heldout_nrmse_a`` of each simulated model (``{"nominal": sim, "extended": sim}``): the
    absolute acceleration (relative + ground, as the accelerometer reads it) on ``held``."""
    seen = record.meta.sensor_ground
    ground = np.asarray(record.f if seen is None else seen, float)  # what the sensor adds to x''
    measured = record.a[:, 0] + ground
    out: dict = {"metric": "heldout_nrmse_a"}
    for key, sim in sims.items():
        if sim is None:
            out[key] = None
            continue
        pred = sim["a"][:, 0] + ground
        out[key] = nrmse(pred[held], measured[held]) if np.all(np.isfinite(pred[held])) else float("inf")
    # knowing nothing: the structure moves with what its sensor's support does
    out["trivial"], out["trivial_label"] = nrmse(ground[held], measured[held]), "moving with its support"
    return out
