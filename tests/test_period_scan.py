"""The scan of the period: a family that moves every period together, and a refinement that leaves
a basin its start lay in when another period fits the record better."""

from dataclasses import replace

import numpy as np
import pytest

from pidyn.data.sources import synthetic
from pidyn.notes import codes
from pidyn.refine import RefineSettings, refine
from pidyn.refine.period_scan import scaled, scan_period
from pidyn.systems import Duffing, LinearSDOF, ShearBuilding
from pidyn.systems.modal import linear_matrices, modal_properties
from pidyn.systems.modes import ModesOnSupports
from pidyn.systems.sdof import SDOFSystem

SYSTEMS = {
    "sdof": lambda: LinearSDOF(c=0.5, k=15.0),
    "three supports": lambda: SDOFSystem(LinearSDOF().terms, inputs=["a", "b", "c"]),
    "building": lambda: ShearBuilding(3),
    "modes": lambda: ModesOnSupports(2, inputs=["a", "b"]),
}


@pytest.mark.parametrize("name", list(SYSTEMS))
def test_the_family_moves_every_period_and_keeps_the_damping_ratios(name):
    system = SYSTEMS[name]()
    values = {s.name: float(s.init) for s in system.param_specs()}
    powers = system.period_scaling()
    assert powers and set(powers) <= set(values)
    before = modal_properties(*linear_matrices(system, values))
    after = modal_properties(*linear_matrices(system, scaled(values, powers, 1.7)))
    np.testing.assert_allclose(np.array(after["period_s"]) * 1.7, before["period_s"], rtol=1e-12)
    np.testing.assert_allclose(after["damping_ratio"], before["damping_ratio"], rtol=1e-12)


def test_a_nonlinear_model_has_no_family_and_no_scan():
    system = Duffing()
    record = synthetic(system, "el_centro", duration=5.0, dt=0.02, channels=("a",))
    assert system.period_scaling() == {}
    assert scan_period(system, record, system.true_values()) is None


def _two_modes(weight: float) -> object:
    """Accelerations of two modes (0.30 s and 0.18 s, 5 % damped) seen by one sensor: one
    degree of freedom fits either; with ``weight`` 0.7 on the slower one the faster fits better."""

    def mode(period: float):
        k = (2 * np.pi / period) ** 2
        return synthetic(
            LinearSDOF(c=0.1 * np.sqrt(k), k=k), "el_centro", duration=20.0, dt=0.02, channels=("a",)
        )

    slow, fast = mode(0.30), mode(0.18)
    a = weight * slow.a + fast.a
    a = a + 0.02 * np.std(a) * np.random.default_rng(0).standard_normal(a.shape)
    return replace(fast, a=a, truth=None, clean=None)


def test_the_refinement_leaves_a_basin_that_another_period_beats():
    record = _two_modes(0.7)
    system = LinearSDOF(c=0.5, k=10.0)
    k = (2 * np.pi / 0.30) ** 2
    start = {"guess": {"c": 0.1 * np.sqrt(k), "k": k}}
    local = refine(system, record, start, RefineSettings(states="simulated", period_scan=False))
    assert 2 * np.pi / np.sqrt(local.params["k"]) == pytest.approx(0.30, rel=0.01)  # stuck where it began
    res = refine(system, record, start, RefineSettings(states="simulated"))
    assert 2 * np.pi / np.sqrt(res.params["k"]) == pytest.approx(0.18, rel=0.01)
    assert res.start == "period_scan" and "period_scan_moved" in codes(res.notes), res.notes
    scan = res.period_scan
    assert scan["best_ratio"] == pytest.approx(0.6, rel=0.06) and scan["cost"] < scan["estimate_cost"]


def test_the_refinement_keeps_an_estimate_in_the_lowest_basin():
    record = _two_modes(0.3)  # the faster mode dominates: its basin is the lowest
    system = LinearSDOF(c=0.5, k=10.0)
    k = (2 * np.pi / 0.18) ** 2
    res = refine(
        system, record, {"guess": {"c": 0.1 * np.sqrt(k), "k": k}}, RefineSettings(states="simulated")
    )
    assert res.start == "guess" and "period_scan_moved" not in codes(res.notes)
    scan = res.period_scan
    assert scan["values"] is None and scan["best_ratio"] == 1.0, scan
    assert len(scan["costs"]) == len(scan["period_ratios"]) and scan["held"] == ["k"]


def test_a_point_that_does_not_simulate_is_null_in_the_run_folder():
    import json

    from pidyn.refine.period_scan import PeriodScan

    scan = PeriodScan([0.5, 1.0], [float("inf"), 2.0], 2.0, 1.0, held=["k"])
    text = json.dumps(scan.to_dict(), allow_nan=False)
    assert json.loads(text)["costs"] == [None, 2.0]
