"""What every diagnosis concludes, whatever the structure: one typed result.

The loop's subjects (``pidyn.discrepancy.subjects``) each keep their own account of how they got
there (``detail``: the single degree of freedom's ``Outcome``, the building's
``BuildingDiagnosis``); what they conclude is this one type. The place of a finding is a column
(``Finding.place``: "" for the structure itself, "storey", ...), so a reader of the result, the
writer of ``diagnosis.json`` and ``report.md`` among them, never branches on the structure.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from pidyn.discrepancy.verdicts import Verdict
from pidyn.notes import code_of, note


@dataclass(frozen=True)
class Finding:
    """One named cause and where it sits."""

    effect: str
    place: str = ""  # the subject's place: "" (the structure itself), "storey", ...
    at: int | None = None  # which one (a storey's number); None for the structure itself

    def words(self) -> str:
        return (
            f"{self.effect} in {self.place} {self.at}" if self.place and self.at is not None else self.effect
        )


@dataclass
class HeldoutErrors:
    """The held-out prediction errors that judge the models: the nominal model's, the extended
    model's (None when nothing was added) and knowing nothing's (the structure at rest, or moving
    with the ground), in ``metric``."""

    metric: str
    nominal: float
    extended: float | None
    trivial: float | None
    trivial_label: str

    @classmethod
    def of(cls, gain: dict[str, Any]) -> HeldoutErrors:
        """From a subject's held-out record (``diagnosis.json``'s ``gain``)."""
        return cls(
            str(gain["metric"]),
            float(gain["nominal"]),
            None if gain.get("extended") is None else float(gain["extended"]),
            None if gain.get("trivial") is None else float(gain["trivial"]),
            str(gain.get("trivial_label", "at rest")),
        )


@dataclass
class DiagnosisResult:
    """The verdict, what was found where, the held-out errors, the coded notes; ``detail`` is the
    subject's own account, which its sections of the report and its figures are drawn from."""

    record: str
    subject: str  # the kind of structure, as the subject names itself
    place: str
    verdict: Verdict
    findings: list[Finding]
    heldout: HeldoutErrors
    gain: dict[str, Any]  # the subject's full held-out record (per channel, against the clean truth ...)
    notes: list[str] = field(default_factory=list)  # coded notes (``pidyn.notes``)
    forced: bool = False  # the cause was named by the user (diagnosis.force_effect), not the screening
    detail: Any = None

    def __post_init__(self) -> None:
        # whatever the subject: a nominal model that predicts worse than knowing nothing is said so
        worse = trivial_note(self.gain)
        if worse is not None and worse not in self.notes:
            self.notes = [worse, *self.notes]

    @property
    def worse_than_trivial(self) -> str | None:
        """The note that the nominal model predicts worse than knowing nothing, or None."""
        return next((n for n in self.notes if code_of(n) == "worse_than_trivial"), None)

    def head(self) -> dict[str, Any]:
        """The part of ``diagnosis.json`` every subject writes the same way."""
        return {
            "record": self.record,
            "subject": self.subject,
            "place": self.place,
            "verdict": self.verdict,
            "findings": [asdict(f) for f in self.findings],
            "causes": [f.effect for f in self.findings],
            "storeys": [f.at if f.place == "storey" else None for f in self.findings],
            "gain": self.gain,
            "notes": list(self.notes),
            "note_codes": [c for n in self.notes if (c := code_of(n))],
            "forced": self.forced,
        }


def trivial_note(gain: dict[str, Any]) -> str | None:
    """Says so when the nominal model predicts the held-out part no better than knowing nothing."""
    if gain.get("nominal_beats_trivial") is not False:
        return None
    return note(
        "worse_than_trivial",
        f"the nominal model predicts the held-out part worse than knowing nothing (NRMSE {gain['nominal']:.4g} "
        f"against {gain['trivial']:.4g}, the structure {gain['trivial_label']}): it does not hold there, "
        "whatever the checks on the fitting part say",
    )
