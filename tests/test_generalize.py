"""Prediction of an unseen response by physics-only training (paper Eq. 14)."""

import sys
from pathlib import Path

import lightning as L
import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).parent))
from conftest import make_cfg  # noqa: E402

from pidyn.data.sources import synthetic_from_motion  # noqa: E402
from pidyn.excitation import prepare  # noqa: E402
from pidyn.models.lit_module import PIDynNetModule  # noqa: E402
from pidyn.models.pidynnet import PIDynNet  # noqa: E402
from pidyn.models.predict import pearson, predict_response  # noqa: E402
from pidyn.nets import TaylorMLP  # noqa: E402
from pidyn.systems import Duffing  # noqa: E402


def trainer(**kw):
    return L.Trainer(accelerator="cpu", max_epochs=1, logger=False, enable_checkpointing=False,
                     enable_progress_bar=False, enable_model_summary=False, **kw)


@pytest.mark.slow
def test_physics_only_prediction_tracks_the_true_response():
    torch.manual_seed(0)
    s = Duffing()
    gm = prepare("kobe", scale=0.5, duration=11.0, dt=0.01).truncated(11.0)
    truth = synthetic_from_motion(s, gm)
    module = PIDynNetModule(PIDynNet(s, TaylorMLP()))  # parameters at their (true) initial values
    module.net.params.set_values(s.true_values())
    before = {k: v.clone() for k, v in module.net.rpn.state_dict().items()}
    pred = predict_response(module, truth, trainer, iterations=300, x_scale=0.1, v_scale=0.5)
    strong = truth.t > 7.0
    assert pearson(pred.x[strong], truth.x[strong]) > 0.9
    assert np.all(pred.x[truth.t < 0.01] == pytest.approx(0.0, abs=1e-6))  # starts at rest, exactly
    # parameters and identification networks untouched
    assert all(torch.equal(before[k], v) for k, v in module.net.rpn.state_dict().items())
    assert all(p.requires_grad for p in module.net.physical_parameters())


@pytest.mark.slow
def test_lbfgs_finish_solves_a_strongly_nonlinear_window_that_adam_alone_does_not():
    """Kobe x1.5 drives the Duffing to k3 x^2 / k1 ~ 0.8; a short Adam budget per window
    leaves the forward problem unsolved, and the wrong state is handed on."""
    torch.manual_seed(0)
    s = Duffing()
    gm = prepare("kobe", scale=1.5, duration=12.0, dt=0.01).truncated(12.0)
    truth = synthetic_from_motion(s, gm)
    module = PIDynNetModule(PIDynNet(s, TaylorMLP()))
    module.net.params.set_values(s.true_values())
    strong = truth.t > 6.0
    kw = dict(iterations=300, x_scale=0.1, v_scale=0.5)
    adam = predict_response(module, truth, trainer, lbfgs_steps=0, **kw)
    both = predict_response(module, truth, trainer, lbfgs_steps=30, **kw)
    g_adam, g_both = pearson(adam.x[strong], truth.x[strong]), pearson(both.x[strong], truth.x[strong])
    assert g_both > 0.99, (g_adam, g_both)
    assert g_adam < g_both
    rel = np.sqrt(np.mean((both.x[strong] - truth.x[strong]) ** 2) / np.mean(truth.x[strong] ** 2))
    assert rel < 0.05


@pytest.mark.slow
def test_generalize_task_writes_figures_and_table(tmp_path):
    from pidyn.tasks.generalize import generalize

    gcfg = make_cfg(["excitation.duration=12", "model.schedule.max_windows=1", "generalization.max_cases=1",
                     "generalization.duration=4", "generalization.iterations=50", "logger=none"], tmp_path,
                    config_name="generalize")
    summary = generalize(gcfg)
    assert summary["cases"] == 1
    for f in ["generalization.csv", "generalization.json", "figures/fig4_identification_prediction.png",
              "figures/fig5_correlation_histogram.png"]:
        assert (tmp_path / f).exists(), f
