"""A single degree of freedom as a subject of the diagnosis loop: the cause sits in the
structure itself. Its steps are ``pidyn.discrepancy.sdof_steps``; a record of accelerometers is
seen through the relative motion integrated from them (``accelerometers.motion_view``)."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

from pidyn.data.checks import check_record
from pidyn.discrepancy.accelerometers import motion_view, needs_view
from pidyn.discrepancy.case import Case, Extension, Outcome, prepare, split_spans
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.learned_step import LEARNED, learned_row
from pidyn.discrepancy.loop import Inputs, Step, Subject, extend
from pidyn.discrepancy.nominal import identify_nominal, nominal_modes, running_period, starting_point
from pidyn.discrepancy.nominal_check import check_heldout
from pidyn.discrepancy.report import report_sections
from pidyn.discrepancy.residual import unexplained_force
from pidyn.discrepancy.result import DiagnosisResult
from pidyn.discrepancy.screening import EXCLUSIVE
from pidyn.discrepancy.sdof_steps import (
    _acceleration_sims,
    _cause_row,
    _first_cause,
    extension_step,
    heldout_errors,
    next_cause,
)
from pidyn.discrepancy.summary import conclusion, summarize, write_figures
from pidyn.discrepancy.verdicts import Verdict, unearned_names
from pidyn.progress import Steps
from pidyn.systems.sdof import SDOFSystem

log = logging.getLogger(__name__)


class SingleDOF(Subject):
    """The nominal model, its screening, held-out check and running period, the first cause; then
    each step extends the model with the pending cause, identifies it (PIDynNet, polish) and screens
    it for the next; the names must earn their place together, or a learned force is tried from the
    nominal model in their place. The current model is (config node, values, system)."""

    place = ""
    takes_words = "a single degree of freedom"

    def __init__(self, case: Case) -> None:
        self.case = case
        self.progress = Steps("diagnosis", 6, log)
        self.forced = bool(case.settings.force_effect)  # the case's: a forced effect's name is never refused
        self._begin(None, None, self.forced)

    @classmethod
    def takes(cls, system: Any) -> bool:
        return isinstance(system, SDOFSystem)

    @classmethod
    def compose(cls, system: Any, inputs: Inputs) -> SingleDOF:
        settings, base = inputs.settings, system
        record = inputs.the_record(base)
        check_record(record)
        if record.excitation != base.excitation:
            base = inputs.make_system(excitation=record.excitation)
        # accelerometers: the relative motion the screening needs, from the accelerations
        if needs_view(record):
            full = inputs.make_system(inputs=record.inputs) if record.n_inputs > 1 else base
            fit = split_spans(record, float(settings.fit_share))[0]
            record = motion_view(record, full, fit, tol=float(settings.polish_tol))

        def identify(node: dict, folder: Path, fit: tuple[float, float]):
            return inputs.identify(record, node, folder, fit)

        return cls(prepare(record, base, inputs.system_node, settings, inputs.mass, inputs.run_dir, identify))

    @property
    def run_dir(self) -> Path:
        return self.case.run_dir

    def nominal(self) -> tuple[dict, dict[str, float], SDOFSystem]:
        case, progress = self.case, self.progress
        progress.step("the nominal model")
        values0, period = starting_point(case)
        nom = self.nom = identify_nominal(case, values0, period)
        progress.step("screening")
        sc = self.sc = case.screen(nom.system, nom.values, nom.s, nom.weak)
        self.pointwise = unexplained_force(
            nom.system, nom.values, case.record.t, case.x_raw, case.weak_f, nom.period
        )
        forced = case.settings.force_effect
        log.info("screening: %s", ", ".join(f"{r.effect} {r.score:.1f}" for r in sc.ranking[:4]))
        # does the nominal model hold on the held-out part? if not, when did the structure change?
        progress.step("held-out check and running period")
        self.x_nom = case.free_run(nom.system, nom.values, float(nom.s.v[0]))
        check, change_row = check_heldout(case, nom, sc, self.x_nom, bool(forced))
        running = self.running = running_period(case, nom)
        progress.step("the first cause")
        cause, self.confirmation, change_row = _first_cause(case, nom, sc, check, change_row, forced, running)
        self.check, self.change_row = check, change_row
        # a period that moves beyond its windows' intervals refutes one linear model
        if case.from_accelerometers:
            structured = check.failed or bool(running and running.get("variation", {}).get("varies"))
        else:
            structured = sc.verdict == Verdict.UNEXPLAINED or check.failed
        if cause is None and case.settings.learn_unexplained and not forced and structured:
            cause = LEARNED  # structured, but nothing in the library explains it: learn the force
        self.cause = cause
        progress.step("extensions")
        self._begin(cause, _cause_row(cause, sc, change_row, self.confirmation), self.forced)
        return self._start()

    def _start(self) -> tuple[dict, dict[str, float], SDOFSystem]:
        return self.nom.node, self.nom.values, self.nom.system

    def _begin(self, cause: str | None, row: Evidence | None, forced: bool) -> None:
        """Extensions from the nominal model with ``cause`` first (its evidence ``row``); ``forced``:
        this run extends with the forced effect alone."""
        self.ext = Extension()
        self.pending: tuple[str | None, Evidence | None] = (cause, row)
        self.limit = 1 if forced else int(self.case.settings.max_effects)
        self.forced_run = forced

    def more(self, found: list) -> bool:
        cause, row = self.pending
        return cause is not None and row is not None and bool(self.case.settings.extend)

    def next_step(self, current: tuple, found: list) -> Step | None:
        """Step k: the current model extended with the pending cause, identified, polished (a learned
        force trained on the response); then the extended model screened against the effects not yet
        in it for the next cause, up to ``diagnosis.max_effects``. A learned force that predicts the
        held-out part worse is refused. Step k's run is in ``extended/`` (k = 1) or ``extended_<k>/``."""
        case, ext = self.case, self.ext
        node, values, _ = current
        cause, row = self.pending
        self.pending = (None, None)
        assert cause is not None and row is not None
        step = extension_step(case, self.nom, node, values, cause, row, ext)
        if step is None:  # a learned force that predicts the held-out part worse: not kept
            return Step(False, current, cause, ext.refused)
        node, values, system = step
        if len(ext.causes) >= self.limit:
            if not self.forced_run:
                log.info("stopping at diagnosis.max_effects=%d effects", self.limit)
        elif cause != LEARNED:  # the learned force takes whatever is left: nothing to screen after it
            present = set(ext.causes) | {t.name for t in system.terms}
            blocked = set().union(*[g for g in EXCLUSIVE if g & present])
            remaining = {n: e for n, e in case.effects.items() if n not in present | blocked}
            if remaining:
                nxt = next_cause(case, system, values, node, remaining, ext, self.nom.s, self.nom.weak)
                if not (nxt[0] == LEARNED and LEARNED in ext.causes):
                    self.pending = nxt
        return Step(True, step, cause, ext.steps[-1])

    def conclude(self, current: Any, found: list, steps: list[Step], refused: Step | None) -> DiagnosisResult:
        case, nom = self.case, self.nom
        ext = self._names_earn_or_learn()
        causes = ext.causes if case.settings.extend else ([] if self.cause is None else [self.cause])
        self.progress.step("simulations and modes")
        x_ext = case.free_run(ext.system, ext.values, float(nom.s.v[0])) if ext.system is not None else None
        sims = _acceleration_sims(case, nom, ext) if case.from_accelerometers else {}
        outcome = Outcome(
            nom,
            self.sc,
            self.check,
            self.change_row,
            ext,
            causes,
            self.cause,
            self.forced,
            self.confirmation,
            self.pointwise,
            self.x_nom,
            x_ext,
            sims,
            nominal_modes(case, nom),
            self.running,
        )
        return conclusion(case, outcome)

    def _names_earn_or_learn(self) -> Extension:
        """The library names of an extension must earn their place together (``unearned_names``, on
        the held-out errors the diagnosis reports): the members of a pair may help only together (a
        gap alone once predicted 1.82 -> 2.17, gap and friction 0.99). When they do not, the extension
        is not kept (``unearned``, with its steps) and a learned force is tried from the nominal model
        in their place; a forced effect's model is kept, its name still refused."""
        case, ext = self.case, self.ext
        names = [c for c in ext.causes if c != LEARNED]
        if not names or ext.system is None:
            return ext
        refused = unearned_names(names, heldout_errors(case, self.nom, ext), case.thresholds)
        if refused is None or self.forced:
            return replace(ext, unearned=refused)
        log.info("%s", refused["note"])
        learned = case.settings.learn_unexplained and LEARNED not in ext.causes
        self._begin(LEARNED if learned else None, learned_row(self.sc.structure) if learned else None, False)
        extend(self, self._start())
        return replace(self.ext, unearned={**refused, "steps": ext.steps})

    def details(self, result: DiagnosisResult) -> dict[str, Any]:
        return summarize(self.case, result)

    def sections(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        return report_sections(summary)

    def figures(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        return write_figures(self.case, result.detail, summary)
