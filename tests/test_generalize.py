"""Prediction of an unseen response by physics-only training (paper Eq. 14)."""

import lightning as L
import numpy as np
import pandas as pd
import pytest
import torch
from helpers import make_cfg  # noqa: E402

from pidyn.data.sources import synthetic_from_motion  # noqa: E402
from pidyn.excitation import prepare  # noqa: E402
from pidyn.models.lit_module import PIDynNetModule  # noqa: E402
from pidyn.models.pidynnet import PIDynNet  # noqa: E402
from pidyn.models.predict import PredictSettings, pearson, predict_response  # noqa: E402
from pidyn.nets import TaylorMLP  # noqa: E402
from pidyn.systems import Duffing  # noqa: E402


def trainer(**kw):
    return L.Trainer(
        accelerator="cpu",
        max_epochs=1,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        **kw,
    )


def duffing_with_true_params(scale: float, duration: float):
    """A Duffing module holding the true parameters, and its true response to Kobe x ``scale``."""
    torch.manual_seed(0)
    s = Duffing()
    truth = synthetic_from_motion(
        s, prepare("kobe", scale=scale, duration=duration, dt=0.01).truncated(duration)
    )
    module = PIDynNetModule(PIDynNet(s, TaylorMLP()))
    module.net.params.set_values(s.true_values())
    return module, truth


@pytest.mark.slow
def test_physics_only_prediction_tracks_the_true_response():
    torch.manual_seed(0)
    s = Duffing()
    gm = prepare("kobe", scale=0.5, duration=11.0, dt=0.01).truncated(11.0)
    truth = synthetic_from_motion(s, gm)
    module = PIDynNetModule(PIDynNet(s, TaylorMLP()))  # parameters at their (true) initial values
    module.net.params.set_values(s.true_values())
    before = {k: v.clone() for k, v in module.net.rpn.state_dict().items()}
    pred = predict_response(
        module, truth, trainer, PredictSettings(iterations=200, lbfgs_steps=3), x_scale=0.1, v_scale=0.5
    )
    strong = truth.t > 7.0
    assert pearson(pred.x[strong], truth.x[strong]) > 0.9
    assert np.all(pred.x[truth.t < 0.01] == pytest.approx(0.0, abs=1e-6))  # starts at rest, exactly
    # parameters and identification networks untouched
    assert all(torch.equal(before[k], v) for k, v in module.net.rpn.state_dict().items())
    assert all(p.requires_grad for p in module.net.physical_parameters())


@pytest.mark.second_proof  # the prediction, L-BFGS finish included, is proven by test_physics_only_prediction_tracks_the_true_response
def test_lbfgs_finish_solves_a_strongly_nonlinear_window_that_adam_alone_does_not():
    """Kobe x1.5 drives the Duffing to k3 x^2 / k1 ~ 0.8; a short Adam budget per window
    leaves the forward problem unsolved, and the wrong state is handed on."""
    module, truth = duffing_with_true_params(scale=1.5, duration=12.0)
    strong = truth.t > 6.0
    kw = dict(iterations=300, split_tol=float("inf"))  # no window splitting here
    adam = predict_response(
        module, truth, trainer, PredictSettings(lbfgs_steps=0, **kw), x_scale=0.1, v_scale=0.5
    )
    both = predict_response(
        module, truth, trainer, PredictSettings(lbfgs_steps=30, **kw), x_scale=0.1, v_scale=0.5
    )
    g_adam, g_both = pearson(adam.x[strong], truth.x[strong]), pearson(both.x[strong], truth.x[strong])
    assert g_both > 0.99, (g_adam, g_both)
    assert g_adam < g_both
    rel = np.sqrt(np.mean((both.x[strong] - truth.x[strong]) ** 2) / np.mean(truth.x[strong] ** 2))
    assert rel < 0.05


@pytest.mark.slow
def test_generalize_task_writes_figures_and_table(tmp_path):
    from pidyn.tasks.generalize import generalize

    # the files and the resume are tested here, not the identification: a short schedule
    gcfg = make_cfg(
        [
            "excitation.duration=12",
            "model.schedule.max_windows=1",
            "model.schedule.pretrain_iters=150",
            "model.schedule.pretrain_iters_window=150",
            "model.schedule.max_iters=200",
            "generalization.max_cases=1",
            "generalization.duration=4",
            "generalization.iterations=50",
            "generalization.lbfgs_steps=3",
            "generalization.split_tol=1e9",
            "logger=none",
        ],
        tmp_path,
        config_name="generalize",
    )
    summary = generalize(gcfg)
    assert summary["cases"] == 1
    for f in [
        "generalization.csv",
        "generalization.json",
        "figures/fig4_identification_prediction.png",
        "figures/fig5_correlation_histogram.png",
        "predictions/case_000.npz",
        "generalization.md",
    ]:
        assert (tmp_path / f).exists(), f
    first = pd.read_csv(tmp_path / "generalization.csv")
    # a longer sweep in the same folder resumes: the finished case is kept, not recomputed
    gcfg.generalization.max_cases = 2
    summary = generalize(gcfg)
    again = pd.read_csv(tmp_path / "generalization.csv")
    assert summary["cases"] == 2 and len(again) == 2
    pd.testing.assert_frame_equal(again.iloc[:1], first)
    assert (tmp_path / "predictions/case_001.npz").exists()


def test_a_window_left_unsolved_is_solved_again_as_two_halves():
    """With a tolerance no window can meet, every window is halved down to min_window, the
    halves tile the record without gap or overlap, and the state is handed across them."""
    module, truth = duffing_with_true_params(scale=0.5, duration=3.0)
    pred = predict_response(
        module,
        truth,
        trainer,
        PredictSettings(iterations=5, lbfgs_steps=0, split_tol=0.0, min_window=0.75),
        window_length=1.5,
        x_scale=0.1,
        v_scale=0.5,
    )
    spans = [(a, b) for a, b, _ in pred.windows]
    assert spans == [(0.0, 0.75), (0.75, 1.5), (1.5, 2.25), (2.25, 3.0)]
    assert all(np.isfinite(loss) and loss > 0 for _, _, loss in pred.windows)
    assert np.all(np.isfinite(pred.x))
    # never-failing tolerance: the windows are left as they are
    pred = predict_response(
        module,
        truth,
        trainer,
        PredictSettings(iterations=5, lbfgs_steps=0, split_tol=float("inf")),
        window_length=1.5,
        x_scale=0.1,
        v_scale=0.5,
    )
    assert [(a, b) for a, b, _ in pred.windows] == [(0.0, 1.5), (1.5, 3.0)]


def test_unseen_records_start_before_their_strong_motion_and_match_the_pga():
    from pidyn.runs.generalization import unseen_cases

    cfg = make_cfg([], config_name="generalize")
    cases = unseen_cases(cfg, "kobe", 8.0)
    own = [c for c in cases if c["record"] == "kobe"]
    assert own and all(c["start"] == 0.0 for c in own)  # versions of the identification record start with it
    chichi = [c for c in cases if c["record"] == "chichi"]
    assert [c["start"] for c in chichi] == [22.0, 22.0]  # strong motion (5 % Arias) at 24.2 s, 2 s lead
    seg = prepare(
        "chichi",
        dt=cfg.excitation.dt,
        start=22.0,
        duration=cfg.generalization.duration,
        scale=chichi[1]["scale"],
    )
    assert seg.pga == pytest.approx(8.0, rel=1e-9)  # the predicted segment itself carries the target PGA
    cfg.generalization.align = False
    assert all(c["start"] == 0.0 for c in unseen_cases(cfg, "kobe", 8.0))


def test_prediction_settings_have_one_source_of_truth():
    """conf/generalize.yaml's prediction fields and PredictSettings' defaults are the same, and a
    misspelled option names the valid ones before any identification runs."""
    from dataclasses import fields

    from pidyn.runs.generalization import prediction_settings

    cfg = make_cfg([], config_name="generalize")
    from_yaml = prediction_settings(cfg.generalization)
    for f in fields(PredictSettings):
        assert f.name in cfg.generalization, f"generalization.{f.name} missing from conf/generalize.yaml"
        assert getattr(from_yaml, f.name) == f.default, (f.name, getattr(from_yaml, f.name), f.default)
    cfg.generalization.start_from = "identifed"
    with pytest.raises(ValueError, match="fresh, identified"):
        prediction_settings(cfg.generalization)
