"""The refinement stage as a user runs it: metrics and identified_params carry the final
estimate with its intervals, PIDynNet's own numbers beside it; refine=none is PIDynNet alone."""

import json

import pytest
import yaml
from helpers import make_cfg  # noqa: E402

from pidyn.tasks.train import train  # noqa: E402

SMOKE = ["debug=smoke", "logger=none", "baselines=none"]
# PIDynNet's estimate for these smoke settings before the refinement stage existed (1 window, 50
# iterations: far from the truth on purpose; these pin the PIDynNet path, not its accuracy).
# Bouc-Wen's beta, gamma, n moved by 2e-4 relative when the fusion's ridge stopped pulling
# ill-determined directions toward raw zero (it now pulls them to the windows' own estimate).
# Duffing's changed when the least-squares start stopped taking a k3 its window does not
# determine (after 50 pretraining iterations k3 = 72 +- more than half of it: k3 keeps its start).
BEFORE = {
    "duffing": {"c": 1.0588386058807373, "k1": 15.065049171447754, "k3": 45.12295913696289},
    "bouc_wen": {
        "c": 2.133432388305664,
        "k": 1.5203810930252075,
        "beta": 0.4899733066558838,
        "gamma": 0.4072237014770508,
        "n": 1.671323537826538,
    },
}


@pytest.mark.parametrize("system", ["duffing", "bouc_wen"])
def test_refine_none_reproduces_pidynnet(tmp_path, system):
    m = train(make_cfg(SMOKE + [f"system={system}", "model.refine=none"], tmp_path))
    assert m["refine"] == "none" and "ci95" not in m
    assert m["params"] == m["pidynnet"]["params"]
    for k, v in BEFORE[system].items():
        assert m["params"][k] == pytest.approx(v, rel=1e-4), (k, m["params"])


def test_refined_run_reports_final_and_pidynnet_estimates(tmp_path):
    m = train(make_cfg(SMOKE, tmp_path))
    for k, v in BEFORE["duffing"].items():  # PIDynNet's own estimate is unchanged by the stage after it
        assert m["pidynnet"]["params"][k] == pytest.approx(v, rel=1e-4)
    assert m["max_error_pct"] < 1e-3 < m["pidynnet"]["max_error_pct"]
    assert m["max_error_pct"] == max(m["error_pct"].values())
    saved = yaml.safe_load((tmp_path / "identified_params.yaml").read_text())
    for n, row in saved["params"].items():
        lo, hi = row["ci95"]
        assert lo <= row["value"] <= hi and [lo, hi] == m["ci95"][n]
    assert json.loads((tmp_path / "refinement.json").read_text())["max_defect"] < 1e-8


def test_csv_without_truth_gets_intervals(tmp_path):
    """`python train.py system=duffing data=csv data.path=FILE`: no truth, so no errors, but
    values, intervals and PIDynNet's estimate all there."""
    import pandas as pd

    from pidyn.data.sources import synthetic
    from pidyn.systems import Duffing

    r = synthetic(Duffing(c=0.4, k1=20.0, k3=200.0), "northridge", duration=12.0, noise=0.02, data_seed=3)
    path = tmp_path / "rec.csv"
    pd.DataFrame({"t": r.t, "ag": r.f, "x": r.x[:, 0], "v": r.v[:, 0]}).to_csv(path, index=False)
    out = tmp_path / "run"
    m = train(make_cfg(SMOKE + ["system=duffing", "data=csv", f"data.path={path}"], out))
    assert m["error_pct"] == {} and m["max_error_pct"] is None and m["pidynnet"]["error_pct"] == {}
    saved = yaml.safe_load((out / "identified_params.yaml").read_text())
    truth = {"c": 0.4, "k1": 20.0, "k3": 200.0}
    for n, row in saved["params"].items():
        lo, hi = row["ci95"]
        assert lo < hi and set(m["pidynnet"]["params"]) == set(truth)
        assert abs(row["value"] - truth[n]) / truth[n] < 0.05, (n, row)


def test_compare_states_refines_from_the_start_the_stage_chose(tmp_path, monkeypatch):
    """compare_states isolates the segment states: the comparison starts from the same
    parameters as the stage (a classical estimate when PIDynNet's simulated worse)."""
    from types import SimpleNamespace

    import pidyn.refine
    import pidyn.runs.methods
    from pidyn.runs.methods import run_refinement

    calls = []

    def fake_refine(system, record, starts, settings, network_states=None, **span):
        calls.append((dict(starts), settings.states))
        return SimpleNamespace(
            start="output_error" if "output_error" in starts else "pidynnet",
            params={},
            cost=1.0,
            converged=True,
            max_defect=0.0,
            seconds=0.0,
        )

    monkeypatch.setattr(pidyn.runs.methods, "refine", fake_refine)
    # the fake refinement has no model to simulate: the divergence check is another test's
    monkeypatch.setattr(pidyn.runs.methods, "check_refined", lambda *a, **k: None)
    cfg = make_cfg(
        SMOKE + ["model.refine.starts=[output_error]", "model.refine.compare_states=[integrated]"], tmp_path
    )
    pidyn_values, oe = {"c": 9.0, "k1": 9.0, "k3": 9.0}, {"c": 0.5, "k1": 15.0, "k3": 120.0}
    record = SimpleNamespace(truth=None)
    out = run_refinement(cfg, None, record, pidyn_values, [{"method": "output_error", "params": oe}], [])
    assert calls[0][0] == {"pidynnet": pidyn_values, "output_error": oe}
    assert calls[1] == ({"output_error": oe}, "integrated")
    assert "integrated" in out.compared
