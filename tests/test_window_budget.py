"""PIDynNet's window budget: a total, and a share per record, so that one record's budget can be
small while a run from several records still takes windows from each."""

from __future__ import annotations

import pytest

from pidyn.config import compose
from pidyn.models.schedule import Schedule


def test_the_window_limit_is_the_smaller_of_the_total_and_the_records_share():
    assert Schedule().window_limit(3) is None
    assert Schedule(max_windows=8).window_limit(17) == 8
    assert Schedule(max_windows=8, windows_per_record=2).window_limit(1) == 2
    assert Schedule(max_windows=8, windows_per_record=2).window_limit(3) == 6
    assert Schedule(max_windows=8, windows_per_record=2).window_limit(17) == 8
    assert Schedule(windows_per_record=1).window_limit(0) == 1
    with pytest.raises(ValueError, match="windows_per_record must be >= 1"):
        Schedule(windows_per_record=0)


def test_a_strong_motion_records_budget_is_two_windows_in_its_identification_and_its_diagnosis():
    train = compose("train", groups={"data": "csmip"}).model.schedule
    assert (train.max_windows, train.windows_per_record) == (8, 2)
    diagnose = compose("diagnose", groups={"data": "csmip"}).model.schedule
    assert (diagnose.max_windows, diagnose.windows_per_record) == (8, 2)
    # the diagnosis's shorter windows (diagnose.yaml), two of them a record, in both
    for schedule in (train, diagnose):
        assert (schedule.pretrain_iters, schedule.pretrain_iters_window, schedule.max_iters) == (
            300,
            300,
            500,
        )
    # a simulated record keeps train.py's full schedule, and so does a run from several strong-motion
    # records (the leave-events-out studies were made with it)
    assert compose("train").model.schedule.max_iters == 1500
    # PIDynNet stops where a peer is far ahead on a strong-motion record only (its diagnosis too); a
    # simulated record and the paper's tables keep its whole budget
    assert train.stop_behind == diagnose.stop_behind == 1.5
    assert compose("train").model.schedule.stop_behind is None
    for exp in ("table1", "table2", "table3"):
        assert compose("train", overrides=[f"experiment={exp}"]).model.schedule.stop_behind is None, exp
    several = Schedule(**train).for_records(3)
    assert (several.pretrain_iters, several.pretrain_iters_window, several.max_iters) == (1000, 1000, 1500)
    assert Schedule(**train).for_records(1).max_iters == 500
    with pytest.raises(ValueError, match="several_records"):
        Schedule(several_records={"max_iter": 5})


def test_the_identifier_trains_the_informative_windows_within_the_limit():
    from types import SimpleNamespace

    from pidyn.models.identify import SubperiodIdentifier

    windows = [SimpleNamespace(index=i, piece=i % 3, informative=i != 1) for i in range(12)]
    run = SimpleNamespace(
        schedule=Schedule(max_windows=8, windows_per_record=2), dm=SimpleNamespace(windows=windows)
    )
    todo = SubperiodIdentifier._todo(run)  # three records: six windows, the uninformative one skipped
    assert [w.index for w in todo] == [0, 2, 3, 4, 5, 6]
    one = SimpleNamespace(
        schedule=Schedule(max_windows=8, windows_per_record=2),
        dm=SimpleNamespace(windows=windows[:1] + windows[3:6:3]),
    )
    assert len(SubperiodIdentifier._todo(one)) == 2


def test_a_simulated_records_budget_is_one_window_and_the_papers_tables_keep_every_one():
    """train.py on a simulated record trains PIDynNet on one window (the refinement ends at the same
    estimates); the tables, the paper's settings and generalize.py keep every window."""
    assert compose("train").model.schedule.max_windows == 1
    assert compose("train", overrides=["system=bouc_wen"]).model.schedule.max_windows == 1
    assert compose("generalize").model.schedule.max_windows is None
    for exp in ("table1", "table2", "table3", "scaling", "paper"):
        assert compose("train", overrides=[f"experiment={exp}"]).model.schedule.max_windows is None, exp
