"""The diagnosis benchmark's bookkeeping: the table is rewritten after every case, and a
later run keeps the committed table's finished cases (same hidden kind, code stamped)."""

import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
import discrepancy_bench as bench  # noqa: E402


def _fake_case(calls: list[int]):
    def run_case(i, out, extra, kinds):
        calls.append(i)
        kind = kinds[i % len(kinds)]
        found = "+".join(sorted(kind.expect)) or "none"
        return {
            "case": i,
            "hidden": kind.label,
            "found": found,
            "verdict": "discrepancy" if kind.expect else "none",
            "hit": True,
            "record": "kobe",
            "noise": 0.01,
            "seconds": 10.0 + i,
            "nrmse_nominal": 1.0,
            "nrmse_extended": 0.1,
            "top_score": 0.9,
        }

    return run_case


def test_partial_table_and_resume(tmp_path, monkeypatch):
    res = tmp_path / "results"
    calls: list[int] = []
    monkeypatch.setattr(bench, "run_case", _fake_case(calls))
    monkeypatch.setattr(
        sys,
        "argv",
        ["bench", "--cases", "5", "--jobs", "1", "--results", str(res), "--out", str(tmp_path / "out")],
    )
    bench.main()
    assert sorted(calls) == [0, 1, 2, 3, 4]
    df = pd.read_csv(res / "discrepancy_bench.csv")
    assert list(df.case) == [0, 1, 2, 3, 4] and df.commit.notna().all()
    # a corrupted row (another kind than case 3 hides now) and a failed one are run again
    df.loc[df.case == 3, "hidden"] = "not_a_kind"
    df["error"] = None
    df.loc[df.case == 1, "error"] = "Traceback: boom"
    df.to_csv(res / "discrepancy_bench.csv", index=False)
    calls.clear()
    monkeypatch.setattr(
        sys,
        "argv",
        ["bench", "--cases", "7", "--jobs", "1", "--results", str(res), "--out", str(tmp_path / "out")],
    )
    bench.main()
    assert sorted(calls) == [1, 3, 5, 6]
    md = (res / "discrepancy_bench.md").read_text()
    assert "7 seeded cases" in md and "planned" not in md.split("\n")[2]
    assert sorted(pd.read_csv(res / "discrepancy_bench.csv").case) == list(range(7))


def test_interrupted_table_says_how_far(tmp_path):
    rows = [
        {
            "case": 0,
            "hidden": "none",
            "found": "none",
            "verdict": "none",
            "hit": True,
            "record": "kobe",
            "noise": 0.0,
            "seconds": 5.0,
            "nrmse_nominal": 0.1,
            "nrmse_extended": 0.1,
            "top_score": 0.1,
            "commit": "abc1234",
        }
    ]
    lines = bench.write_results(rows, 90, "short", tmp_path)
    assert "(1 of the 90 planned cases finished; the rest resume)" in lines[2]
    assert "abc1234" in "\n".join(lines)


def test_a_named_study_writes_its_own_table(tmp_path, monkeypatch):
    res = tmp_path / "results"
    monkeypatch.setattr(bench, "run_case", _fake_case([]))
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "bench",
            "--cases",
            "2",
            "--jobs",
            "1",
            "--results",
            str(res),
            "--out",
            str(tmp_path / "out"),
            "--name",
            "timing",
            "--kinds",
            "none",
            "hysteresis",
            "data.source.duration=40",
        ],
    )
    bench.main()
    assert sorted(p.name for p in res.iterdir()) == ["timing.csv", "timing.json", "timing.md"]
    md = (res / "timing.md").read_text()
    assert "--name timing" in md and "data.source.duration=40" in md
    assert set(pd.read_csv(res / "timing.csv").hidden) == {"none", "hysteresis"}


def test_a_hash_that_reads_as_a_number_stays_a_hash(tmp_path):
    """61e7462 is a float to pandas (infinity): the kept rows must carry the hash as written."""
    kinds = bench.KINDS
    path = tmp_path / "t.csv"
    pd.DataFrame(
        [
            {
                "case": 0,
                "hidden": kinds[0].label,
                "found": "none",
                "verdict": "none",
                "hit": True,
                "seconds": 1.0,
                "commit": "61e7462",
            }
        ]
    ).to_csv(path, index=False)
    assert bench.committed_rows(path, kinds)[0]["commit"] == "61e7462"


def test_a_study_of_later_seeds_runs_only_those(tmp_path, monkeypatch):
    """``--first 180 --cases 183 --name ...``: the cases (seeds) the benchmark's table does not use."""
    res = tmp_path / "results"
    calls: list[int] = []
    monkeypatch.setattr(bench, "run_case", _fake_case(calls))
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "bench",
            "--first",
            "180",
            "--cases",
            "183",
            "--jobs",
            "1",
            "--results",
            str(res),
            "--out",
            str(tmp_path / "out"),
            "--name",
            "later",
        ],
    )
    bench.main()
    assert sorted(calls) == [180, 181, 182]
    df = pd.read_csv(res / "later.csv")
    assert list(df.case) == [180, 181, 182]
    assert "3 seeded cases" in (res / "later.md").read_text()
    assert not (res / "discrepancy_bench.csv").exists()
