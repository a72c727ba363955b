"""What the diagnosis keeps of each extension step, typed: the step that named an effect (or was
refused), the evidence behind it and, for a single degree of freedom, the screening that follows.

The loop, the tie-breaks and the notes read fields; ``to_dict`` is the step's form in
``diagnosis.json``, and ``of`` reads that form back for the report of a finished run."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pidyn.discrepancy.evidence import Evidence

#: what each step keeps of the row that named its effect
ROW_EVIDENCE = ("score", "delta_bic", "explained", "cv_gain", "heldout_gain", "force_share", "source")
#: what each step keeps of the next screening's rows: the evidence behind the next name
STEP_EVIDENCE = (
    "effect",
    "score",
    "delta_bic",
    "explained",
    "cv_gain",
    "heldout_gain",
    "force_share",
    "passes",
    "persists",
    "heldout_miss",
    "heldout_small",
    "note",
    "parameters",
    "source",
)


@dataclass
class ExtensionStep:
    """Step ``step`` of a single degree of freedom: the effect added, its run folder and equation,
    the row that named it; then what the screening of the extended model found (``next_*``)."""

    step: int
    effect: str
    folder: str
    equation: str
    evidence: Evidence
    heldout_nrmse: dict[str, float] | None = None  # a learned force: without and with it
    next_ranking: list[Evidence] | None = None
    next_structure: dict[str, Any] | None = None
    next_verdict: Any = None  # a Verdict
    next_confirmation: list[Evidence] | None = None

    def to_dict(self) -> dict[str, Any]:
        evidence = {key: getattr(self.evidence, key) for key in ROW_EVIDENCE}
        if self.heldout_nrmse is not None:
            evidence["heldout_nrmse"] = self.heldout_nrmse
        out: dict[str, Any] = {
            "step": self.step,
            "effect": self.effect,
            "folder": self.folder,
            "equation": self.equation,
            "evidence": evidence,
        }
        if self.next_ranking is not None:
            out["next_ranking"] = [
                {k: v for k, v in r.to_dict().items() if k in STEP_EVIDENCE} for r in self.next_ranking
            ]
            out["next_structure"] = self.next_structure
            out["next_verdict"] = self.next_verdict
        if self.next_confirmation is not None:
            out["next_confirmation"] = [r.to_dict() for r in self.next_confirmation]
        return out


@dataclass
class LearnedRefusal:
    """A learned force that predicts the held-out part worse than the model it extends: not kept."""

    effect: str
    folder: str
    heldout_nrmse: dict[str, float]
    note: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "folder": self.folder,
            "heldout_nrmse": self.heldout_nrmse,
            "note": self.note,
        }


@dataclass
class Rival:
    """The close rival a storey's named effect was chosen over (or lost to), on the fitting part."""

    effect: str
    fit_bic: float
    n_params: int
    heldout_after: float

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class StoreyStep:
    """A building's step: an effect in a storey, extended and refined, with its fitting-part BIC and
    the held-out floor accelerations before and after; named (``accepted``) or refused."""

    effect: str
    storey: int
    score: float | None
    cv_gain: float | None
    screening_parameters: dict[str, Any]
    parameters: dict[str, float]
    intervals: dict[str, Any]
    source: str
    fit_bic: float
    n_params: int
    heldout_before: float
    heldout_after: float
    accepted: bool
    size_rel_std: float | None = None  # refused: its size is not determined
    delta_bic_fit: float | None = None  # the fitting part's BIC gain over the model it extends
    misfit_explained: float | None = None  # the share of the fit test's excess it removes
    rival: Rival | None = None
    extra: dict[str, Any] = field(default_factory=dict)  # fields of a report read back, kept as they were

    def versus(self) -> Rival:
        return Rival(self.effect, self.fit_bic, self.n_params, self.heldout_after)

    def outcome(self) -> str:
        """The step's end for people (the log and the report): named, or which rule refused it."""
        if self.accepted:
            return "named"
        if self.size_rel_std is not None:
            return f"refused: its size is not determined (std {100 * self.size_rel_std:.0f} % of it)"
        return "refused: no held-out gain"

    def to_dict(self) -> dict[str, Any]:
        out = {k: v for k, v in self.__dict__.items() if k not in ("rival", "extra")}
        for key in ("size_rel_std", "delta_bic_fit", "misfit_explained"):
            if out[key] is None:
                del out[key]
        if self.rival is not None:
            out["rival"] = self.rival.to_dict()
        return {**out, **self.extra}

    @classmethod
    def of(cls, d: dict[str, Any]) -> StoreyStep:
        """A step from its form in ``diagnosis.json``."""
        known = set(cls.__dataclass_fields__) - {"rival", "extra"}
        rival = d.get("rival")
        return cls(
            **{k: d.get(k) for k in known if k != "extra"},
            rival=None if rival is None else Rival(**rival),
            extra={k: v for k, v in d.items() if k not in known and k != "rival"},
        )
