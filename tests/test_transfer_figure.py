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


def test_a_single_degree_of_freedoms_loop_is_its_force_terms_along_the_response(tmp_path):
    """The loop is the sum of the force terms at the simulated response; a building draws none."""
    from pidyn.runs.loop_figure import loop_figure, restoring_loop
    from pidyn.systems import BoucWen

    system = BoucWen()
    rec = synthetic(system, "el_centro", duration=8.0, channels=("x",))
    p = system.true_values()
    sim = simulate_response(system, p, rec)
    x, force = restoring_loop(system, p, rec.t, sim)
    clean = rec.clean
    assert np.allclose(x[:, 0], clean.x[:, 0], rtol=0, atol=1e-4 * np.abs(clean.x).max())
    # Bouc-Wen's restoring force is c x' + k z: its loop is open (energy dissipated per cycle)
    assert np.allclose(
        force[:, 0], p["c"] * clean.v[:, 0] + p["k"] * clean.z[:, 0], atol=1e-3 * np.abs(force).max()
    )
    assert loop_figure(tmp_path / "loop.png", system, p, rec, sim) and (tmp_path / "loop.png").is_file()
    building = ShearBuilding(n_storeys=2)
    assert not loop_figure(tmp_path / "no.png", building, building.true_values(), rec, sim)
