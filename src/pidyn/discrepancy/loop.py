"""The diagnosis loop, one for every kind of structure.

What does the nominal model get wrong, where, and what does fixing it gain? Whatever the
structure, the diagnosis runs the same steps:

1. the nominal model, identified on the fitting part (``Subject.nominal``);
2. while the subject wants more (``Subject.more``): screen the current model, choose the next
   cause and its place, extend the model with it, identify and judge the extension
   (``Subject.next_step``). An accepted step becomes the current model; a refused one ends
   the loop and is reported;
3. the verdict, the fallbacks (a learned force where the library names nothing that earns its
   place) and the held-out gain (``Subject.conclude``): one typed result for every subject
   (``pidyn.discrepancy.result.DiagnosisResult``, the place a column);
4. ``diagnosis.json``, ``report.md`` and the figures, by one writer (``pidyn.discrepancy.writer``):
   the same head for every subject, then the subject's ``details``, ``sections`` and ``figures``.

A *subject* is a kind of structure with the places a cause can sit at: a single degree of
freedom (the structure itself), a shear building (its storeys). It says how the record is seen,
how the model is screened, extended, fitted and judged. The subjects live one file each in
``pidyn.discrepancy.subjects`` and are found there (``subject_for``); adding a structure to the
diagnosis is adding its file.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pidyn.data.sources import Record
from pidyn.discrepancy.result import DiagnosisResult
from pidyn.discrepancy.settings import DiagnosisSettings

#: identify(record, config node, run folder, fitting span) -> (metrics, system, values): one
#: identification of the model a config node describes (PIDynNet; the task layer gives it)
Identify = Callable[[Record, dict, Path, tuple[float, float]], tuple[dict, Any, dict[str, float]]]


@dataclass
class Inputs:
    """What a subject is composed from: the settings, the nominal system's config, the record (or
    how to read it) and the services of the layer above (an identification, the refinement's
    settings, an earlier run to start from)."""

    settings: DiagnosisSettings
    system_node: dict
    make_system: Callable[..., Any]  # the config's system, with keyword overrides (excitation, inputs)
    read_record: Callable[[Any], Record]  # the config's data for a system
    record: Record | None  # given by the caller, else read
    mass: float | None
    run_dir: Path
    identify: Identify
    refine_settings: Callable[[], Any]  # the refinement's settings (None when model.refine=none)
    start: str  # model.start: auto, data, config or an earlier run's folder

    def the_record(self, system: Any) -> Record:
        return self.read_record(system) if self.record is None else self.record


@dataclass
class Step:
    """One extension step as the loop sees it: accepted or refused, the model it leads to, what
    it named and where (the subject's own record of it), and what ``diagnosis.json`` keeps."""

    accepted: bool
    current: Any
    found: Any
    report: Any  # the subject's typed account of the step (pidyn.discrepancy.step_reports); None: none


class Subject(ABC):
    """A kind of structure the diagnosis loop runs on (see the module's docstring)."""

    #: where a cause sits, as ``diagnosis.json`` names it: "" (the structure itself), "storey", ...
    place: str = ""
    #: in words, for the refusal of a structure no subject takes
    takes_words: str = ""

    @classmethod
    @abstractmethod
    def takes(cls, system: Any) -> bool:
        """Whether this subject diagnoses ``system``."""

    @classmethod
    @abstractmethod
    def compose(cls, system: Any, inputs: Inputs) -> Subject:
        """The subject of one diagnosis: the record read and checked, the spans split."""

    @property
    @abstractmethod
    def run_dir(self) -> Path:
        """The diagnosis's run folder."""

    @abstractmethod
    def nominal(self) -> Any:
        """The nominal model identified: the loop's first current model."""

    @abstractmethod
    def more(self, found: list) -> bool:
        """Whether to look for another cause, with ``found`` named so far."""

    @abstractmethod
    def next_step(self, current: Any, found: list) -> Step | None:
        """The current model screened, the next cause chosen, the model extended and judged;
        None when there is nothing to try."""

    @abstractmethod
    def conclude(self, current: Any, found: list, steps: list[Step], refused: Step | None) -> DiagnosisResult:
        """The verdict, what was found where, the held-out errors; the subject's account as its detail."""

    @abstractmethod
    def details(self, result: DiagnosisResult) -> dict[str, Any]:
        """What ``diagnosis.json`` holds beyond the result's head (the subject's evidence)."""

    @abstractmethod
    def sections(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        """The subject's sections of ``report.md``, after the common head."""

    @abstractmethod
    def figures(self, result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
        """The figures drawn into ``figures/`` of the run folder; their file names."""


def extend(subject: Subject, current: Any) -> tuple[Any, list, list[Step], Step | None]:
    """Step 2 of the loop from ``current``: (the last accepted model, what was found, every step,
    the refused step or None)."""
    found: list = []
    steps: list[Step] = []
    refused = None
    while subject.more(found):
        step = subject.next_step(current, found)
        if step is None:
            break
        steps.append(step)
        if not step.accepted:
            refused = step
            break
        found.append(step.found)
        current = step.current
    return current, found, steps, refused


def diagnose(subject: Subject) -> DiagnosisResult:
    """Steps 1-3 of the loop; the result."""
    current = subject.nominal()
    current, found, steps, refused = extend(subject, current)
    return subject.conclude(current, found, steps, refused)
