import math

import pytest
import torch

from pidyn.callbacks import ParameterClamp, ParameterEarlyStopping
from pidyn.models.lit_module import PIDynNetModule
from pidyn.models.pidynnet import PIDynNet
from pidyn.nets import TaylorMLP
from pidyn.systems import Duffing


def module():
    return PIDynNetModule(PIDynNet(Duffing(), TaylorMLP()))


def test_clamp_box_is_three_sigma_of_previous_window_trajectory():
    clamp = ParameterClamp(n_sigma=3.0, min_rel_width=0.0)
    traj = torch.tensor([[0.4, 14.0], [0.5, 15.0], [0.6, 16.0]])
    clamp.update_from_trajectory(["c", "k1"], traj, {"c": 0.5, "k1": 15.0})
    sd = traj.std(0)
    assert clamp.bounds["c"] == pytest.approx((0.5 - 3 * float(sd[0]), 0.5 + 3 * float(sd[0])))
    assert clamp.bounds["k1"] == pytest.approx((15 - 3 * float(sd[1]), 15 + 3 * float(sd[1])))


def test_clamp_projects_parameters_into_the_box_and_floor_applies():
    m = module()
    clamp = ParameterClamp(n_sigma=3.0, min_rel_width=0.1)
    flat = torch.tensor([[0.5, 15.0, 120.0]] * 5)  # a flat trajectory: sigma = 0
    clamp.update_from_trajectory(["c", "k1", "k3"], flat, {"c": 0.5, "k1": 15.0, "k3": 120.0})
    assert clamp.bounds["k3"] == pytest.approx((108.0, 132.0))  # the 10 % floor, not a zero-width box
    m.net.params.set_values({"c": 2.0, "k1": 15.5, "k3": 50.0})
    moved = clamp.apply(m)
    v = m.net.params.as_floats()
    assert moved == 2
    assert v["c"] == pytest.approx(0.55, rel=1e-5) and v["k3"] == pytest.approx(108.0, rel=1e-5)
    assert v["k1"] == pytest.approx(15.5, rel=1e-5)  # inside the box: untouched


def test_literal_clamp_locks_a_flat_trajectory():
    clamp = ParameterClamp(n_sigma=3.0, min_rel_width=0.0)
    clamp.update_from_trajectory(["c"], torch.tensor([[0.7]] * 4), {"c": 0.7})
    lo, hi = clamp.bounds["c"]
    assert lo == hi == pytest.approx(0.7)


def test_clamp_box_opens_for_a_parameter_the_windows_did_not_determine():
    """A flat trajectory of an undetermined k3 (posterior std 2 in log k3) must not lock it: the
    box spans exp(+-6) around it, in its log coordinate; a determined c keeps its tight box."""
    m = module()
    specs = {n: m.net.params.spec(n) for n in ("c", "k3")}
    clamp = ParameterClamp(n_sigma=3.0, min_rel_width=0.05)
    flat = torch.tensor([[0.5, 50.0]] * 5)
    clamp.update_from_trajectory(["c", "k3"], flat, {"c": 0.5, "k3": 50.0}, {"c": 1e-4, "k3": 2.0}, specs)
    lo, hi = clamp.bounds["k3"]
    assert lo == pytest.approx(50.0 * math.exp(-6.0), rel=1e-6) and hi == pytest.approx(
        50.0 * math.exp(6.0), rel=1e-6
    )
    assert clamp.bounds["c"] == pytest.approx((0.475, 0.525))  # the floor; 3 x 1e-4 in log c is inside it
    m.net.params.set_values({"c": 0.5, "k3": 400.0})
    assert clamp.apply(m) == 0  # the truth of k3 is reachable


def test_early_stopping_eq10_fixed_reference():
    es = ParameterEarlyStopping(check_every=100, eps=1e-3, patience=3, start=0, reference="fixed")
    base = torch.tensor([1.0, 10.0])
    assert not es.check(base)  # sets the reference theta_{N0}
    # drifting slowly: each step 0.04 % but the distance to the fixed reference grows past eps
    seq = [base * (1 + 4e-4 * i) for i in range(1, 6)]
    fired = [es.check(s) for s in seq]
    # checks 1, 2 pass (< 1e-3), check 3 (1.2e-3) fails and resets the reference, so no stop yet
    assert fired[:3] == [False, False, False]
    assert es.passed == 2 or es.passed == 1


def test_early_stopping_stops_after_n_successive_quiet_checks():
    es = ParameterEarlyStopping(check_every=100, eps=1e-4, patience=3, start=0, space="raw", smooth=1)
    theta = torch.tensor([0.5, 15.0, 120.0])
    assert not es.check(theta)
    assert not es.check(theta * (1 + 1e-6))
    assert not es.check(theta * (1 - 1e-6))
    assert es.check(theta)


def test_early_stopping_resets_on_a_jump():
    es = ParameterEarlyStopping(check_every=100, eps=1e-4, patience=2, start=0, space="raw", smooth=1)
    theta = torch.tensor([1.0])
    es.check(theta)
    es.check(theta)
    assert not es.check(theta * 1.1)  # a jump resets the count
    assert not es.check(theta * 1.1)
    assert es.check(theta * 1.1)
