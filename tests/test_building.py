"""Multi-storey shear buildings measured by floor accelerometers: the equations (once, for
torch, NumPy and dual arrays), the measurement channels, modal properties, and identification
from accelerations only (refinement, UKF, PIDynNet's drift)."""

import numpy as np
import pytest
import torch

from pidyn.baselines import cramer_rao, unscented_kalman_filter
from pidyn.data.sources import Record, synthetic
from pidyn.data.windows import make_windows
from pidyn.excitation import prepare
from pidyn.models.pidynnet import PIDynNet
from pidyn.nets import TaylorMLP
from pidyn.refine import RefineSettings, refine
from pidyn.simulate import simulate
from pidyn.systems import ShearBuilding
from pidyn.systems.base import Kinematics
from pidyn.systems.modal import compare_modes, modal_properties

BW1 = {1: [{"term": "hysteresis", "beta": 20.0, "gamma": 40.0, "n": 2.0, "shape_scale": 20.0}]}


def five_storey(**kw):
    return ShearBuilding(n_storeys=5, stiffnesses=200.0, stiffness_taper=0.5, storey_terms=BW1, **kw)


def test_parameters_carry_their_storey_and_guesses_apply_to_every_storey():
    sb = five_storey(guess={"c": 1.0, "k": 120.0, "beta": 10.0}, params={"k2": {"init": 80.0}})
    specs = {s.name: s for s in sb.param_specs()}
    assert [n for n in specs if n.startswith("k")] == ["k1", "k2", "k3", "k4", "k5"]
    assert {"beta1", "gamma1", "n1"} <= set(specs) and "beta2" not in specs
    assert specs["k1"].true == 200.0 and specs["k5"].true == pytest.approx(100.0)
    assert specs["c3"].init == 1.0 and specs["k4"].init == 120.0 and specs["k2"].init == 80.0
    assert specs["beta1"].init == 10.0 and specs["gamma1"].init == 40.0
    assert sb.n_latent == 1 and sb.latent_names == ("hysteresis1",)
    with pytest.raises(ValueError, match="storeys are 1..5"):
        ShearBuilding(n_storeys=5, storey_terms={6: {"term": "cubic_stiffness", "k3": 1.0}})
    with pytest.raises(ValueError, match="not one of"):
        ShearBuilding(storey_terms={1: {"term": "cubik"}})
    with pytest.raises(ValueError, match="3 values for 5 storeys"):
        ShearBuilding(n_storeys=5, stiffnesses=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="base names"):
        ShearBuilding(guess={"kk": 1.0})


@pytest.mark.parametrize(
    "system",
    [five_storey(), ShearBuilding(storey_terms={2: {"term": "cubic_stiffness", "k3": 5e3}})],
    ids=["bouc_wen_storey", "cubic_storey"],
)
def test_torch_residual_and_numpy_rate_are_one_equation(system):
    """The residual vanishes on a solve_ivp trajectory: the same code serves the loss and the
    simulation (the dual-array rate against finite differences: ``test_refine.py``)."""
    gm = prepare("el_centro", scale=2.0, duration=6.0, dt=0.01)
    p = system.true_values()
    tr = simulate(system, p, gm, gm.t)
    n = system.n_dof
    y = np.concatenate([tr.x, tr.v] + ([tr.z] if tr.z is not None else []), axis=1)
    rate = system.state_rate(tr.t, y, p, tr.f)
    T = lambda a: torch.tensor(a, dtype=torch.float64)  # noqa: E731
    k = Kinematics(
        T(tr.t),
        T(tr.x),
        T(tr.v),
        T(rate[:, n : 2 * n]),
        None if tr.z is None else T(tr.z),
        None if tr.z is None else T(rate[:, 2 * n :]),
    )
    res = system.residual(k, T(tr.f), {a: torch.tensor(b, dtype=torch.float64) for a, b in p.items()})
    assert res["motion"].shape == (len(tr.t), n)
    for name, r in res.items():
        assert float(r.abs().max()) < 1e-9, name
    assert np.abs(rate[:, n : 2 * n] - tr.a).max() < 1e-9


def test_modal_properties_match_closed_forms():
    one = ShearBuilding(n_storeys=1, masses=[4.0], dampings=[2.0], stiffnesses=[100.0])
    m = modal_properties(*one.linear_matrices(one.true_values()))
    assert m["frequency_hz"][0] * 2 * np.pi == pytest.approx(5.0)
    assert m["damping_ratio"][0] == pytest.approx(2.0 / (2 * np.sqrt(400.0)))
    # two equal storeys, unit masses: omega^2 = k (3 -+ sqrt 5) / 2, first shape (1, (1 + sqrt 5) / 2) / roof
    two = ShearBuilding(n_storeys=2, masses=1.0, dampings=1e-9, stiffnesses=100.0, stiffness_taper=1.0)
    m = modal_properties(*two.linear_matrices(two.true_values()))
    w = np.sqrt(100.0 * (3 - np.sqrt(5)) / 2), np.sqrt(100.0 * (3 + np.sqrt(5)) / 2)
    np.testing.assert_allclose(np.array(m["frequency_hz"]) * 2 * np.pi, w, rtol=1e-12)
    np.testing.assert_allclose(m["mode_shapes"][0], [2 / (1 + np.sqrt(5)), 1.0], rtol=1e-12)
    # a Bouc-Wen storey's stiffness about rest is its k; a wrong k1 shows in the frequencies, not the MAC only
    sb = five_storey()
    wrong = dict(sb.true_values(), k1=150.0)
    cmp = compare_modes(sb, wrong, sb.true_values())
    assert cmp["frequency_error_pct"][0] > 1.0 and min(cmp["mac"]) > 0.9


def test_accelerometers_on_some_floors_measure_absolute_acceleration_with_its_own_noise():
    sb = five_storey()
    r = synthetic(
        sb,
        "el_centro",
        eq_scale=3.0,
        duration=8.0,
        noise={"a": 0.02, "x": 0.0},
        channels=("a", "x"),
        sensors=[1, 3, 5],
        data_seed=4,
    )
    assert r.sensors() == {"x": [1, 3, 5], "a": [1, 3, 5]} and r.x is not None
    assert np.all(np.isnan(r.a[:, [1, 3]])) and not np.isnan(r.a[:, [0, 2, 4]]).any()
    absolute = r.clean.a[:, 4] + r.f
    err = r.a[:, 4] + r.f - absolute
    assert np.std(err) / np.sqrt(np.mean(absolute**2)) == pytest.approx(0.02, rel=0.1)
    assert np.allclose(r.x[:, 0], r.clean.x[:, 0])  # its own level: noise-free displacement
    with pytest.raises(ValueError, match="sensors"):
        synthetic(sb, "el_centro", duration=4.0, channels=("a",), sensors=[0, 6])
    with pytest.raises(ValueError, match="noise levels"):
        synthetic(sb, "el_centro", duration=4.0, channels=("a",), noise={"x": 0.01})
    with pytest.raises(Exception, match="no response channel"):
        Record("empty", t=np.arange(20) * 0.01, f=np.zeros(20))


def test_refinement_recovers_a_building_from_floor_accelerations_to_solver_precision():
    """Noise-free, accelerometers on floors 1 and 3 only, initial state unknown: the refinement
    started from 20 % wrong parameters and integrated accelerations returns the truth."""
    sb = ShearBuilding()
    r = synthetic(sb, "el_centro", duration=10.0, channels=("a",), sensors=[1, 3])
    truth = sb.true_values()
    start = {
        n: v * (1.2 if i % 2 else 0.8) for i, (n, v) in enumerate(truth.items()) if not n.startswith("m")
    }
    res = refine(sb, r, {"start": start}, RefineSettings(states="integrated", segment_length=2.0))
    for n, v in res.params.items():
        assert v == pytest.approx(truth[n], rel=2e-5), n  # RK4 (4 substeps) against solve_ivp
    assert res.max_defect < 1e-8


def test_ukf_and_cramer_rao_take_any_channel_set():
    sb = ShearBuilding()
    r = synthetic(sb, "el_centro", duration=12.0, channels=("a",), sensors=[1, 2, 3], noise=0.02, data_seed=1)
    start = {"c1": 0.6, "k1": 180.0, "c2": 0.6, "k2": 170.0, "c3": 0.4, "k3": 90.0}
    ukf = unscented_kalman_filter(r, sb, noise_level=0.02, init=start, q_param=1e-9)
    truth = sb.true_values()
    for n in ("k1", "k2", "k3"):
        assert abs(ukf.params[n] / truth[n] - 1) < 0.02, (n, ukf.params[n])
    all3 = cramer_rao(sb, truth, r.t, r.f, 0.02, channels={"a": [1, 2, 3]})["std_pct"]
    roof = cramer_rao(sb, truth, r.t, r.f, 0.02, channels={"a": [3]})["std_pct"]
    assert all(0 < all3[n] < roof[n] for n in all3)  # fewer sensors, less information


def test_pidynnet_pins_the_drift_that_accelerations_leave_free():
    """x + a + b t fits the accelerations as well as x: with the true networks' output shifted
    by a drift, the drift solve finds it again from the physics and the parameters with it."""
    torch.manual_seed(0)
    sb = ShearBuilding()
    r = synthetic(sb, "el_centro", duration=6.0, channels=("a",))
    w = make_windows(r.t, r.f, None, None, r.a, 3.0, 400, dtype=torch.float64, accel_signal=r.f)[1]
    net = PIDynNet(sb, TaylorMLP(out_features=3, width=8, depth=1, n_fourier=1)).double()
    net.enter_window(w)
    assert net.use_drift
    # a stand-in for a perfectly pretrained network: the true y = x + q plus a drift
    clean = r.clean
    tp = w.t_pool.numpy()
    x = np.stack([np.interp(tp, clean.t, clean.x[:, j]) for j in range(3)], 1)
    v = np.stack([np.interp(tp, clean.t, clean.v[:, j]) for j in range(3)], 1)
    a = np.stack([np.interp(tp, clean.t, clean.a[:, j]) for j in range(3)], 1)
    tau = (tp - 0.5 * (w.t0 + w.t1)) / (0.5 * (w.t1 - w.t0))
    drift = np.array([0.02, -0.01, 0.03])[None, :] + np.array([0.01, 0.02, -0.02])[None, :] * tau[:, None]

    def fake(t, f=None, q=None, qd=None, order=2, latent=True):
        d = net.scale_x * (net.drift[0] + net.drift[1] * torch.as_tensor(tau)[:, None])
        dv = net.scale_x * net.drift[1] / net.rpn.t_half
        T = lambda z: torch.as_tensor(z)  # noqa: E731
        return Kinematics(
            T(tp), T(x + drift) + d, T(v + drift[:, 1:2] * 0 + np.gradient(drift, tp, axis=0)) + dv, T(a)
        )

    net.kinematics = fake
    net.use_drift = False  # the solve sees the networks alone
    est, rejected = net.solve_drift(w, ["c1", "k1", "c2", "k2", "c3", "k3"])
    truth = sb.true_values()
    for n, v_ in est.items():
        assert v_ == pytest.approx(truth[n], rel=2e-2), n
    recovered = (net.scale_x * net.drift[0]).detach().numpy()
    assert np.allclose(recovered, -np.array([0.02, -0.01, 0.03]), atol=2e-3)


@pytest.mark.slow
def test_a_users_accelerometer_file_identifies_a_two_storey_building(tmp_path):
    """The interface as a user runs it: ``train.py system=shear_building system.n_storeys=2
    system.masses=[..] data=csv data.path=FILE`` on a CSV of t, ag, a1, a2 (absolute floor
    accelerations, 1 % noise), composed as the command composes it and run in this process (the
    command line itself is proven by test_package and test_probe). PIDynNet alone finds the
    stiffnesses within a few percent; the final estimate lies within 4 of its own standard errors
    of the truth, with ci95 written."""
    import json

    import pandas as pd
    import yaml
    from helpers import make_cfg

    from pidyn.tasks.train import train

    sb = ShearBuilding(n_storeys=2)
    r = synthetic(sb, "el_centro", duration=12.0, channels=("a",), noise=0.01, data_seed=3)
    csv = tmp_path / "floors.csv"
    pd.DataFrame({"t": r.t, "ag": r.f, "a1": r.a[:, 0] + r.f, "a2": r.a[:, 1] + r.f}).to_csv(csv, index=False)
    cfg = make_cfg(
        [
            "system=shear_building",
            "system.n_storeys=2",
            "system.masses=[1.0,1.0]",
            "data=csv",
            f"data.path={csv}",
            "logger=none",
            "baselines=none",
            "model.schedule.max_windows=1",
            "model.schedule.max_iters=500",
            "model.schedule.pretrain_iters=300",
        ],
        tmp_path / "run",
    )
    train(cfg)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    ident = yaml.safe_load((tmp_path / "run" / "identified_params.yaml").read_text())
    truth = sb.true_values()
    assert set(metrics["params"]) == {"c1", "k1", "c2", "k2"}
    for n in ("k1", "k2"):
        assert abs(metrics["pidynnet"]["params"][n] / truth[n] - 1) < 0.05, (
            n,
            metrics["pidynnet"]["params"][n],
        )
    for n, v in metrics["params"].items():
        lo, hi = ident["params"][n]["ci95"]
        assert lo < v < hi
        assert abs(v - truth[n]) < 4 * metrics["std"][n], (n, v, truth[n], metrics["std"][n])
    # a measured building's modes: the stabilisation diagram, and its shapes beside the data's with MAC
    figures = tmp_path / "run" / "figures"
    for name in ("stabilization.png", "mode_shapes.png"):
        assert (figures / name).stat().st_size > 10_000, name
    true_hz = modal_properties(*sb.linear_matrices(truth))["frequency_hz"]
    stood = [m["frequency_hz"] for m in metrics["stabilization"]["stable_modes"]]
    assert all(min(abs(f - g) / g for f in stood) < 0.02 for g in true_hz), stood
    assert [r["mode"] for r in metrics["mode_shapes"]] == [1, 2]
    assert all(r["subspace"]["mac"] > 0.99 for r in metrics["mode_shapes"]), metrics["mode_shapes"]
