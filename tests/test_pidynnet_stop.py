"""PIDynNet stops where a peer's estimate is far ahead (``model.schedule.stop_behind``): the refinement
starts from the estimate that simulates best, so later windows are spent on nothing it uses."""

from __future__ import annotations

import json

import pytest
from helpers import make_cfg

from pidyn.models.schedule import Schedule

FAST = [
    "model.schedule.pretrain_iters=20",
    "model.schedule.pretrain_iters_window=10",
    "model.schedule.max_iters=20",
    "excitation.duration=15",
]


class _Rows:
    """A baselines job whose rows are in."""

    def __init__(self, rows: list[dict]) -> None:
        self.rows, self.asked = rows, 0

    def result(self) -> list[dict]:
        self.asked += 1
        return self.rows


def test_the_factor_is_at_least_one():
    assert Schedule(stop_behind=2.0).stop_behind == 2.0
    with pytest.raises(ValueError, match="stop_behind must be >= 1"):
        Schedule(stop_behind=0.5)


def test_the_check_stops_an_estimate_far_behind_a_peers_and_keeps_one_that_is_not(tmp_path):
    from pidyn.runs.build import system_and_record
    from pidyn.runs.pidynnet_stop import behind_check

    cfg = make_cfg(["model.schedule.stop_behind=2.0", "excitation.duration=15"], tmp_path)
    system, record = system_and_record(cfg, None)
    truth = dict(record.truth)
    off = {**truth, "k1": 2.0 * truth["k1"]}  # a period 30 % short
    peers = _Rows([{"method": "output_error", "params": truth}, {"method": "ukf", "params": {}}])
    ask = behind_check(cfg, system, record, peers, None)
    text = ask(off)
    assert text is not None and "[pidynnet_behind]" in text and "output_error's" in text
    assert ask(truth) is None  # level with the peer: PIDynNet goes on
    # a peer no better than PIDynNet's estimate by the factor: goes on too
    assert (
        behind_check(cfg, system, record, _Rows([{"method": "output_error", "params": off}]), None)(off)
        is None
    )
    assert peers.asked == 2  # the rows asked for at each window (the job keeps them)
    # off without the setting, without a refinement, or without a peer among its starts
    assert behind_check(make_cfg([], tmp_path), system, record, peers, None) is None
    none = make_cfg(["model.schedule.stop_behind=2.0", "model.refine=none"], tmp_path)
    assert behind_check(none, system, record, peers, None) is None
    assert behind_check(cfg, system, record, _Rows([]), None)(off) is None


def test_a_baselines_job_gives_the_same_rows_when_asked_again(monkeypatch):
    import pidyn.baselines.worker as worker

    calls: list[tuple] = []
    monkeypatch.setattr(worker, "baseline_rows", lambda *a: calls.append(a) or [{"method": "x"}])
    job = worker.BaselineJob({"run": []}, 0.0, None, None)  # no worker: the rows are made here
    assert job.result() == job.result() == [{"method": "x"}]
    assert len(calls) == 1


@pytest.mark.slow
def test_a_run_whose_peer_is_far_ahead_trains_one_window_and_refines_from_the_peer(tmp_path):
    from pidyn.tasks.train import train

    cfg = make_cfg(
        FAST
        + [
            "model.schedule.max_windows=3",
            "model.schedule.stop_behind=1.0",
            "baselines.run=[output_error]",
            "baselines.cramer_rao=false",
        ],
        tmp_path,
    )
    metrics = train(cfg)
    assert metrics["windows"] == 1
    assert any("[pidynnet_behind]" in n for n in metrics["notes"])
    assert json.loads((tmp_path / "refinement.json").read_text())["start"] == "output_error"
    state = json.loads((tmp_path / "subperiod_state.json").read_text())
    assert len(state["windows"]) == 1 and state["next_window"] > state["windows"][0]["index"]
    assert max(metrics["error_pct"].values()) < 1.0  # the refinement from the peer still identifies
