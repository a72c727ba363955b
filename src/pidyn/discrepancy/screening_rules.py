"""The screening's thresholds and the rules its verdict follows: the effect that passes every
test, a step in time that fits one fold only or misses the held-out part, a tie the record does not
decide, and a structure no library effect explains."""

from __future__ import annotations

from dataclasses import dataclass

from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.verdicts import Verdict


@dataclass
class Thresholds:
    """When an effect counts as found (defaults calibrated on clean and 5 %-noise data)."""

    min_delta_bic: float = 10.0  # "very strong" evidence on Kass & Raftery's scale
    min_cv_gain: float = 0.05  # blocked cross-validation's share of the force residual removed
    min_force_share: float = 1e-6  # of the force's total sum of squares
    min_structure_gain: float = (
        0.3  # a generic f(x, x') removing this share (CV) marks the residual as structured
    )
    min_library_share: float = 0.5  # the named effect must explain this share of what the generic one does
    pair_margin: float = (
        2.0  # BIC by which a pair must beat the pairs holding the best single effect ("positive")
    )
    #: a step in time found in the fitting part must persist: its held-out gain may not fall below this
    min_step_heldout_gain: float = -0.1
    #: an effect that makes the held-out prediction worse than this, where a generic f(x, x')
    #: improves it by min_structure_gain, is refused (the held-out part has structure it misses)
    min_heldout_gain: float = 0.0
    #: ... and an effect that predicts less than this share of what that generic f(x, x') predicts
    #: there explains none of the held-out structure: it is not named (pairs are not refused by it:
    #: the second effect of a pair may predict little alone)
    min_heldout_share: float = 0.1
    #: a library name is kept only when the extended model's held-out error is at least this share
    #: below the nominal model's (else the verdict is ``unexplained``)
    min_name_gain: float = 0.05
    #: between passing effects this close in BIC (below "strong", 6, on Kass & Raftery's
    #: scale) the one with the clearly better blocked cross-validation gain is named
    tie_delta_bic: float = 6.0
    tie_cv_margin: float = 0.1  # ... when one's CV gain is higher by this

    def step_persists(self, heldout_gain: float | None) -> bool:
        """A step in time lasts into the rows no fit used (no rows: nothing to refute it)."""
        return heldout_gain is None or heldout_gain >= self.min_step_heldout_gain


def _verdict(ranking: list[Evidence], structure: dict, th: Thresholds) -> tuple[Verdict, str | None]:
    """``discrepancy`` when the top effect passes and explains a fair share of what a generic
    f(x, x') explains; ``unexplained`` when the residual is structured but no effect does;
    else ``none``. Marks ``structure['structured']`` (and a note when the top effect is refused)."""
    top = ranking[0] if ranking else None
    structured = structure["cv_gain"] >= th.min_structure_gain  # blocked CV: flexibility is not rewarded
    structure["structured"] = bool(structured)
    pair = structure.get("pair")
    if pair is not None:  # two effects explain it together: name the pair's lead first
        return Verdict.DISCREPANCY, pair["lead"]
    found = top is not None and _passes(top, th)
    if found and structured and top.cv_gain < th.min_library_share * structure["cv_gain"]:
        # the best library effect explains only a small part of a clearly structured residual:
        # naming it would be naming the wrong thing
        structure["note"] = (
            f"{top.effect} passes but explains {top.cv_gain:.2f} of the residual in "
            f"cross-validation against {structure['cv_gain']:.2f} for a generic f(x, x')"
        )
        found = False
    if found:
        rival = _tie_break(ranking, th)
        if rival is not None:
            structure["tie_break"] = (
                f"{rival.effect} (score {rival.score:.1f}, cross-validation gain "
                f"{rival.cv_gain:.2f}) named before {top.effect} ({top.score:.1f}, "
                f"{top.cv_gain:.2f}): BIC does not decide between them, "
                "cross-validation does"
            )
            return Verdict.DISCREPANCY, rival.effect
        return Verdict.DISCREPANCY, top.effect
    return (Verdict.UNEXPLAINED if structured else Verdict.NONE), None


def _mark_fleeting_step(r: Evidence, th: Thresholds) -> None:
    """Mark a step in time that does not last (``persists: False``, with a note): a stiffness
    lower only in the strong motion is one that depends on the amplitude (softening), not damage."""
    if r.step_in_time and not th.step_persists(r.heldout_gain):
        r.persists = False
        r.note = (
            f"a step at t = {r.parameters.get('t_d', float('nan')):.2f} s that does not persist: "
            f"held-out gain {r.heldout_gain:.2f}"
        )


def _mark_heldout_miss(r: Evidence, structure: dict, th: Thresholds) -> None:
    """Mark an effect (not a step in time: ``_mark_fleeting_step`` rules those) that predicts the
    held-out part worse than the nominal model does, where a generic f(x, x') predicts it
    clearly better: the effect fits the fitting part's force by a shape the structure does not
    have (an even spring standing in for a trilinear one under a one-sided pulse). Mark it as
    ``heldout_small`` when it predicts less than ``min_heldout_share`` of what the generic force
    predicts there: a quadratic spring fitted to a symmetric trilinear one gains 0.01 where the
    generic force gains 0.77."""
    ho, generic = r.heldout_gain, structure.get("heldout_gain")
    if r.step_in_time or r.score is None or ho is None or generic is None:
        return
    if generic < th.min_structure_gain:
        return
    if ho < th.min_heldout_gain:
        r.heldout_miss = True
        r.note = (
            f"held-out gain {ho:.2f} against {generic:.2f} for a generic f(x, x'): "
            "it does not predict the rows no fit used"
        )
    elif ho < th.min_heldout_share * generic:
        r.heldout_small = True
        r.note = (
            f"held-out gain {ho:.2f} against {generic:.2f} for a generic f(x, x'): "
            "it explains almost none of the structure in the rows no fit used"
        )


def _tie_break(ranking: list[Evidence], th: Thresholds) -> Evidence | None:
    """The passing effect to name instead of the top one, when BIC does not decide between them
    (within ``tie_delta_bic``) and blocked cross-validation clearly does; None: the top one."""
    passing = [r for r in ranking if r.passes]
    if len(passing) < 2 or passing[0] is not ranking[0]:
        return None
    top = passing[0]
    rivals = [
        r
        for r in passing[1:]
        if top.score - r.score < th.tie_delta_bic and r.cv_gain - top.cv_gain >= th.tie_cv_margin
    ]
    return max(rivals, key=lambda r: r.cv_gain) if rivals else None


def _passes(r: Evidence, th: Thresholds) -> bool:
    if r.score is None or r.persists is False or r.heldout_miss or r.heldout_small:
        return False
    return (
        r.delta_bic <= -th.min_delta_bic
        and r.force_share >= th.min_force_share
        and r.cv_gain >= th.min_cv_gain
    )
