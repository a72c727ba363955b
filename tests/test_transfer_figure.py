"""The transfer-function figure: measured and modelled H1 from the ground, with the coherence."""

from __future__ import annotations

import numpy as np

from pidyn.data.sources import synthetic
from pidyn.runs.transfer_figure import transfer_figure
from pidyn.simulate import simulate_response
from pidyn.systems import LinearSDOF, ShearBuilding


def test_an_accelerometer_records_peak_is_the_models_natural_frequency(tmp_path):
    system = LinearSDOF(c=0.4, k=60.0)
    rec = synthetic(system, "el_centro", duration=20.0, channels=("a",), noise=0.02)
    sim = simulate_response(system, system.true_values(), rec)
    out = transfer_figure(tmp_path / "tf.png", rec, system, sim)
    fn = np.sqrt(60.0) / (2 * np.pi)
    assert out is not None and out["channel"] == "a"
    for peak in out["peak_hz"].values():  # within the Welch resolution (segments of 5 s)
        assert abs(peak - fn) < 0.25, (peak, fn)
    assert (tmp_path / "tf.png").stat().st_size > 10_000


def test_a_building_reads_its_top_floor_and_a_short_record_draws_nothing(tmp_path):
    system = ShearBuilding(n_storeys=2)
    rec = synthetic(system, "kobe", duration=10.0, channels=("a",), sensors=[1, 2])
    sim = simulate_response(system, system.true_values(), rec)
    out = transfer_figure(tmp_path / "tf.png", rec, system, sim)
    assert out is not None and out["channel"] == "a2"
    short = synthetic(system, "kobe", duration=0.5, channels=("a",))
    assert (
        transfer_figure(
            tmp_path / "none.png", short, system, simulate_response(system, system.true_values(), short)
        )
        is None
    )
    assert not (tmp_path / "none.png").exists()
