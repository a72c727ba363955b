"""How the integrator reads the excitation between samples: linear for the project's simulated
records, band-limited for a measured record sampled a few times per period (each test able to fail)."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.data.measured.silverbox import load_silverbox
from pidyn.integrate import stage_excitation
from pidyn.refine.output_error import fit_output_error
from pidyn.refine.problem import Channel, ShootingProblem, segment_bounds
from pidyn.simulate import input_hold, simulate, simulate_response, simulate_states
from pidyn.systems import Duffing, LinearSDOF

FS = 100.0
F_RES = 11.0  # 9 samples a period, as the Silverbox circuit's resonance


def _oscillator():
    w = 2 * np.pi * F_RES
    return LinearSDOF(mass=1.0, excitation="force"), {"m": 1.0, "c": 2 * 0.05 * w, "k": w**2}


def test_the_band_limited_hold_follows_a_sampled_tone_the_linear_one_attenuates():
    system, vals = _oscillator()
    t = np.arange(0, 3, 1 / FS)
    tone = lambda tt: np.sin(2 * np.pi * F_RES * np.asarray(tt))  # noqa: E731
    exact = simulate(system, vals, tone, t).x[:, 0]  # the continuous tone, tightly integrated
    inner = slice(50, 250)  # away from the interpolation filter's ends
    err = {}
    for hold in ("linear", "bandlimited"):
        Y, _ = simulate_states(system, vals, t, tone(t), substeps=4, hold=hold)
        err[hold] = np.sqrt(np.mean((Y[inner, 0] - exact[inner]) ** 2)) / np.std(exact[inner])
    # the linear hold's gain sinc(0.11)^2 = 0.96 at the tone: about 4 % of the response
    assert 0.02 < err["linear"] < 0.06
    assert err["bandlimited"] < 1e-3


def test_stage_values_lie_on_the_samples_and_an_unknown_hold_is_named():
    f = np.sin(np.linspace(0, 20, 300))
    st = stage_excitation(f, 4, "bandlimited")
    assert st.shape == (299, 9)
    np.testing.assert_allclose(st[:, 0], f[:-1], atol=1e-3)
    np.testing.assert_allclose(st[:, -1], f[1:], atol=1e-3)
    assert stage_excitation(f, 4, "linear") is None
    with pytest.raises(ValueError, match="unknown excitation hold 'cubic'"):
        stage_excitation(f, 4, "cubic")


def test_shooting_segments_cut_the_whole_records_band_limited_stages():
    """Segments started from the free run's own states continue it exactly: each segment reads
    the same stage values as the whole record, not ones interpolated from its own samples."""
    system, vals = _oscillator()
    t = np.arange(0, 4, 1 / FS)
    rng = np.random.default_rng(3)
    f = np.convolve(rng.standard_normal(len(t)), np.ones(3) / 3, mode="same")
    Y, _ = simulate_states(system, vals, t, f, substeps=4, hold="bandlimited")
    chans = [Channel("x", 0, Y[:, 0], float(np.std(Y[:, 0])))]
    bounds = segment_bounds(t, 0.5)
    prob = ShootingProblem(system, t, f, chans, bounds, 4, hold="bandlimited")
    u = prob.pack(vals, Y[bounds[:-1]])
    data, defects = prob.residuals(u)
    assert np.max(np.abs(data)) < 1e-9 and np.max(np.abs(defects)) < 1e-9
    lin = ShootingProblem(system, t, f, chans, bounds, 4)  # the linear hold misreads the same record
    assert np.max(np.abs(lin.residuals(lin.pack(vals, Y[bounds[:-1]]))[0])) > 1e-2


def test_silverbox_is_read_band_limited_and_fits_better_so():
    """On two seconds of the circuit's estimation part, the cubic model fitted by output error
    with the record's own (band-limited) hold predicts the next two seconds better than with the
    linear hold, whose fit absorbs the hold's attenuation into the mass."""
    rec = load_silverbox()  # starts at rest, in the gap before the first realisation
    assert input_hold(rec) == "bandlimited"
    fit, both = rec.segment(0.0, 2.0), rec.segment(0.0, 4.0)
    system = Duffing(mass=5.2e-6, excitation="force", identify_mass=True)
    start = {"m": 5.2e-6, "c": 2.2e-4, "k1": 0.95, "k3": 3.7}
    out = {}
    for hold in ("linear", "bandlimited"):
        fit.meta.input_hold = both.meta.input_hold = hold
        values = {**start, **fit_output_error(fit, system, init=start, max_nfev=40).params}
        sim = simulate_response(system, values, both)["x"][:, 0]
        err = (sim - both.x[:, 0])[both.t > 2.0]  # the two seconds after the fitted ones
        out[hold] = (1e3 * np.sqrt(np.mean(err**2)), values["m"])
    assert out["bandlimited"][0] < 0.6 * out["linear"][0]  # mV
    assert out["bandlimited"][1] > 1.02 * out["linear"][1]  # the linear hold's fit is 4 % light


def test_a_strong_motion_record_carries_its_hold_and_a_wrong_one_is_named():
    from pathlib import Path

    from pidyn.data.sources import DataError
    from pidyn.data.strong_motion import csmip_record

    path = (
        Path(__file__).resolve().parents[1] / "data" / "painter_street" / "records" / "riodell82_ce89324p.zip"
    )
    rec = csmip_record(path, on_missing="drop", input_hold="bandlimited")
    assert rec.meta.input_hold == "bandlimited" and rec.f.shape[1] == 4  # two supports, acc and vel
    assert stage_excitation(rec.f, 4, input_hold(rec)).shape == (len(rec.t) - 1, 9, 4)
    with pytest.raises(DataError, match="data.input_hold must be one of linear, bandlimited, got 'zoh'"):
        csmip_record(path, on_missing="drop", input_hold="zoh")


def test_the_ukf_reads_a_band_limited_record_as_the_refinement_does():
    """A clean record of the 9-samples-a-period oscillator made band-limited: the UKF that reads it
    band-limited ends on the truth; read linearly, its stiffness ends about 0.1 % off."""
    from pidyn.baselines.ukf import unscented_kalman_filter
    from pidyn.data.sources import Record

    system, vals = _oscillator()
    t = np.arange(0, 4, 1 / FS)
    rng = np.random.default_rng(5)
    f = np.convolve(rng.standard_normal(len(t)), np.ones(3) / 3, mode="same")
    Y, _ = simulate_states(system, vals, t, f, substeps=4, hold="bandlimited")
    err = {}
    for hold in ("linear", "bandlimited"):
        rec = Record(name="tone", t=t, f=f, x=Y[:, :1], excitation="force", meta={"input_hold": hold})
        est = unscented_kalman_filter(
            rec, system, init={"c": vals["c"], "k": vals["k"]}, q_param=1e-8, substeps=4
        )
        err[hold] = abs(est.params["k"] / vals["k"] - 1)
    assert err["bandlimited"] < 1e-5 and err["linear"] > 5e-4, err
