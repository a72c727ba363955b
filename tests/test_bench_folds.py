"""The leave-events-out folds: every event predicted once, the same folds for the same seed (the
studies that look again at a fold must draw the one the study drew)."""

from pathlib import Path

from pidyn.bench.folds import event_name, folds


def test_every_event_is_in_one_fold_and_a_seed_draws_the_same_folds():
    rows = [{"event": f"e{i}"} for i in range(23)]
    parts = folds(rows, 5, seed=0)
    names = [r["event"] for part in parts for r in part]
    assert sorted(names) == sorted(r["event"] for r in rows)  # each once
    assert sorted(len(p) for p in parts) == [4, 4, 5, 5, 5]
    assert folds(rows, 5, seed=0) == parts
    assert folds(rows, 5, seed=1) != parts


def test_an_archive_is_named_by_its_event_without_the_station():
    assert event_name(Path("records/petrolia_25apr1992_ce89324p.zip")) == "petrolia_25apr1992"
    assert event_name(Path("records/58658_003_20211002_12.22.00.P.zip")) == "58658_003_20211002_12"
