"""The one writer of a diagnosis: every subject's result is the same type, and its head (the
verdict, what was found where, the held-out errors beside knowing nothing's) is written the same
way whatever the structure."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pidyn.discrepancy.loop import Subject
from pidyn.discrepancy.result import DiagnosisResult, Finding, HeldoutErrors, trivial_note
from pidyn.discrepancy.verdicts import Verdict
from pidyn.discrepancy.writer import write_diagnosis
from pidyn.notes import codes


class _Written(Subject):
    """A subject that only writes: its details, one section, no figure."""

    place = "support"
    takes_words = "a test"

    def __init__(self, run_dir: Path) -> None:
        self._run_dir = run_dir

    @classmethod
    def takes(cls, system):
        return False

    @classmethod
    def compose(cls, system, inputs):
        raise NotImplementedError

    @property
    def run_dir(self) -> Path:
        return self._run_dir

    def nominal(self):
        return None

    def more(self, found):
        return False

    def next_step(self, current, found):
        return None

    def conclude(self, current, found, steps, refused):
        raise NotImplementedError

    def details(self, result):
        return {"verdict": "overruled", "evidence": [1, 2], "split": {"fit": [0, 6.5], "heldout": [6.5, 10]}}

    def sections(self, result, summary):
        return ["## The subject's own", ""]

    def figures(self, result, summary):
        return []


def _gain(nominal: float, extended: float | None, trivial: float) -> dict:
    return {
        "metric": "heldout_nrmse_a",
        "nominal": nominal,
        "extended": extended,
        "trivial": trivial,
        "trivial_label": "moving with the ground",
        "nominal_beats_trivial": nominal < trivial,
    }


@pytest.mark.parametrize("place, at", [("", None), ("storey", 2), ("support", 1)])
def test_the_head_is_written_from_the_result_whatever_the_place(tmp_path, place, at):
    gain = _gain(0.4, 0.1, 1.0)
    result = DiagnosisResult(
        "rec",
        "thing",
        place,
        Verdict.DISCREPANCY,
        [Finding("cubic_stiffness", place, at)],
        HeldoutErrors.of(gain),
        gain,
    )
    d = write_diagnosis(_Written(tmp_path), result, 1.5)
    on_disk = json.loads((tmp_path / "diagnosis.json").read_text())
    assert on_disk == json.loads(json.dumps(d, default=str))
    assert on_disk["verdict"] == "discrepancy"  # the result's, not a subject's detail
    assert on_disk["findings"] == [{"effect": "cubic_stiffness", "place": place, "at": at}]
    assert on_disk["causes"] == ["cubic_stiffness"] and on_disk["evidence"] == [1, 2]
    assert on_disk["storeys"] == [at if place == "storey" else None]
    report = (tmp_path / "report.md").read_text()
    where = f"{place} {at}" if place else "the structure"
    assert f"| cubic_stiffness | {where} |" in report
    assert "| knowing nothing (the structure moving with the ground) | 1 |" in report
    assert report.index("**Verdict: discrepancy") < report.index("## The subject's own")


def test_a_model_worse_than_knowing_nothing_is_said_in_the_head(tmp_path):
    gain = _gain(1.3, None, 1.0)
    worse = trivial_note(gain)
    assert worse is not None and codes(worse) == {"worse_than_trivial"}
    result = DiagnosisResult(
        "rec", "thing", "", Verdict.UNEXPLAINED, [], HeldoutErrors.of(gain), gain, [worse]
    )
    d = write_diagnosis(_Written(tmp_path), result, 0.1)
    assert d["note_codes"] == ["worse_than_trivial"] and d["findings"] == []
    assert (
        "**Note:** the nominal model predicts the held-out part worse" in (tmp_path / "report.md").read_text()
    )
    assert trivial_note(_gain(0.5, None, 1.0)) is None


def test_every_subjects_result_says_when_its_nominal_model_is_worse_than_knowing_nothing():
    """The result adds the note itself, once, whichever subject made it."""
    gain = _gain(1.3, 1.1, 1.0)
    result = DiagnosisResult("rec", "thing", "storey", Verdict.NONE, [], HeldoutErrors.of(gain), gain)
    assert codes(result.notes) == {"worse_than_trivial"} and result.worse_than_trivial == result.notes[0]
    again = DiagnosisResult(
        "rec", "thing", "", Verdict.NONE, [], HeldoutErrors.of(gain), gain, list(result.notes)
    )
    assert again.notes == result.notes
    fine = _gain(0.4, None, 1.0)
    assert DiagnosisResult("rec", "thing", "", Verdict.NONE, [], HeldoutErrors.of(fine), fine).notes == []
