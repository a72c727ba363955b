"""A run's knobs and scores go to TensorBoard's HParams: numbers, bools and strings only, finite scores."""

from __future__ import annotations

from types import SimpleNamespace

from pidyn.runs.hparams import log_hparams


def test_knobs_are_plain_and_only_finite_scores_are_written():
    seen = {}
    logger = SimpleNamespace(
        experiment=object(), log_hyperparams=lambda hp, scores: seen.update(hp=hp, scores=scores)
    )
    metrics = {
        "system": "duffing",
        "noise": 0.05,
        "eq_scale": 1.0,
        "refine": {"method": "multiple_shooting"},
        "max_error_pct": 0.4,
        "adequacy": {"fit_nrmse": 0.02, "heldout_nrmse": float("nan")},
        "wall_seconds": 12.0,
    }
    hp = log_hparams(logger, metrics)
    assert hp == seen["hp"] and hp["refine"] == "{'method': 'multiple_shooting'}" and hp["noise"] == 0.05
    assert seen["scores"] == {
        "hparams/max_error_pct": 0.4,
        "hparams/fit_nrmse": 0.02,
        "hparams/wall_seconds": 12.0,
    }
    assert log_hparams(None, metrics) == hp  # no logger: nothing written, the knobs still returned
