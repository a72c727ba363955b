"""A bridge deck on its supports as a subject of the diagnosis loop: a cause sits at a support.
Every deck channel reads what all the supports do together, so each (effect, support) is scored
by what it would change in the channels (``pidyn.discrepancy.deck_steps``), tried by output error
in that order, and named only when it predicts the held-out part better. Where two supports'
candidates change the channels alike, the report says the data cannot tell them apart."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.data.checks import check_record
from pidyn.data.sources import Record
from pidyn.discrepancy.case import split_spans
from pidyn.discrepancy.deck_model import DeckDiagnosis, DeckState, Placed, channels
from pidyn.discrepancy.deck_report import deck_notes, deck_sections, deck_summary, write_deck_figures
from pidyn.discrepancy.deck_steps import (
    alike,
    choose,
    deck_fit_test,
    fit_mask,
    nominal_deck,
    score_candidates,
    support_effects,
    try_candidate,
)
from pidyn.discrepancy.effects import EFFECTS
from pidyn.discrepancy.loop import Inputs, Step, Subject
from pidyn.discrepancy.result import DiagnosisResult, Finding, HeldoutErrors
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.verdicts import Verdict
from pidyn.progress import Steps
from pidyn.systems.deck import RigidDeck

log = logging.getLogger(__name__)


@dataclass
class DeckStudy:
    """What every step of a deck's diagnosis reads: the record and its split, the nominal deck,
    the settings and the effects tried at each support."""

    record: Record
    system: RigidDeck
    settings: DiagnosisSettings
    refine_settings: Any
    fit: tuple[float, float]
    held: tuple[float, float]
    effects: list[str]
    #: each deck channel's noise (its units), read by the nominal deck's fit test
    noise: dict[str, float] = field(default_factory=dict)


class Deck(Subject):
    """The nominal deck refined; each step scores every (effect, support) and tries the best few
    (``diagnosis.confirm.misfit_candidates``) by output error, the first that predicts the
    held-out channels better named. Nothing named: ``none`` where the nominal deck fits its
    fitting part down to the sensors' noise, ``unexplained`` where it does not."""

    place = "support"
    takes_words = "a bridge deck on its supports"

    def __init__(self, study: DeckStudy, run_dir: Path) -> None:
        self.study, self._run_dir = study, run_dir
        self.progress = Steps(
            "deck diagnosis", int(study.settings.max_effects) * bool(study.settings.extend) + 2, log
        )
        self.steps: list[dict] = []
        self.ranking: list[dict] = []
        self.alike: list[dict] = []

    @classmethod
    def takes(cls, system: Any) -> bool:
        return isinstance(system, RigidDeck)

    @classmethod
    def compose(cls, system: Any, inputs: Inputs) -> Deck:
        record = inputs.the_record(system)
        check_record(record)
        channels(record)  # a named refusal for a record without a sensor layout
        missing = [n for n in system.inputs if n not in (record.inputs or ())]
        if missing:
            raise ValueError(
                f"record '{record.name}': no ground motion for support(s) {missing} of the deck (supports "
                f"{list(system.inputs)}); a support whose motion was not measured cannot be driven: diagnose an "
                "event with every support's channel"
            )
        refine = inputs.refine_settings()
        if refine is None:
            raise ValueError(
                "diagnose: a deck's diagnosis refines every model; model.refine=none is not possible"
            )
        settings = inputs.settings
        effects = list(settings.effects or support_effects())
        unknown = [e for e in effects if e not in EFFECTS]
        if unknown:
            raise ValueError(f"diagnosis.effects: unknown effect(s) {unknown}; choose from {sorted(EFFECTS)}")
        fit, held = split_spans(record, float(settings.fit_share))
        inputs.run_dir.mkdir(parents=True, exist_ok=True)
        study = DeckStudy(record, system, settings, replace(refine, states="integrated"), fit, held, effects)
        return cls(study, inputs.run_dir)

    @property
    def run_dir(self) -> Path:
        return self._run_dir

    def nominal(self) -> DeckState:
        s = self.study
        log.info(
            "deck diagnosis of '%s': fit %.4g-%.4g s, held out %.4g-%.4g s", s.record.name, *s.fit, *s.held
        )
        self.progress.step("the nominal deck")
        self.nominal_state, self.nominal_report = nominal_deck(s)
        fitted = self.nominal_report["fit_test"]["channels"]
        meas, _, names = channels(s.record)
        m = fit_mask(s.record, s.fit)
        s.noise = {
            n: float(fitted[n]["noise"]) * float(np.std(meas[m, i]))
            for i, n in enumerate(names)
            if fitted.get(n, {}).get("noise") is not None
        }
        return self.nominal_state

    def more(self, found: list) -> bool:
        return len(found) < int(self.study.settings.max_effects) and bool(self.study.settings.extend)

    def next_step(self, current: DeckState, found: list) -> Step | None:
        """The current deck's fit test first: a deck that fits its fitting part down to the noise
        has nothing left to name. Else every (effect, support) scored, the best few refined, and
        the one that fits best among those that earn their name on the held-out part named."""
        study = self.study
        test = (
            self.nominal_report["fit_test"]
            if not found
            else deck_fit_test(study, current.system, current.values)
        )
        if not test["failed"]:
            log.info(
                "the %s deck fits its fitting part down to the noise: nothing more to name",
                "nominal" if not found else "extended",
            )
            return None
        self.progress.step(f"scoring every effect at every support for effect {len(found) + 1}")
        scored = score_candidates(study, current, found)
        self.ranking = [c.row() for c in scored]
        if not scored:
            return None
        log.info("scores: %s", ", ".join(f"{c.effect}@{c.support} {c.share:.3g}" for c in scored[:5]))
        tried = [
            (c, *try_candidate(study, current, found, c))
            for c in scored[: int(study.settings.confirm.misfit_candidates)]
        ]
        self.steps += [t[2] for t in tried]
        best = choose(tried)
        if best is None:
            return Step(False, current, None, [t[2] for t in tried])
        cand, state, report = best
        self.alike += alike(scored, cand)
        return Step(
            True, state, Placed(cand.effect, cand.support, _own_names(cand, report), cand.ctx), report
        )

    def conclude(
        self, current: DeckState, found: list, steps: list[Step], refused: Step | None
    ) -> DiagnosisResult:
        self.progress.step("the verdict", last=True)
        fit_failed = bool(self.nominal_report["fit_test"]["failed"])
        verdict = Verdict.DISCREPANCY if found else (Verdict.UNEXPLAINED if fit_failed else Verdict.NONE)
        detail = DeckDiagnosis(
            verdict,
            list(found),
            self.nominal_report,
            current,
            self.nominal_state,
            self.steps,
            self.ranking,
            self.alike,
        )
        detail.notes = deck_notes(self.study, detail)
        gain = _gain(self.nominal_state, current if found else None)
        return DiagnosisResult(
            self.study.record.name,
            "bridge deck",
            self.place,
            verdict,
            [Finding(f.effect, self.place, f.support) for f in found],
            HeldoutErrors.of(gain),
            gain,
            detail.notes,
            False,
            detail,
        )

    def details(self, result: DiagnosisResult) -> dict[str, Any]:
        return deck_summary(self.study, result.detail)

    def sections(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        return deck_sections(summary)

    def figures(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        return write_deck_figures(self.run_dir, self.study, result.detail)


def _own_names(cand, report: dict) -> dict[str, float]:
    """The refined effect's parameters in the effect's own names (``kh``, not ``kh2``)."""
    term = EFFECTS[cand.effect].term(cand.params, cand.ctx)
    own = {}
    for s in term.specs():
        for full, v in report["parameters"].items():
            if full in (f"{s.name}{cand.support}", f"{s.name}_{cand.support}"):
                own[s.name] = v
    return {**cand.params, **own}


def _gain(nominal: DeckState, extended: DeckState | None) -> dict[str, Any]:
    """The held-out record: the mean NRMSE of the deck channels, per channel, against the deck
    moving with a support."""
    h = nominal.heldout
    return {
        "metric": "nrmse_a (deck channels, absolute)",
        "nominal": h.mean,
        "extended": None if extended is None else extended.heldout.mean,
        "trivial": h.trivial,
        "trivial_label": h.trivial_label,
        "nominal_beats_trivial": bool(h.mean < h.trivial),
        "per_channel": {
            "nominal": h.per_channel,
            "extended": None if extended is None else extended.heldout.per_channel,
            "trivial": h.trivial_per_channel,
        },
    }
