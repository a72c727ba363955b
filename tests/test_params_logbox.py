"""The ``logbox`` transform: a positive ratio held between two bounds, like ``log`` inside them."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pidyn.autodiff import Dual
from pidyn.config import make_system
from pidyn.params import ParamSpec, dvalue_draw, from_raw, from_theta, to_raw, to_theta


def test_logbox_round_trips_and_never_leaves_its_bounds():
    s = ParamSpec("m2", init=1.0, scale=1.0, transform="logbox", lower=0.1, upper=10.0)
    for v in (0.11, 0.5, 1.0, 3.0, 9.9):
        raw = to_raw(s, v)
        assert float(from_raw(s, torch.tensor(raw, dtype=torch.float64))) == pytest.approx(v, rel=1e-12)
        assert from_theta([s], np.array([raw]))["m2"] == pytest.approx(v, rel=1e-12)
    assert to_raw(s, 1.0) == pytest.approx(0.0)  # the geometric middle of the bounds
    # about as sensitive as log at the middle: d value / d raw = ln(100) / 4 at 1
    assert dvalue_draw(s, 0.0) == pytest.approx(np.log(100.0) / 4)
    for raw in (-50.0, 50.0):
        v = float(from_raw(s, torch.tensor(raw, dtype=torch.float64)))
        assert 0.1 * (1 - 1e-12) <= v <= 10.0 * (1 + 1e-12)
    with pytest.raises(ValueError, match="logbox"):
        ParamSpec("m2", init=1.0, transform="logbox", lower=0.0, upper=10.0)


def test_logbox_gives_exact_derivatives_through_dual_numbers():
    s = ParamSpec("m2", init=1.0, scale=1.0, transform="logbox", lower=0.1, upper=10.0)
    th = Dual(np.array([0.3]), np.array([[1.0]]))
    out = from_theta([s], [th[0]])["m2"]
    assert float(np.ravel(out.d)[0]) == pytest.approx(dvalue_draw(s, 0.3), rel=1e-10)


def test_a_building_with_unknown_masses_holds_its_mass_ratios():
    b = make_system("shear_building", n_storeys=3, masses="unknown")
    specs = {s.name: s for s in b.param_specs()}
    assert specs["m2"].transform == "logbox" and (specs["m2"].lower, specs["m2"].upper) == (0.1, 10.0)
    assert to_theta([specs["m2"]], {"m2": 0.0098})[0] < -10  # clipped to the bound, never below it
