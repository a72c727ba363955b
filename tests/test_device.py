"""Every tensor the training step reads follows the module to its device (``trainer=gpu``).

CI has no GPU. The losses are therefore also evaluated on PyTorch's ``meta`` device: a meta
tensor meets a CPU tensor (other than a 0-d scalar) only with an error, so a tensor left on
the host inside the physics or data losses fails here just as it would on a GPU, and so
does a step that reads a value back from the device.
"""

from __future__ import annotations

import copy

import pytest
import torch
from helpers import make_cfg

from pidyn.runs.build import build_run


@pytest.fixture(scope="module", params=["duffing", "bouc_wen", "shear_building"])
def built(request, tmp_path_factory):
    return build_run(
        make_cfg([f"system={request.param}", "debug=smoke"], tmp_path_factory.mktemp("run")), None
    )


def test_window_to_moves_every_tensor_and_leaves_the_original(built):
    w = built.ident.dm.windows[0]
    m = w.to("meta")
    for name, val in vars(m).items():
        if isinstance(val, torch.Tensor):
            assert val.device.type == "meta", name
            assert getattr(w, name).device.type == "cpu", name
    assert m.complete == w.complete and m.complete is not w.complete


@pytest.mark.parametrize("fill", [False, True])
@pytest.mark.parametrize("anchored", [False, True])
def test_the_losses_read_no_tensor_left_on_the_host(built, fill, anchored):
    net = copy.deepcopy(built.module.net)  # moved to meta below; the fixture's stays on the host
    w = copy.deepcopy(built.ident.dm.windows[0])
    net.enter_window(w)
    if fill:  # pretraining's fill of floors without a sensor is computed on the host once
        for kind in ("x", "v", "a"):
            w.filled(kind)
    if anchored:  # prediction holds the handed-over state exactly (the anchor moves with the module)
        nd, nz = net.system.n_dof, net.system.n_latent
        net.anchor = (torch.tensor(w.t0), torch.zeros(nd), torch.zeros(nd), torch.zeros(nz) if nz else None)
    net.to("meta")
    wm = w.to("meta")
    losses = {
        **net.data_losses(wm, fill=fill),
        **net.physics_losses(wm.t_pool, wm.f_pool, wm.q_pool, wm.qd_pool),
    }
    assert losses and all(v.device.type == "meta" for v in losses.values())


def test_a_partly_measured_channel_is_masked_and_a_complete_one_is_not(tmp_path):
    run = build_run(make_cfg(["system=shear_building", "debug=smoke", "data.sensors=[1,3]"], tmp_path), None)
    w = run.ident.dm.windows[0]
    assert w.complete == {"a": False}
    filled, complete = w.filled("a")
    assert complete and not torch.isnan(filled).any()
    assert torch.allclose(filled[:, 1], 0.5 * (w.a[:, 0] + w.a[:, 2]))
    net = run.module.net
    net.enter_window(w)
    masked = net.data_losses(w)["data/a"]
    k = net.kinematics(w.t_data, w.f_data, w.q_data, w.qd_data, order=2, latent=False)
    cols = [0, 2]
    by_hand = (((k.a[:, cols] - w.a[:, cols]) / net.scale_a[cols]) ** 2).mean()
    assert torch.allclose(masked, by_hand)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no GPU on this machine")
def test_trainer_gpu_runs_the_smoke_identification(tmp_path):
    from pidyn.tasks.train import train

    metrics = train(make_cfg(["trainer=gpu", "debug=smoke", "system=bouc_wen"], tmp_path))
    assert metrics["params"] and all(v == v for v in metrics["params"].values())
