import numpy as np
import pytest
import torch

from pidyn.data.windows import double_integral, make_windows
from pidyn.models.pidynnet import PIDynNet
from pidyn.nets import TaylorMLP
from pidyn.systems import Duffing


def test_double_integral_is_exact_for_piecewise_linear_signals():
    t = np.arange(0, 4.0001, 0.01)
    s = 0.5 + 2.0 * t  # linear: q = 0.5 tau^2/2 + 2 (t^3/6 ...) relative to t0
    tq = np.linspace(1.0, 3.0, 333)
    q, qd = double_integral(t, s, tq, 1.0)
    tau = tq - 1.0
    s0, k = 0.5 + 2.0, 2.0
    assert np.allclose(qd, s0 * tau + k * tau**2 / 2, atol=1e-12)
    assert np.allclose(q, s0 * tau**2 / 2 + k * tau**3 / 6, atol=1e-12)


def test_windows_cover_record_and_flag_quiet_ones():
    t = np.arange(0, 12.0001, 0.01)
    x = np.sin(2 * t) * (t < 6)
    ws = make_windows(t, np.cos(t), x, None, None, 3.0, 100, min_peak_fraction=0.2)
    assert [w.t0 for w in ws] == [0.0, 3.0, 6.0, 9.0]
    assert [w.informative for w in ws] == [True, True, False, False]


def test_excitation_transform_is_an_exact_change_of_variable():
    """With the transform, x, x', x'' from the network equal y - q, y' - q', y'' - ag."""
    torch.set_default_dtype(torch.float64)
    t = np.arange(0, 6.0001, 0.01)
    ag = np.sin(7 * t) + 0.2 * np.cos(31 * t)
    w = make_windows(t, ag, 0.1 * np.sin(t), None, None, 3.0, 200, accel_signal=ag)[1]
    net = PIDynNet(Duffing(), TaylorMLP())
    net.enter_window(w)
    k = net.kinematics(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)
    y, yd, ydd = net.rpn.taylor(w.t_pool)
    assert torch.allclose(k.x[:, 0], y[:, 0] - w.q_pool)
    assert torch.allclose(k.v[:, 0], yd[:, 0] - w.qd_pool)
    assert torch.allclose(k.a[:, 0], ydd[:, 0] - w.f_pool)
    # q is the double integral of the (interpolated) excitation: check q'' numerically
    h = float(w.t_pool[1] - w.t_pool[0])
    qdd = (w.q_pool[2:] - 2 * w.q_pool[1:-1] + w.q_pool[:-2]) / h**2
    assert float((qdd - w.f_pool[1:-1]).abs().max()) < 0.05 * float(w.f_pool.abs().max())
    assert float(w.q_pool[0]) == pytest.approx(0.0, abs=1e-12) and float(w.qd_pool[0]) == pytest.approx(
        0.0, abs=1e-12
    )


def test_without_the_transform_the_networks_represent_x_itself():
    """Transform off (experiment=paper): no q, and x'' is the network's own second derivative."""
    torch.set_default_dtype(torch.float64)
    t = np.arange(0, 6.0001, 0.01)
    ag = np.sin(7 * t)
    w = make_windows(t, ag, 0.1 * np.sin(t), None, None, 3.0, 200)[1]
    assert w.q_pool is None and w.q_data is None
    net = PIDynNet(Duffing(), TaylorMLP())
    net.enter_window(w)
    k = net.kinematics(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)
    y, yd, ydd = net.rpn.taylor(w.t_pool)
    assert torch.equal(k.x, y) and torch.equal(k.a, ydd)


def test_excitation_as_acceleration():
    from pidyn.systems import ShearBuilding

    f = np.array([1.0, -2.0])
    assert np.array_equal(Duffing().excitation_as_acceleration(f), f)
    assert np.array_equal(Duffing(mass=2.0, excitation="force").excitation_as_acceleration(f), -f / 2.0)
    assert ShearBuilding(excitation="force").excitation_as_acceleration(f) is None
