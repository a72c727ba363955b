"""The proof that identification works: a real (short) PIDynNet run recovers Duffing parameters."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from conftest import make_cfg  # noqa: E402

from pidyn.tasks.train import train  # noqa: E402


@pytest.mark.slow
def test_duffing_identified_from_one_kobe_window(tmp_path):
    """Default recipe, Kobe 1995 first 12 s, one informative window (~30 s on one core)."""
    cfg = make_cfg(["excitation.duration=12", "model.schedule.max_windows=1", "logger=none"], tmp_path)
    m = train(cfg)
    assert m["windows"] == 1
    for name, err in m["error_pct"].items():
        assert err < 3.0, (name, err, m["params"])
    assert m["sim_nrmse_x"] < 0.05


@pytest.mark.slow
def test_noisy_duffing_still_within_a_few_percent(tmp_path):
    cfg = make_cfg(["excitation.duration=12", "model.schedule.max_windows=1", "noise=0.05", "logger=none"], tmp_path)
    m = train(cfg)
    for name, err in m["error_pct"].items():
        assert err < 5.0, (name, err, m["params"])
