"""The adequacy test: a model that describes its record passes, one that does not (a response
unrelated to the input, an input in the wrong units, a model that diverges, a prediction worse
than knowing nothing) fails with its reason in words; the trivial predictions; the one-sided
interval of a parameter on its bound."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pidyn import Record
from pidyn.adequacy import (
    AdequacySettings,
    check_adequacy,
    describe,
    ljung_box,
    trivial_predictions,
)
from pidyn.config import make_system
from pidyn.simulate import rk4_stability, simulate_response


def _record(noise: float = 0.02, channels=("x", "v")) -> Record:
    return Record.simulate("linear", excitation="el_centro", duration=20, noise=noise, channels=channels)


def _sim(record: Record, **values) -> dict[str, np.ndarray]:
    system = make_system("linear")
    return simulate_response(system, {**record.truth, **values}, record)


def test_the_true_model_is_adequate_and_a_wrong_one_is_not():
    rec = _record()
    good = check_adequacy(_sim(rec), rec, (0.0, 14.0), (14.0, 20.0))
    assert good["adequate"] and good["explains"] and good["predicts"] and good["within_noise"], good[
        "reasons"
    ]
    assert good["fit_nrmse"] < 0.03 and good["trivial"] == "at rest"
    # a model 30 % too stiff still "explains" most of the response, but not within the declared noise
    stiff = check_adequacy(_sim(rec, k=rec.truth["k"] * 1.3), rec, (0.0, 14.0), (14.0, 20.0))
    assert not stiff["adequate"] and stiff["within_noise"] is False
    assert "declared noise" in describe(stiff) and "DOES NOT DESCRIBE" in describe(stiff)


def test_a_response_unrelated_to_the_input_is_not_explained():
    rec = _record(noise=0.0)
    rng = np.random.default_rng(0)
    noise = replace(
        rec,
        x=rng.normal(size=rec.x.shape) * np.std(rec.x),
        v=rng.normal(size=rec.v.shape) * np.std(rec.v),
        clean=None,
        meta={},
    )
    out = check_adequacy(_sim(rec), noise, (0.0, 14.0), (14.0, 20.0))
    assert not out["adequate"] and not out["explains"] and out["predicts"] is False
    assert out["within_noise"] is None  # a measurement declares no noise
    assert out["fit_nrmse"] > 1.0 and any("knowing nothing" in r for r in out["reasons"])


def test_a_diverging_model_fails_as_such():
    rec = _record()
    sim = _sim(rec)
    sim["x"] = sim["x"].copy()
    sim["x"][-10:] = np.inf
    out = check_adequacy(sim, rec, (0.0, 20.0))
    assert not out["adequate"] and not out["simulates"] and "diverges" in out["reasons"][0]


def test_an_accelerometer_is_scored_against_the_structure_moving_with_its_support():
    rec = _record(channels=("a",))
    triv = trivial_predictions(rec, (0.0, 14.0))
    label, series = triv["a"]
    assert label == "moving with ground" and np.allclose(series, rec.f)
    out = check_adequacy(_sim(rec), rec, (0.0, 14.0), (14.0, 20.0))
    assert out["adequate"], out["reasons"]
    # predicting the ground's own acceleration is what "moving with the support" scores
    row = out["channels"]["a"]
    meas = rec.a[:, 0] + rec.f
    m = rec.t >= 14.0 - 1e-9
    expected = np.sqrt(np.mean((rec.f[m] - meas[m]) ** 2)) / np.std(meas[m])
    assert row["trivial_heldout_nrmse"] == pytest.approx(expected)


def test_a_prediction_worse_than_rest_on_the_held_out_part_is_flagged():
    rec = _record(noise=0.0)
    # the true model on the fitting part; the held-out part's response turned over (a model out of
    # phase there predicts it worse than rest does)
    bent = replace(rec, x=np.where(rec.t[:, None] > 14.0, -rec.x, rec.x), v=None, clean=None, meta={})
    out = check_adequacy(_sim(rec), bent, (0.0, 14.0), (14.0, 20.0))
    assert out["explains"] and out["predicts"] is False and not out["adequate"]
    assert out["heldout_nrmse"] > out["trivial_heldout_nrmse"]


def test_ljung_box_passes_white_noise_and_rejects_a_smooth_error():
    rng = np.random.default_rng(1)
    assert ljung_box(rng.normal(size=2000), 20)[1] > 0.01
    smooth = np.convolve(rng.normal(size=2000), np.ones(25) / 25, mode="same")
    assert ljung_box(smooth, 20)[1] < 1e-6


def test_settings_are_ordered_limits():
    s = AdequacySettings()
    assert 0 < s.max_fit_nrmse < 1 and s.noise_tolerance > 1 and s.noise_floor_nrmse > 0


def test_a_model_too_stiff_for_the_integrator_step_is_refused_by_name():
    system = make_system("shear_building", n_storeys=3)
    values = system.true_values()
    ok = rk4_stability(system, values, 0.02)
    assert ok is not None and ok["stable"]
    # a storey of a hundredth of a gram and huge damping: a rate of about 5e4 per second
    bad = {**values, "m2": 1e-5, "c2": 547.0}
    out = rk4_stability(system, bad, 1 / 120)
    assert not out["stable"] and out["max_abs_lambda_h"] > 2.8
    rec = _record()
    res = check_adequacy(_sim(rec), rec, (0.0, 20.0), stability=out)
    assert not res["adequate"] and not res["simulates"] and "RK4 stability region" in res["reasons"][0]


def test_a_quiet_fitting_part_does_not_reject_the_true_model():
    """Chi-Chi TCU078's first 20 s barely move: there the noise alone misses more than half of the
    fitting part, and the true model must still pass; a model off by 30 % must not."""
    rec = Record.simulate("linear", excitation="chichi", duration=30, noise=0.025, channels=("x", "v"))
    out = check_adequacy(_sim(rec), rec, (0.0, 19.5), (19.5, 30.0))
    assert out["fit_nrmse"] > 0.5 and out["adequate"], out["reasons"]
    off = check_adequacy(_sim(rec, k=rec.truth["k"] * 1.3), rec, (0.0, 19.5), (19.5, 30.0))
    assert not off["adequate"] and "held-out part" in " ".join(off["reasons"])


def test_a_nominal_model_worse_than_knowing_nothing_is_never_said_to_hold():
    from types import SimpleNamespace

    from pidyn.discrepancy.result import trivial_note
    from pidyn.discrepancy.summary import _verdict
    from pidyn.discrepancy.verdicts import Verdict

    gain = {"nominal": 1.37, "trivial": 1.0, "trivial_label": "at rest", "nominal_beats_trivial": False}
    text = trivial_note(gain)
    assert "worse than knowing nothing" in text and "[worse_than_trivial]" in text
    assert trivial_note({**gain, "nominal": 0.3, "nominal_beats_trivial": True}) is None
    clean = SimpleNamespace(
        screening=SimpleNamespace(verdict=Verdict.NONE),
        check=SimpleNamespace(failed=False),
        running=None,
        cause=None,
    )
    case = SimpleNamespace(from_accelerometers=False)
    assert _verdict(case, clean, False, False) == Verdict.NONE
    assert _verdict(case, clean, False, False, worse=True) == Verdict.UNEXPLAINED


def test_a_storey_overdamped_on_its_own_is_simulated_with_the_steps_it_needs():
    """The stiff shake-table building's fit from Northridge: storey 3's dashpot 1.8 times critical
    on its own, a real rate of 1337 per second, just beyond four RK4 steps per sample at 120 Hz
    (|lambda h| = 2.79). It is a model, not a numerical accident: its exact solution (matrix
    exponentials) fits its record, so the simulator takes five steps, matches that solution and
    the adequacy test judges the fit."""
    from scipy.signal import StateSpace, lsim

    from pidyn.simulate import stable_substeps

    system = make_system("shear_building", n_storeys=3)
    values = {
        **system.true_values(),
        "m1": 1.0, "m2": 0.7612, "m3": 1.2823, "c1": 0.0, "c2": 0.0, "c3": 661.55,
        "k1": 13336.2, "k2": 9397.9, "k3": 26915.9,
    }  # fmt: skip
    dt = 1 / 120
    assert not rk4_stability(system, values, dt, 4)["stable"]
    assert stable_substeps(system, values, dt) == 5
    judged = rk4_stability(system, values, dt, substeps=None)
    assert judged["stable"] and judged["substeps"] == 5

    t = np.arange(0, 20, dt)
    rng = np.random.default_rng(3)
    ag = np.convolve(rng.normal(size=len(t)), np.hanning(9) / 4, mode="same")  # below 15 Hz mostly
    rec = Record(name="overdamped storey", t=t, f=ag, a=np.zeros((len(t), 3)), excitation="ground")
    sim = simulate_response(system, values, rec)
    assert np.all(np.isfinite(sim["x"]))
    M = np.diag([values["m1"], values["m2"], values["m3"]])
    C, K = (
        np.array([[a + b, -b, 0], [-b, b + c, -c], [0, -c, c]])
        for a, b, c in (
            (values["c1"], values["c2"], values["c3"]),
            (values["k1"], values["k2"], values["k3"]),
        )
    )
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-Mi @ K, -Mi @ C]])
    B = np.concatenate([np.zeros(3), -np.ones(3)])[:, None]
    _, _, states = lsim(StateSpace(A, B, np.eye(6), np.zeros((6, 1))), ag, t, interp=True)
    err = np.max(np.abs(sim["x"] - states[:, :3])) / np.max(np.abs(states[:, :3]))
    assert err < 1e-3

    # a storey of a hundredth of a gram needs far more than MAX_SUBSTEPS: still refused, at that limit
    tiny = rk4_stability(system, {**values, "m2": 1e-5, "c2": 547.0}, dt, substeps=None)
    assert not tiny["stable"] and tiny["substeps"] == 32
