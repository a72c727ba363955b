"""The field's figures of a measured record: the subspace realization behind the stabilisation
diagram and the peers' mode shapes, the diagram's classes, the mode shapes beside the peers' with
MAC, and the period and damping against the amplitude."""

from dataclasses import replace

import numpy as np
import pytest

from pidyn.baselines.peers import io_arrays
from pidyn.baselines.subspace import Pole, mpc, poles, real_shape
from pidyn.data.sources import synthetic
from pidyn.runs.amplitude_figure import amplitude_figure, linear_part
from pidyn.runs.mode_shape_figure import mode_shape_figure
from pidyn.runs.stabilization_figure import classify, stabilization_figure, stable_modes
from pidyn.simulate import simulate_response
from pidyn.systems import LinearSDOF, ShearBuilding
from pidyn.systems.modal import mac, modal_properties, modes_with_intervals


@pytest.fixture(scope="module")
def building():
    sb = ShearBuilding(n_storeys=3)
    rec = synthetic(sb, "el_centro", duration=20.0, channels=("a",), noise={"a": 0.02}, data_seed=1)
    return sb, replace(rec, truth=None, clean=None)


def test_the_subspace_fit_finds_a_buildings_modes_and_shapes(building):
    sb, rec = building
    true = modal_properties(*sb.linear_matrices(sb.true_values()))
    U, Y = io_arrays(rec)
    table = poles(U, Y, rec.dt, [2, 4, 6, 8])
    found = table[6]
    assert len(found) == 3
    for p, f, z, shape in zip(found, true["frequency_hz"], true["damping_ratio"], true["mode_shapes"]):
        assert p.frequency_hz == pytest.approx(f, rel=2e-3)
        assert p.damping_ratio == pytest.approx(z, rel=0.1)
        assert mac(p.shape, shape) > 0.999 and p.mpc > 0.99
        assert real_shape(p.shape)[-1] == pytest.approx(1.0)


def test_mpc_and_mac_of_known_shapes():
    real = np.array([0.3, 0.7, 1.0])
    assert mpc(real * np.exp(0.4j)) == pytest.approx(1.0)
    assert mpc(np.array([1.0, 1j])) == pytest.approx(0.0, abs=1e-12)  # two components 90 degrees apart
    assert mac(real, 2 * real * np.exp(1.1j)) == pytest.approx(1.0)
    assert mac(np.array([1.0, 0.0]), np.array([0.0, 1.0])) == pytest.approx(0.0)
    assert real_shape(real * np.exp(2.0j)) == pytest.approx(real / real[-1])


def test_a_pole_is_stable_only_when_frequency_damping_and_shape_hold():
    s = np.array([1.0, 2.0])
    table = {
        2: [Pole(2, 1.0, 0.02, s, 1.0)],
        4: [Pole(4, 1.005, 0.0205, s, 1.0), Pole(4, 7.0, 0.02, s, 1.0)],
        6: [Pole(6, 1.006, 0.03, s, 1.0), Pole(6, 7.02, 0.02, s, 1.0)],
        8: [Pole(8, 1.007, 0.03, np.array([2.0, -1.0]), 1.0), Pole(8, 7.03, 0.8, s, 1.0)],
    }
    classes = [(p.order, round(p.frequency_hz, 3), c) for p, c in classify(table)]
    assert classes == [
        (2, 1.0, "new"),
        (4, 1.005, "stable"),
        (4, 7.0, "new"),
        (6, 1.006, "frequency"),  # damping moved by half
        (6, 7.02, "stable"),
        (8, 1.007, "frequency and damping"),  # the shape turned
    ]  # the 80 % damped pole is no mode: not drawn
    assert stable_modes(classify(table), min_orders=1)[0]["orders"] == [4]


def test_the_stabilization_diagram_of_a_measured_building_stands_at_its_modes(building, tmp_path):
    sb, rec = building
    out = stabilization_figure(tmp_path / "stabilization.png", rec, sb.n_dof)
    assert (tmp_path / "stabilization.png").stat().st_size > 10_000
    true = modal_properties(*sb.linear_matrices(sb.true_values()))["frequency_hz"]
    found = [m["frequency_hz"] for m in out["stable_modes"]]
    for f in true:
        assert min(abs(g - f) / f for g in found) < 0.01
    assert all(len(m["orders"]) >= 3 for m in out["stable_modes"])


def test_mode_shapes_beside_the_peers_with_mac(building, tmp_path):
    sb, rec = building
    modes = modes_with_intervals(sb, sb.true_values())
    rows = mode_shape_figure(tmp_path / "mode_shapes.png", rec, modes)
    assert (tmp_path / "mode_shapes.png").stat().st_size > 10_000
    assert [r["mode"] for r in rows] == [1, 2, 3]
    for r, m in zip(rows, modes):
        assert r["subspace"]["mac"] > 0.999
        assert r["subspace"]["frequency_hz"] == pytest.approx(m["frequency_hz"], rel=5e-3)
    # SRIM's modes as the peers' row keeps them (mode_shape at the outputs, longest period first)
    srim = [{"frequency_hz": m["frequency_hz"] * 1.01, "mode_shape": m["mode_shape"]} for m in modes[::-1]]
    rows = mode_shape_figure(tmp_path / "mode_shapes.png", rec, modes, srim)
    assert [r["SRIM"]["frequency_hz"] for r in rows] == pytest.approx(
        [1.01 * m["frequency_hz"] for m in modes]
    )
    assert all(r["SRIM"]["mac"] == pytest.approx(1.0) for r in rows)
    # a single degree of freedom has no shape to compare
    assert mode_shape_figure(tmp_path / "none.png", rec, modes[:1]) is None


def test_period_against_amplitude_is_flat_for_a_linear_structure(tmp_path):
    sdof = LinearSDOF(c=0.6, k=400.0)
    rec = synthetic(sdof, "el_centro", noise=0.01, channels=("a",), duration=25.0)
    measured = replace(rec, truth=None, clean=None)
    values = sdof.true_values()
    sim = simulate_response(sdof, values, measured)
    period = 2 * np.pi / np.sqrt(400.0)
    out = amplitude_figure(tmp_path / "period_vs_amplitude.png", measured, sdof, values, sim, period)
    assert (tmp_path / "period_vs_amplitude.png").stat().st_size > 10_000
    assert len(out["period"]) >= 4 and out["unit"]
    inside = [lo <= period <= hi for lo, hi in zip(out["period_lo"], out["period_hi"])]
    assert np.mean(inside) >= 0.75
    # a simulated record is held to its truth, not drawn
    assert amplitude_figure(tmp_path / "x.png", rec, sdof, values, sim, period) is None
    assert linear_part(sdof) is sdof


def test_srims_modes_keep_their_shapes_mpc_and_emac(building, tmp_path):
    pytest.importorskip("mdof")
    from pidyn.baselines.peers import srim

    sb, rec = building
    res = srim(rec, orders=(6,))
    true = modal_properties(*sb.linear_matrices(sb.true_values()))
    for m, shape in zip(res.modes, true["mode_shapes"]):  # fundamental first
        assert mac(m["mode_shape"], shape) > 0.99 and 0.9 < m["mpc"] <= 1.0 and np.isfinite(m["emac"])
    # a run that did not fit SRIM: the figure fits it itself, at the model's number of modes
    rows = mode_shape_figure(tmp_path / "m.png", rec, modes_with_intervals(sb, sb.true_values()))
    assert all(r["SRIM"]["mac"] > 0.99 for r in rows), rows


def test_the_amplitude_law_is_drawn_through_the_windows_of_a_softening_structure(tmp_path):
    """A structure whose stiffness falls with its recent amplitude (AmplitudeSoftening): the
    windows' periods rise with the shaking's peak, and the law's own period at each window's
    simulated envelope follows them."""
    from pidyn.systems import AmplitudeDependent

    sys_ = AmplitudeDependent(c=0.6, k=400.0, soft=0.4, gain=0.5, tau=1.0, a_ref=0.05, w0=20.0)
    rec = synthetic(sys_, "el_centro", noise=0.01, channels=("a",), duration=25.0, eq_scale=2.0)
    measured = replace(rec, truth=None, clean=None)
    values = sys_.true_values()
    sim = simulate_response(sys_, values, measured)
    out = amplitude_figure(tmp_path / "p.png", measured, sys_, values, sim, 2 * np.pi / np.sqrt(400.0))
    assert (tmp_path / "p.png").stat().st_size > 10_000 and len(out["law_period"]) == len(out["period"])
    peak, period, law = (np.asarray(out[k]) for k in ("peak", "period", "law_period"))
    strong, weak = peak >= np.quantile(peak, 0.75), peak <= np.quantile(peak, 0.25)
    assert period[strong].mean() > period[weak].mean() and law[strong].mean() > law[weak].mean()
    assert np.corrcoef(period, law)[0, 1] > 0.5
