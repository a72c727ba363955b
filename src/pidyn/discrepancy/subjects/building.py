"""A shear building as a subject of the diagnosis loop: a cause sits in a storey. Each storey is
seen as a single degree of freedom loaded by its measured shear (``pidyn.discrepancy.storeys``
says how); its steps are ``pidyn.discrepancy.storey_steps``."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

from pidyn.data.checks import check_floors, check_record
from pidyn.data.sources import Record
from pidyn.discrepancy.case import split_spans
from pidyn.discrepancy.loop import Inputs, Step, Subject
from pidyn.discrepancy.result import DiagnosisResult, Finding, HeldoutErrors
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.storey_choice import Study
from pidyn.discrepancy.storey_model import BuildingDiagnosis, BuildingState
from pidyn.discrepancy.storey_report import report_lines, summarize_building, write_building_figures
from pidyn.discrepancy.storey_steps import building_gain, next_step, refusal_notes
from pidyn.discrepancy.storeys import building_verdict, extended_entry, learned_step, nominal_state
from pidyn.discrepancy.verdicts import Verdict
from pidyn.progress import Steps
from pidyn.starts.policy import start_from_run
from pidyn.systems.shear_building import ShearBuilding

log = logging.getLogger(__name__)


class Building(Subject):
    """The nominal building refined; each step screens every storey, and the strongest passing
    (effect, storey) extends the building, named only when it predicts the held-out floor
    accelerations better; a structured storey force that nothing earns is ``unexplained``, and
    gets a learned storey force. The current model is a dict: system, values, held-out errors,
    the refinement's result and the noise."""

    place = "storey"
    takes_words = "a shear building"

    def __init__(
        self,
        record: Record,
        system: ShearBuilding,
        settings: DiagnosisSettings,
        refine_settings: Any,
        start: dict | None,
        run_dir: Path,
    ) -> None:
        self.record, self.system, self.settings = record, system, settings
        self.refine_settings, self.start, self._run_dir = refine_settings, start, run_dir
        self.fit, self.held = split_spans(record, float(settings.fit_share))
        self.progress = Steps(
            "building diagnosis", int(settings.max_effects) * bool(settings.extend) + 2, log
        )

    @classmethod
    def takes(cls, system: Any) -> bool:
        return isinstance(system, ShearBuilding)

    @classmethod
    def compose(cls, system: Any, inputs: Inputs) -> Building:
        record = inputs.the_record(system)
        check_record(record)
        check_floors(record, system.name, system.n_dof)
        refine = inputs.refine_settings()
        if refine is None:
            raise ValueError(
                "diagnose: a building's diagnosis refines every model; model.refine=none is not possible"
            )
        # no networks here: the segments start from the accelerations integrated twice
        refine = replace(refine, states="integrated")
        inputs.run_dir.mkdir(parents=True, exist_ok=True)
        start = None
        if inputs.start not in ("auto", "data", "config"):  # model.start=<an earlier run's folder>
            start = start_from_run(inputs.start, system).values
        return cls(record, system, inputs.settings, refine, start, inputs.run_dir)

    @property
    def run_dir(self) -> Path:
        return self._run_dir

    def nominal(self) -> dict:
        log.info(
            "building diagnosis of '%s': fit %.4g-%.4g s, held out %.4g-%.4g s",
            self.record.name,
            *self.fit,
            *self.held,
        )
        self.study = Study(self.record, self.system, self.settings, self.refine_settings, self.fit, self.held)
        self.progress.step("the nominal building")
        self.nominal_report, current = nominal_state(self.study, self.start)
        return current

    def more(self, found: list) -> bool:
        return len(found) < int(self.settings.max_effects) and bool(self.settings.extend)

    def next_step(self, current: BuildingState, found: list) -> Step | None:
        self.progress.step(f"screening the storeys for effect {len(found) + 1}")
        views, screenings = self.study.screen(current, found)
        return next_step(self.study, current, found, views, screenings)

    def conclude(
        self, current: BuildingState, found: list, steps: list[Step], refused: Step | None
    ) -> DiagnosisResult:
        study, settings, nominal = self.study, self.settings, self.nominal_report
        self.progress.step("the final screening and the verdict", last=True)
        views, screenings = study.screen(current, found)
        verdict, unexplained, notes, test = building_verdict(study, current, found, screenings)
        nominal.heldout_test = test
        notes = refusal_notes(None if refused is None else refused.report) + notes
        learned = None
        if verdict == Verdict.UNEXPLAINED and settings.learn_unexplained:
            current, learned = learned_step(
                study, current, found, (views, screenings), unexplained, self.run_dir
            )
        extended = extended_entry(current, found, bool(learned and learned["kept"]))
        gain = building_gain(nominal, current, extended is not None)
        account = BuildingDiagnosis(
            verdict,
            found,
            nominal,
            extended,
            [s.report for s in steps if s.report is not None],
            gain,
            unexplained,
            views,
            screenings,
            current.values,
            study.corner,
            notes,
            None
            if learned is None
            else {k: v for k, v in learned.items() if k not in ("system", "values", "heldout")},
        )
        return DiagnosisResult(
            self.record.name,
            "shear building",
            self.place,
            verdict,
            [Finding(f.effect, self.place, f.storey) for f in found],
            HeldoutErrors.of(gain),
            gain,
            notes,
            bool(settings.force_effect),
            account,
        )

    def details(self, result: DiagnosisResult) -> dict[str, Any]:
        return summarize_building(
            self.record, self.system, result.detail, self.fit, self.held, self.settings.thresholds
        )

    def sections(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        return report_lines(summary)

    def figures(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        return write_building_figures(self.run_dir, result.detail)
