"""The start from the data of a building with floors unmeasured: a frequency scan of the
config's stiffness profile, not the transmissibility's peak (which a 20 s record resolves to
0.2 Hz and which sat on the second mode)."""

from __future__ import annotations

import pytest

from pidyn.baselines.data_start import fundamental, start_from_data
from pidyn.data.sources import synthetic
from pidyn.systems.modal import linear_matrices, modal_properties
from pidyn.systems.shear_building import ShearBuilding

MASSES, STIFF = [1.108, 1.061, 1.016, 1.081], [237.63, 198.03, 158.42, 118.82]


def f1(system: ShearBuilding, values: dict[str, float]) -> float:
    return float(modal_properties(*linear_matrices(system, values))["frequency_hz"][0])


def test_a_building_with_a_floor_unmeasured_starts_at_its_fundamental():
    true = ShearBuilding(4, MASSES, [0.6, 0.55, 0.5, 0.45], STIFF)
    rec = synthetic(
        true, "san_fernando", duration=20.0, dt=0.02, noise=0.03, channels=("a",), sensors=[1, 2, 4]
    )
    truth = f1(true, true.true_values())
    nominal = ShearBuilding(4, MASSES)  # the config's guesses: stiffness tapering, two seconds
    start = start_from_data(rec.segment(0.0, 13.0), nominal)
    assert start is not None and start.method == "frequency_scan", start
    assert start.frequency_hz == pytest.approx(truth, rel=0.08)
    values = {**{s.name: float(s.init) for s in nominal.param_specs()}, **start.values}
    assert f1(nominal, values) == pytest.approx(truth, rel=0.08)
    for i, k in enumerate(STIFF, start=1):
        assert values[f"k{i}"] == pytest.approx(k, rel=0.15)
    peak = fundamental(rec.segment(0.0, 13.0))
    assert peak is not None and peak[0] > 1.5 * truth  # the transmissibility alone was a mode off
