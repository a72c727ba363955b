"""The learned storey force of an unexplained building diagnosis finds the storey whose force the
linear model misses, and predicts the held-out floor accelerations better (able to fail: a
network in the wrong storey, or one that only fits the fitting part, is not kept)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pidyn.discrepancy.storey_model import BuildingState


@pytest.mark.slow
def test_a_learned_force_goes_to_the_storey_the_linear_model_misses(tmp_path):
    from pidyn.data.sources import synthetic
    from pidyn.discrepancy.settings import LearnedSettings
    from pidyn.discrepancy.storey_learned import learned_storey_force
    from pidyn.discrepancy.storey_nominal import fundamental_hz, heldout_nrmse
    from pidyn.simulate import simulate_response
    from pidyn.systems import ShearBuilding

    linear = ShearBuilding(n_storeys=3, dampings=0.4, stiffnesses=[200.0, 160.0, 120.0])
    values = {s.name: float(s.init) for s in linear.param_specs()}
    probe = synthetic(linear, "kobe", eq_scale=1.0, duration=15.0, dt=0.02, channels=("a",))
    drift = simulate_response(linear, values, probe)["x"]
    d2 = float(np.max(np.abs(drift[:, 1] - drift[:, 0])))
    k3 = 0.6 * 160.0 / d2**2  # the cubic spring adds 60 % of storey 2's force at its largest drift
    hidden = ShearBuilding(
        n_storeys=3,
        dampings=0.4,
        stiffnesses=[200.0, 160.0, 120.0],
        storey_terms={2: [{"term": "cubic_stiffness", "k3": k3}]},
    )
    record = synthetic(hidden, "kobe", duration=15.0, dt=0.02, noise=0.01, channels=("a",))
    study = SimpleNamespace(
        record=record,
        fit=(0.0, 10.0),
        held=(10.0, 15.0),
        settings=SimpleNamespace(learned=LearnedSettings(max_evaluations=10)),
    )
    current = BuildingState(linear, values, heldout_nrmse(record, linear, values, study.held))
    out = learned_storey_force(
        study, current, None, tmp_path, 1.0 / fundamental_hz(linear, values), heldout_nrmse
    )
    assert out is not None and out["storeys_tried"] == [1, 2, 3]
    assert out["storey"] == 2, out["fit_loss_ratio"]
    assert out["kept"] and out["heldout_after"] < 0.5 * out["heldout_before"], (
        out["heldout_before"],
        out["heldout_after"],
    )
    assert (tmp_path / "learned_force.pt").exists()


@pytest.mark.parametrize(
    ("ratios", "ordered", "expected"),
    [
        ((0.822, 0.803), True, 0),  # within the margin: the score test's first stays
        ((0.822, 0.70), True, 1),  # clearly lower: the brief fit decides
        ((0.822, 0.803), False, 1),  # no order given (every storey): the lowest
        ((0.40, 0.70), True, 0),
    ],
)
def test_a_brief_fit_overrules_the_score_tests_order_only_by_the_margin(ratios, ordered, expected):
    from pidyn.discrepancy.storey_learned import _chosen

    tried = [(r, i + 1, None, None) for i, r in enumerate(ratios)]
    assert _chosen(tried, ordered, 0.1) is tried[expected]
