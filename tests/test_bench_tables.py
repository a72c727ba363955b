"""The studies' table cells: a missing or non-finite value reads the same in every table."""

from __future__ import annotations

import math

from pidyn.bench.tables import cell, interval, median, sweep_runs


def test_a_cell_says_missing_for_none_empty_and_non_finite():
    assert cell(0.12345) == "0.123" and cell(3, ".1f") == "3.0" and cell("0.5", ".2f") == "0.50"
    assert [cell(v) for v in (None, "", math.nan, math.inf)] == ["-"] * 4
    assert cell(None, missing="n/a") == "n/a"


def test_an_interval_needs_both_ends():
    assert interval([0.1, 0.25]) == "[0.100, 0.250]" and interval((1, 2), ".3g") == "[1, 2]"
    assert interval(None) == interval([None, 1.0]) == interval([0.1, math.nan]) == "-"


def test_the_median_of_the_known_values():
    assert median([3.0, None, 1.0, 2.0]) == 2.0 and median([1, 4]) == 2.5 and median([None]) is None


def test_a_sweeps_jobs_come_with_their_configs(tmp_path):
    for i, event in enumerate(("b", "a")):
        (tmp_path / str(i) / ".hydra").mkdir(parents=True)
        (tmp_path / str(i) / ".hydra" / "config.yaml").write_text(f"data:\n  event: {event}\n")
    runs = sweep_runs(tmp_path)
    assert [(cfg["data"]["event"], run.name) for cfg, run in runs] == [("b", "0"), ("a", "1")]
