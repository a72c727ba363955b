"""Wearable IMUs on a shake-table building (data=xsens): the reader's named errors, the clocks'
alignment and the shaking axis recovered from copies changed on purpose, and a building whose
masses are unknown identified for what its records determine."""

from __future__ import annotations

import gzip
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pidyn.data.imu import (
    ImuFormatError,
    align_floors,
    along,
    read_xsens,
    run_files,
    run_labels,
    shaking_axis,
    xsens_record,
)

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "data" / "mini_shake_table"
STIFF3 = MODELS / "Stiff 3 story"


def _rotation(yaw_deg: float, tilt_deg: float) -> np.ndarray:
    y, t = np.radians(yaw_deg), np.radians(tilt_deg)
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    return rx @ rz


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal below 10 Hz (where interpolating twice at 120 Hz is exact enough)."""
    from pidyn.signals import band

    return float(np.corrcoef(band(a, 1 / 120, 0.2, 10.0), band(b, 1 / 120, 0.2, 10.0))[0, 1]) > 0.999


def test_shipped_models_read_with_their_runs_and_floors():
    assert run_labels(STIFF3) == ["Northridge", "Sine 1.5"]
    assert run_labels(MODELS / "Stiff 1 story")[0] == "El Centro Trial 1"
    rec = xsens_record(STIFF3, "Northridge", fit_share=0.65)
    assert rec.a.shape[1] == 3 and rec.dt == pytest.approx(1 / 120, rel=1e-3)
    assert rec.meta.floors == ["Ground Floor", "1st Floor", "2nd Floor", "3rd Floor (Top floor)"]
    assert rec.meta.alignment.coarse == "clock" and np.isfinite(rec.a).all()
    assert 5.0 < rec.meta.pga < 12.0  # m/s^2, gravity off
    assert rec.meta.split.fit[1] == pytest.approx(0.65 * rec.t[-1])


def test_named_errors_for_a_missing_floor_a_broken_file_and_an_unknown_run(tmp_path):
    model = tmp_path / "model"
    shutil.copytree(STIFF3, model)
    with pytest.raises(ImuFormatError, match="no run labelled 'Kobe'.*Northridge"):
        xsens_record(model, "Kobe")
    with pytest.raises(ImuFormatError, match="3 floor.*the model has 2 storey"):
        xsens_record(model, "Northridge", n_storeys=2)
    floor2 = next((model / "2nd Floor").glob("(Northridge)*"))
    lines = gzip.open(floor2, "rt").read().splitlines()
    lines[300] = "299,123,abc,1.0,9.8"
    with gzip.open(floor2, "wt") as fh:
        fh.write("\n".join(lines))
    with pytest.raises(ImuFormatError, match=r"2nd Floor.*\(Northridge\).*non-numeric"):
        xsens_record(model, "Northridge")
    shutil.rmtree(model / "2nd Floor")
    with pytest.raises(ImuFormatError, match="floors \\[0, 1, 3\\]: a floor between"):
        run_files(model, "Northridge")


def test_the_alignment_recovers_lags_put_in_on_purpose():
    """A floor whose samples come 0.3712 s late on a clock of its own (StartTime the same second):
    placed by StartTime, its low-band lag finds the offset to within half a sample. A floor 19 ms
    late on the shared clock: align=lag finds it and moves it back."""
    files = run_files(STIFF3, "Northridge")
    imus = [read_xsens(f) for _, f in files]
    axes = [shaking_axis(m.acc) for m in imus]
    _, ref, rep0 = align_floors(imus, axes, "clock")
    late = 0.3712
    m = imus[1]
    shifted = np.stack([np.interp(m.t + late, m.t, m.acc[:, j]) for j in range(3)], axis=1)
    unsynced = replace(m, acc=shifted, clock0_us=m.clock0_us + 4.1e9)  # another clock altogether
    _, data, rep = align_floors([imus[0], unsynced, *imus[2:]], axes, "clock")
    assert rep.coarse == "start_time"
    assert rep.applied_ms[1] == pytest.approx(1e3 * late - rep0.lag_ms[1], abs=1e3 / 240)  # it started late
    k = int(round(rep.start_s * 120))  # the common part starts where the late floor does
    n = min(len(data), len(ref) - k)
    assert _same(data[:n, 1], ref[k : k + n, 1])
    delayed = replace(m, acc=np.stack([np.interp(m.t - 0.019, m.t, m.acc[:, j]) for j in range(3)], axis=1))
    _, moved, rep = align_floors([imus[0], delayed, *imus[2:]], axes, "lag")
    assert rep.coarse == "clock" and rep.lag_ms[1] == pytest.approx(19.0 + rep0.lag_ms[1], abs=1.0)
    k = int(round(rep.start_s * 120))
    n = min(len(moved), len(ref) - k)
    assert _same(moved[:n, 1], ref[k : k + n, 1])


def test_axis_gravity_and_bias_come_off_a_rotated_biased_copy():
    """A floor's motion along one horizontal axis, seen by a sensor yawed 40 deg and tilted 3 deg
    with a bias on each axis: the principal axis, the gravity and the bias come off and the motion
    is back (up to its sign, which the record takes from the table)."""
    rng = np.random.default_rng(0)
    t = np.arange(0, 40, 1 / 120)
    motion = np.convolve(rng.standard_normal(len(t)), np.hanning(25), "same") * (t > 3) * (t < 35)
    world = np.stack([motion, 0.02 * rng.standard_normal(len(t)), np.full(len(t), 9.81)], axis=1)
    R = _rotation(40.0, 3.0)
    sensor = world @ R + np.array([0.05, -0.03, 0.02])
    ax = shaking_axis(sensor)
    got = along(sensor, ax, rest=slice(0, 240))
    got *= np.sign(got @ motion)
    assert ax.tilt_deg == pytest.approx(3.0, abs=0.3)
    assert np.sqrt(np.mean((got - motion) ** 2)) / np.std(motion) < 0.02


def test_masses_unknown_identify_the_frequencies_and_refuse_absolute_stiffness():
    """A 3-storey building with masses 2, 1.5, 1 kg measured by floor accelerometers, identified
    with its masses unknown: the frequencies, mass ratios and stiffness per kg of floor 1 come
    back; absolute N/m are refused without a mass and given with one."""
    from pidyn.data.sources import synthetic
    from pidyn.refine import RefineSettings, refine
    from pidyn.starts.data import start_from_data
    from pidyn.systems import ShearBuilding
    from pidyn.systems.modal import modal_properties, modes_with_intervals
    from pidyn.systems.shear_building import UnknownMassError

    known = ShearBuilding(
        3, masses=[2.0, 1.5, 1.0], stiffnesses=[400.0, 300.0, 200.0], dampings=[1.0, 0.8, 0.5]
    )
    rec = synthetic(known, "el_centro", duration=15.0, channels=("a",), noise=0.01, data_seed=2)
    free = ShearBuilding(3, masses="unknown")
    truth = free.own_units(known.true_values() | {"m1": 2.0, "m2": 1.5, "m3": 1.0})
    start = start_from_data(rec, free)
    assert start.method == "equation_error"
    res = refine(free, rec, {"start": start.values}, RefineSettings(states="integrated", segment_length=2.0))
    for n in ("m2", "m3", "k1", "k2", "k3"):
        assert res.params[n] == pytest.approx(truth[n], rel=0.02), n
    values = {"m1": 1.0, **res.params}
    modes = modes_with_intervals(free, values, res.names, np.asarray(res.covariance))
    true_f = modal_properties(
        *known.linear_matrices(known.true_values() | {"m1": 2.0, "m2": 1.5, "m3": 1.0})
    )["frequency_hz"]
    for m, f in zip(modes, true_f):
        assert m["frequency_hz"] == pytest.approx(f, rel=0.005)
        assert m["frequency_ci95"][0] < m["frequency_hz"] < m["frequency_ci95"][1]
    assert modes[0]["mode_shape"][-1] == 1.0 and len(modes[0]["mode_shape_ci95"]) == 3
    with pytest.raises(UnknownMassError, match="masses are unknown.*give floor 1's mass"):
        free.absolute_values(values)
    assert free.absolute_values(values, m1=2.0)["k1"] == pytest.approx(400.0, rel=0.02)
    specs = {s.name: s for s in free.param_specs()}
    assert not specs["m1"].trainable and specs["m2"].trainable and "per kg of m1" in specs["k1"].unit


def test_a_damping_the_draws_leave_undefined_has_no_interval_not_a_nan():
    """A damper the record does not determine (its log-variance huge, as at a bound): most draws
    overflow and have no damping ratio; the interval is none (JSON's null), never NaN, and the
    period, which the draws do determine, keeps its interval."""
    from pidyn.systems import LinearSDOF
    from pidyn.systems.modal import modes_with_intervals

    mode = modes_with_intervals(
        LinearSDOF(c=0.5, k=15.0), {"m": 1.0, "c": 0.5, "k": 15.0}, ["c", "k"], np.diag([1e6, 1e-4])
    )[0]
    assert mode["damping_ci95"] == [None, None]
    lo, hi = mode["period_ci95"]
    assert lo < mode["period_s"] < hi
