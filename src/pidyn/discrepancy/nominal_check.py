"""Whether the nominal model holds on the held-out part (the calibrated test of ``heldout_check``
on what the sensors read) and, where the data say it does not, when the structure changed."""

from __future__ import annotations

import logging

import numpy as np

from pidyn.discrepancy.case import Case, Nominal
from pidyn.discrepancy.changes import locate_step
from pidyn.discrepancy.effects import EFFECTS
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.heldout_check import (
    HELDOUT_BAND,
    SETTLE_PERIODS,
    HeldoutCheck,
    heldout_check,
    simulation_sensitivity,
)
from pidyn.discrepancy.screening import Screening
from pidyn.simulate import simulate_response

log = logging.getLogger(__name__)


def heldout_test(case: Case, nom: Nominal, x_nom: np.ndarray) -> HeldoutCheck:
    """The calibrated held-out test of the nominal model (``pidyn.discrepancy.heldout_check``): on the
    displacement, or on an accelerometer record the acceleration, as the sensors read it."""
    kind = "a" if case.from_accelerometers else "x"
    if case.from_accelerometers:
        meas = case.record.a[:, 0]
        sim = case.free_response(nom.system, nom.values, float(nom.s.v[0]))["a"][:, 0]
    else:
        meas, sim = case.x_raw, x_nom

    def simulate(p: dict[str, float]) -> np.ndarray:  # the forced response, from rest
        return simulate_response(nom.system, {**nom.values, **p}, case.record, int(case.settings.substeps))[
            kind
        ][:, 0]

    # how the prediction moves with the fitted parameters: their uncertainty widens what a correct
    # model may leave on the held-out part (the forced response's sensitivities: a free run's start
    # from a noisy measured state would read as information the record does not hold)
    names = [s.name for s in nom.system.param_specs() if s.trainable and s.name in nom.values]
    check = heldout_check(
        meas,
        sim,
        case.mask(case.fit),
        case.mask(case.held),
        case.noise_std(meas, nom.period),
        level=float(case.settings.changes.heldout_level),
        sensitivity=simulation_sensitivity(simulate, nom.values, names),
        band=(case.record.dt, HELDOUT_BAND / nom.period),
        settle=int(round(SETTLE_PERIODS * nom.period / case.record.dt)),
    )
    return check


def check_heldout(
    case: Case, nom: Nominal, sc: Screening, x_nom: np.ndarray, forced: bool
) -> tuple[HeldoutCheck, dict | None]:
    """The held-out failure check, and where the structure changed when the data say it did
    (a located change moves ``case.fit`` / ``case.held`` to the change point). On an
    accelerometer record the check compares accelerations, as the sensors read them."""
    check = heldout_test(case, nom, x_nom)
    log.info("%s", check.sentence())
    time_effects = {
        n: p_
        for n, p_ in {
            n: case.stiff if e.changes == "stiffness" else "c" for n, e in EFFECTS.items() if e.step_in_time
        }.items()
        if n in case.effects and p_ in nom.values
    }
    if forced or not time_effects or not ((check.failed and sc.cause is None) or sc.cause in time_effects):
        return check, None
    change, case.fit, case.held = locate_step(
        nom.system,
        nom.values,
        nom.s,
        case.weak_f,
        case.x_raw,
        nom.weak,
        case.fit,
        case.held,
        case.mass_known,
        {n: p_ for n, p_ in time_effects.items() if sc.cause in (None, n)},
        case.thresholds,
        bool(check.failed and sc.cause is None),
    )
    if change is None:
        return check, None
    log.info("%s", change.sentence())
    return check, Evidence(
        change.effect,
        score=-change.delta_bic,
        parameters=change.effect_parameters(),
        source="change",
        change=change,
    )
