"""The steps of a single degree of freedom's diagnosis (``subjects.single_dof`` runs them in the
diagnosis loop, ``pidyn.discrepancy.loop``):

1. a data-driven start, then the nominal model on the fitting part (``identify``: PIDynNet,
   then optionally an output-error polish);
2. the force it cannot explain, screened against the effect library
   (``pidyn.discrepancy.screening``): a cause, or ``none``; an effect the weak-form screening
   leans to without deciding is fitted by output error and named when the simulated response
   decides for it (``pidyn.discrepancy.confirm``);
3. the held-out check, and where the structure changed when the model fails there
   (``pidyn.discrepancy.changes``); the first cause (``_first_cause``);
4. the model extended with the named effect and identified again (``extension_step``), screened
   again (``next_cause``), until nothing more passes the evidence (a structured remainder no
   library effect explains gets a learned force, ``pidyn.discrepancy.learned_fit``);
5. nominal and extended models simulated over the held-out part and compared.

The case and what it ends with are ``pidyn.discrepancy.case``; the nominal model's start, fit,
modes and running period ``pidyn.discrepancy.nominal``.

``identify(node, folder, fit) -> (metrics, system, values)`` identifies the model a config
node describes on the fitting span ``fit`` and writes its run to ``folder``: the task passes
it in, so this package never imports the task layer.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

import numpy as np

from pidyn.discrepancy.accelerometers import acceleration_gain
from pidyn.discrepancy.case import Case, Extension, Nominal
from pidyn.discrepancy.confirm import Confirmation, confirm, undecided
from pidyn.discrepancy.effects import EFFECTS, Signals
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.extend import (  # noqa: F401
    EXTENSION,
    build_system,
    check_fit,
    extension_node,
    release_held,
    system_node,
)
from pidyn.discrepancy.learned_step import (
    LEARNED,
    learned_row,
    refuse_learned,
    save_unexplained,
    train_learned_force,
)
from pidyn.discrepancy.nominal import (
    fit_budget,
    polish,
)
from pidyn.discrepancy.screening import Screening, screen
from pidyn.discrepancy.step_reports import ExtensionStep
from pidyn.discrepancy.verdicts import Verdict
from pidyn.reporting import nrmse
from pidyn.systems.sdof import SDOFSystem
from pidyn.weak_form import WeakForm

log = logging.getLogger(__name__)


def _first_cause(
    case: Case, nom: Nominal, sc, check, change_row: Evidence | None, forced, running: dict | None = None
) -> tuple[str | None, Any, Evidence | None]:
    """The cause to extend with first (a located change, a forced effect, the screening's
    choice), the output-error confirmation where the simulated response decides, and the
    located change that survives it. A period that moves through the record (``running``) adds
    the amplitude-dependent structure to the candidates."""
    cause = change_row.effect if change_row is not None else (forced or sc.cause)
    confirmation = None
    if case.from_accelerometers and not forced and (change_row is None or not check.failed):
        # integrated accelerations are a poor measurement of the motion: the weak form proposes, output
        # error on the accelerations decides among every effect it could fit, a change it located in time
        # included while the nominal model holds on the held-out part (a change the weak form reads
        # into integration drift fits the accelerations no better)
        extra = [] if change_row is None else [_change_candidate(change_row)]
        if running and running.get("variation", {}).get("varies") and not case.settings.effects:
            extra.append(_amplitude_candidate())  # (a user's list of effects screens it where it names it)
        confirmation = confirm_undecided(
            case, nom.system, nom.values, nom.node, sc, nom.s, 1, everything=True, extra=extra
        )
        cause = None if confirmation.row is None else confirmation.row.effect
        if change_row is not None and cause != change_row.effect:
            log.info("the output error does not confirm the change the weak form located: none is named")
            change_row = None
    elif cause is None and not forced and sc.verdict == Verdict.NONE:
        # an effect the weak form leans towards without deciding: the simulated response decides
        confirmation = confirm_undecided(case, nom.system, nom.values, nom.node, sc, nom.s, 1)
        if confirmation.row is not None:
            cause = confirmation.row.effect
    return cause, confirmation, change_row


def _change_candidate(change_row: Evidence) -> Evidence:
    """A located change as one candidate of the output-error check: started where the weak form
    put it, its time free (no ``change``, so nothing is held), its location kept for the record."""
    return Evidence(
        change_row.effect,
        score=change_row.score,
        parameters=dict(change_row.parameters),
        located=change_row.change.to_dict(),
    )


#: the amplitude-dependent structure, tried where the period moves (``Effect.tried_where_period_moves``)
AMPLITUDE = next(n for n, e in EFFECTS.items() if e.tried_where_period_moves)


def _amplitude_candidate() -> Evidence:
    """The amplitude-dependent structure as a candidate of the output-error check, started at a
    small softening and a time constant of a second (on the 1992 Petrolia records the fits from
    0.5 and 2 s ended together; the weak form does not score it: ``score`` None)."""
    return Evidence(AMPLITUDE, parameters={"soft": 0.1, "gain": 0.1, "tau": 1.0})


def _cause_row(cause: str | None, sc, change_row: Evidence | None, confirmation) -> Evidence | None:
    """The evidence row the extension starts from: the learned force's, the located change's,
    the confirmation's or the screening's."""
    if cause is None:
        return None
    if cause == LEARNED:
        return learned_row(sc.structure)
    if change_row:
        return change_row
    if confirmation and confirmation.row:
        return confirmation.row
    return next(r for r in sc.ranking if r.effect == cause)  # a forced effect is screened (``case.prepare``)


def _acceleration_sims(case: Case, nom: Nominal, ext: Extension) -> dict:
    """The nominal and extended models' responses: the gain is measured on the accelerations, as
    the sensors read them."""
    v0 = float(nom.s.v[0])
    return {
        "nominal": case.free_response(nom.system, nom.values, v0),
        "extended": None if ext.system is None else case.free_response(ext.system, ext.values, v0),
    }


def heldout_errors(case: Case, nom: Nominal, ext: Extension) -> dict[str, float | None]:
    """The nominal and extended models' held-out NRMSE as ``diagnosis.json``'s ``gain`` gives it:
    of the displacement, or of the accelerations as the sensors read them."""
    held = case.mask(case.held)
    sims = _acceleration_sims(case, nom, ext)
    if case.from_accelerometers:
        gain = acceleration_gain(case.record, sims, held)
        return {"nominal": gain["nominal"], "extended": gain["extended"]}
    return {k: None if s is None else nrmse(s["x"][held, 0], case.x_raw[held]) for k, s in sims.items()}


def extension_step(
    case: Case, nom: Nominal, node: dict, values: dict, cause: str, row: Evidence, out: Extension
) -> tuple[dict, dict[str, float], SDOFSystem] | None:
    """Step k: the current model extended with ``cause``, identified, polished (and a learned
    force trained on the response); recorded in ``out``. None when a learned force is refused."""
    st, record, s = case.settings, case.record, nom.s
    if row.score is not None and not np.isfinite(row.score):
        raise ValueError(f"effect '{cause}' has no physical fit to this record ({row.note})")
    k = len(out.causes) + 1
    if cause == LEARNED:  # start the network at the force the current model cannot explain
        path = save_unexplained(
            case.run_dir / f"unexplained_{k}.npz",
            record,
            build_system(node),
            values,
            case.x_raw,
            case.fit,
            f=case.weak_f,
        )
        row = replace(row, parameters={"init_from": str(path)})
    ext_node = extension_node(node, values, cause, row, s.context(), k, case.mass_known)
    folder = case.run_dir / ("extended" if k == 1 else f"extended_{k}")
    metrics, system, ext_values = case.identify(ext_node, folder, case.fit)
    trained = cause == LEARNED and st.learned.output_error
    if st.polish:  # a held change time is refined here, from where the search put it; a learned force's
        # model only briefly: its training on the simulated response (the physical parameters with the
        # weights) follows and the held-out part decides, so a long polish before it buys nothing
        budget = int(st.polish_max_nfev) if trained else None
        check = None if cause == LEARNED else check_fit(values, row, k)  # the fit that named the effect
        ext_values, out.note = polish(case, build_system(release_held(ext_node)), ext_values, budget, check)
    if trained:
        ext_values, out.learned_fit = train_learned_force(
            record, system, ext_values, s, case.fit, st.learned, folder
        )
    errors = None
    if cause == LEARNED:
        out.refused, errors = refuse_learned(
            record,
            build_system(node),
            values,
            system,
            ext_values,
            case.x_raw,
            float(s.v[0]),
            case.held,
            int(st.substeps),
            folder,
        )
        if out.refused is not None:  # a network that fits the fitting part but predicts worse
            return None
    out.causes.append(cause)
    equation = system.describe(ext_values)
    # the step keeps the evidence as it stands now (copies: a later check may annotate the rows)
    out.steps.append(
        ExtensionStep(k, cause, folder.name, equation, replace(row), errors if cause == LEARNED else None)
    )
    out.system, out.values, out.metrics = system, ext_values, metrics
    log.info("step %d: extended with %s: %s", k, cause, system.describe(ext_values))
    return ext_node, ext_values, system


def next_cause(
    case: Case,
    system: SDOFSystem,
    values: dict[str, float],
    node: dict,
    remaining: dict,
    out: Extension,
    s: Signals,
    weak: WeakForm,
) -> tuple[str | None, Evidence | None]:
    """Screen the model just extended against the effects not yet in it; what the weak form
    leaves undecided goes to the output-error check, and a structured remainder no library
    effect explains to the learned force. The evidence lands on the last step of ``out``."""
    k = len(out.causes)
    sc = screen(
        system,
        values,
        s,
        case.weak_f,
        case.x_raw,
        weak,
        case.fit[1],
        case.mass_known,
        remaining,
        case.thresholds,
    )
    step = out.steps[-1]
    step.next_ranking = [replace(r) for r in sc.ranking]
    step.next_structure, step.next_verdict = dict(sc.structure), sc.verdict
    log.info(
        "screening the extended model: %s",
        ", ".join(f"{r.effect} {r.score:.1f}" for r in sc.ranking[:4] if r.score is not None),
    )
    if case.from_accelerometers:  # output error on the accelerations decides (see ``run``)
        confirmation = confirm_undecided(case, system, values, node, sc, s, k + 1, everything=True)
        step.next_confirmation = [replace(r) for r in confirmation.tested]
        return (None, None) if confirmation.row is None else (confirmation.row.effect, confirmation.row)
    if sc.cause is not None:
        return sc.cause, next(r for r in sc.ranking if r.effect == sc.cause)
    if sc.verdict == Verdict.NONE:  # the simulated response decides what the weak form leans to
        confirmation = confirm_undecided(case, system, values, node, sc, s, k + 1)
        step.next_confirmation = [replace(r) for r in confirmation.tested]
        if confirmation.row is not None:
            return confirmation.row.effect, confirmation.row
    if sc.verdict == Verdict.UNEXPLAINED and LEARNED not in out.causes and case.settings.learn_unexplained:
        return LEARNED, learned_row(
            sc.structure
        )  # what remains is structured but no library effect: learn it
    return None, None


def confirm_undecided(
    case: Case,
    system: SDOFSystem,
    values: dict[str, float],
    node: dict,
    sc: Screening,
    s: Signals,
    k: int,
    everything: bool = False,
    extra: list[Evidence] | None = None,
) -> Confirmation:
    """The output-error check of the effects screening ``sc`` leaves undecided
    (``pidyn.discrepancy.confirm``); ``diagnosis.confirm.max_candidates`` = 0 turns it off.
    ``everything``: every effect the weak form could fit at all (an accelerometer record);
    ``extra``: candidates from elsewhere (a located change), tried after them."""
    st = case.settings
    if everything:
        candidates = [
            r for r in sc.ranking if r.score is not None and np.isfinite(r.score) and not r.step_in_time
        ]
    else:
        candidates = undecided(sc.ranking, case.thresholds, int(st.confirm.max_candidates))
    candidates = candidates + list(extra or [])
    if not candidates:
        return Confirmation()
    node = release_held(node)  # as in the polish: a located change time is refined with the rest
    ctx = s.context()

    def build(row: Evidence) -> Any:
        return build_system(extension_node(node, values, row.effect, row, ctx, k, case.mass_known))

    # deciding, not confirming (an accelerometer record): each fit run to its end
    nfev = fit_budget(case) if everything else int(st.polish_max_nfev)
    return confirm(
        case.record,
        build_system(node),
        values,
        candidates,
        build,
        case.fit,
        case.held,
        case.thresholds,
        substeps=int(st.substeps),
        max_nfev=nfev,
        polish_seconds=st.polish_seconds,
        tol=float(st.polish_tol),
    )
