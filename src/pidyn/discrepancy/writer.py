"""The one writer of a diagnosis's run folder: ``diagnosis.json``, ``report.md`` and the figures.

Every subject's report opens the same way, drawn from the typed result: the verdict in words,
what was found where (the place a column), the held-out errors beside knowing nothing's, the
notes. The subject adds its own sections (its evidence, its equations) and its figures after it.
"""

from __future__ import annotations

import logging
from typing import Any

from pidyn.discrepancy.loop import Subject
from pidyn.discrepancy.result import DiagnosisResult
from pidyn.discrepancy.verdicts import Verdict
from pidyn.reporting import write_json

log = logging.getLogger("pidyn.tasks.diagnose")

#: the verdict in words, whatever the structure
VERDICT_WORDS = {
    Verdict.NONE: "No candidate effect explains more of the residual than noise and the model's own error "
    "would. The nominal model is adequate for these data.",
    Verdict.UNEXPLAINED: "The nominal model is clearly wrong on these data, but no effect of the library (nor "
    "a change of stiffness or damping in time) explains what it misses. Look at the residual force "
    "before trusting this model.",
}


def write_diagnosis(subject: Subject, result: DiagnosisResult, wall_seconds: float) -> dict[str, Any]:
    """The run folder's files; the content of ``diagnosis.json``."""
    head = result.head()
    details = subject.details(result)
    summary = {**head, **{k: v for k, v in details.items() if k not in head}, "wall_seconds": wall_seconds}
    write_json(subject.run_dir / "diagnosis.json", summary)
    figures = subject.figures(result, summary)
    lines = head_lines(result, summary) + subject.sections(result, summary) + ["## Figures", ""]
    lines += [f"![{f}](figures/{f})" for f in figures]
    (subject.run_dir / "report.md").write_text("\n".join(lines) + "\n")
    log_verdict(result)
    return summary


def head_lines(result: DiagnosisResult, summary: dict[str, Any]) -> list[str]:
    """The title, the verdict, what was found where, the held-out errors, the notes and the split."""
    what = f" ({result.subject})" if result.place else ""
    lines = [f"# Diagnosis of `{result.record}`{what}", ""]
    if result.verdict == Verdict.DISCREPANCY:
        named = ", ".join(f"`{f.words()}`" for f in result.findings) or f"`{summary.get('cause')}`"
        by = " (named by the user, not by the screening)" if result.forced else ""
        lines += [
            f"**Verdict: discrepancy. Cause{'s' if len(result.findings) > 1 else ''}: {named}**{by}",
            "",
        ]
    else:
        lines += [f"**Verdict: {result.verdict}.** {VERDICT_WORDS[result.verdict]}", ""]
    if result.findings:
        lines += ["| effect | place |", "|---|---|"]
        lines += [
            f"| {f.effect} | {f'{f.place} {f.at}' if f.place else 'the structure'} |" for f in result.findings
        ]
        lines.append("")
    h = result.heldout
    lines += [f"| model | held-out NRMSE ({h.metric}) |", "|---|---|", f"| nominal | {h.nominal:.4g} |"]
    if h.extended is not None:
        lines.append(f"| extended | {h.extended:.4g} |")
    if h.trivial is not None:
        lines.append(f"| knowing nothing (the structure {h.trivial_label}) | {h.trivial:.4g} |")
    lines += [""] + [f"**Note:** {n}" for n in result.notes] + ([""] if result.notes else [])
    split = summary.get("split")
    if split:
        (f0, f1), (h0, h1) = split["fit"], split["heldout"]
        lines += [
            f"Fitting part {f0:.4g}-{f1:.4g} s; held-out part {h0:.4g}-{h1:.4g} s (not used for fitting).",
            "",
        ]
    return lines


def log_verdict(result: DiagnosisResult) -> None:
    """The verdict, where, and the held-out errors beside knowing nothing's, in the log."""
    h = result.heldout
    named = [f.words() for f in result.findings]
    log.info(
        "verdict: %s%s; held-out NRMSE (%s) nominal %.4g%s; knowing nothing (the structure %s) %.4g",
        result.verdict,
        f" ({', '.join(named)})" if named else "",
        h.metric,
        h.nominal,
        "" if h.extended is None else f", extended {h.extended:.4g}",
        h.trivial_label,
        h.trivial if h.trivial is not None else float("nan"),
    )
    if result.worse_than_trivial:
        log.warning("%s", result.worse_than_trivial)
