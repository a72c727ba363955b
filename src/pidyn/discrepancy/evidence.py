"""One effect's evidence, typed: what the screening, the output-error check and the located
change say of a candidate cause, and what an extension step starts from.

A row of the weak-form screening (``source`` "weak_form"), a candidate or result of the
output-error check ("output_error"), a change located in time (``change``) and the generic
yardstick a learned force starts from are all this one type, so that the steps that rank, refuse,
tie-break and extend read fields, not keys. ``to_dict`` is its form in ``diagnosis.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any


@dataclass
class Evidence:
    """One candidate cause's evidence (see the module's docstring)."""

    effect: str
    score: float | None = None  # -dBIC against the model it extends (None: no physical fit, or not scored)
    delta_bic: float | None = None
    explained: float | None = None  # share of the residual (force, or simulated channels) it removes
    force_share: float | None = None  # of the force's total sum of squares
    cv_gain: float | None = None  # blocked cross-validation's share of the residual removed
    heldout_gain: float | None = None  # ... on the rows no fit used (None: no such rows)
    parameters: dict[str, Any] = field(default_factory=dict)  # the effect's estimate
    nominal_refit: dict[str, float] = field(default_factory=dict)  # the nominal parameters fitted beside it
    step_in_time: bool = False
    passes: bool = False  # passes the screening's (or the check's) thresholds
    persists: bool | None = None  # a step in time: lasts into the held-out rows (None: not judged)
    heldout_miss: bool = False  # predicts the held-out part worse where a generic force predicts it better
    heldout_small: bool = False  # ... or less than a share of what the generic force predicts there
    note: str | None = None  # why a rule refused it
    spring_share: float | None = None  # a storey's spring kept beside it, as a share of its own law's
    source: str = "weak_form"  # weak_form | output_error | change | learned
    weak_form_score: float | None = None  # the output-error check's candidate: its screening score
    independent_samples: float | None = None
    rivals: list[Evidence] | None = None  # the check's passing effects it cannot be told from
    located: dict[str, Any] | None = None  # a change located in time: where the weak form put it
    change: Any = None  # the located change itself (``changes.Change``): its time is held when extended
    seconds: float | None = None  # the output-error check's fit
    nfev: int | None = None
    error: str | None = None  # the check's fit failed: why

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: the effect, its score and whether it passes, and every field set."""
        out: dict[str, Any] = {"effect": self.effect, "score": self.score, "passes": self.passes}
        for f in fields(self):
            value = getattr(self, f.name)
            if (
                f.name in out
                or value is None
                or value is False
                or (f.name in ("parameters", "nominal_refit") and not value)
            ):
                continue
            if f.name == "source" and value == "weak_form":
                continue
            if f.name == "rivals":
                value = [r.to_dict() for r in value]
            elif f.name == "change":
                value = value.to_dict()
            out[f.name] = value
        return out
