"""Real structures from their own files: the CSMIP reader, several supports, the start from the
data, the peers, and the diagnosis of accelerometer records (each test able to fail)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from pidyn.data.csmip import CsmipFormatError, MissingChannelError, read_archive, read_v2
from pidyn.data.strong_motion import csmip_record
from pidyn.notes import codes

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "data" / "painter_street" / "records"
RIODELL82 = RECORDS / "riodell82_ce89324p.zip"  # film era: two recorders, channel 3 missing


def _members(path: Path) -> dict[str, str]:
    with zipfile.ZipFile(path) as z:
        return {i.filename: z.read(i).decode("latin-1") for i in z.infolist()}


def _zip(path: Path, members: dict[str, str]) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, text in members.items():
            z.writestr(name, text)
    return path


def test_reader_reads_a_shipped_archive_in_si_units_by_station_channel():
    a = read_archive(RIODELL82)
    assert sorted(a.channels) == [4, 7, 9, 11, 15, 17, 18, 20]  # 1 and 3 are not in this event
    ch7, ch9 = a.channels[7], a.channels[9]
    # the header's peak acceleration, -411.527 cm/s^2 at 2.88 s, in m/s^2
    assert ch7.dt == pytest.approx(0.02) and ch7.n == 1080
    assert np.min(ch7.acc) == pytest.approx(-4.11527, abs=1e-6) and np.argmin(ch7.acc) == 144
    # the second recorder's channel 1 is the station's channel 9 (named in the file), and stops earlier
    assert ch9.recorder_channel == 1 and ch9.n == 1065 and ch9.recorder != ch7.recorder
    assert ch7.vel is not None and ch7.disp is not None and ch7.band_hz == (0.5, 23.0)
    assert "GIRDER AT CENTER BENT" in ch7.location


def test_reader_names_the_file_and_the_problem(tmp_path):
    files = _members(RIODELL82)
    name = next(n for n in files if n.upper().endswith("CHAN07.V2"))
    text = files[name]
    lines = text.split("\r\n")
    start = next(i for i, ln in enumerate(lines) if "POINTS OF ACCEL DATA" in ln)
    cut = "\r\n".join(lines[: start + 50])  # the acceleration block stops after 49 lines of 135
    with pytest.raises(
        CsmipFormatError, match=r"CHAN07\.V2: accel block: 392 values where the header states 1080"
    ):
        read_v2(cut, "riodell82/CHAN07.V2")
    garbled = "\r\n".join(lines[: start + 3] + ["    1.284    -8.9x9   -12.322"] + lines[start + 4 :])
    with pytest.raises(CsmipFormatError, match=r"line \d+ has '-8\.9x9', not a number"):
        read_v2(garbled, "riodell82/CHAN07.V2")
    shifted = text.replace(
        "ACCELERATION =  -411.527", "ACCELERATION =  -411.111"
    )  # a header not of these data
    with pytest.raises(
        CsmipFormatError, match="peak acceleration 411.527 in the samples, 411.111 in the header"
    ):
        read_v2(shifted, "riodell82/CHAN07.V2")
    broken = tmp_path / "broken.zip"
    broken.write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(CsmipFormatError, match="broken.zip: not a readable zip archive"):
        read_archive(broken)
    only_v1 = _zip(tmp_path / "v1.zip", {"CHAN07.V1": "uncorrected"})
    with pytest.raises(CsmipFormatError, match=r"v1.zip: no V2 file"):
        read_archive(only_v1)
    # a channel the set asks for and the event lacks: named, with what the archive holds
    with pytest.raises(MissingChannelError, match=r"input channel\(s\) \[3\] not in this archive"):
        csmip_record(RIODELL82, station="CE89324")
    with pytest.raises(MissingChannelError, match="none of the input channels"):
        csmip_record(RECORDS / "petrolia91_ce89324p.zip", station="CE89324", on_missing="drop")


def test_a_record_cuts_aligns_and_resamples_what_it_reads():
    rec = csmip_record(RIODELL82, station="CE89324", on_missing="drop")
    assert {"channel_missing", "cut_to_shortest"} <= codes(rec.meta.notes), rec.meta.notes
    assert len(rec.t) == 1065 or "1065 samples" in " ".join(rec.meta.notes)
    assert rec.meta.input_channels == [17, 20] and rec.n_inputs == 2 and rec.f.shape[1] == 4
    assert rec.a.shape[1] == 3 and rec.meta.acceleration == "absolute"  # no model given: every output kept
    # a digital record at 0.01 s: resampled to 0.02 s, its pre-event part measured, split for the held-out check
    rec = csmip_record(RECORDS / "nc73667866_ce89324p.zip", station="CE89324", max_outputs=1)
    assert rec.dt == pytest.approx(0.02) and rec.a.shape[1] == 1 and rec.inputs == ["ch3", "ch17", "ch20"]
    assert 0 < rec.meta.pre_event_rms["share_of_peak"] < 0.02
    fit, held = rec.meta.split.fit, rec.meta.split.heldout
    assert fit[1] == pytest.approx(0.65 * rec.t[-1]) and held[1] == pytest.approx(rec.t[-1])
    # the velocities beside the accelerations are the files' own (integrated by the processing)
    v2 = read_archive(RECORDS / "nc73667866_ce89324p.zip").channels[3]
    i0 = int(round(rec.meta.t_offset / v2.dt))
    assert np.max(np.abs(rec.f[:, 3] - v2.vel[i0 : i0 + 2 * len(rec.t) : 2][: len(rec.t)])) < 0.05 * np.max(
        np.abs(v2.vel)
    )


def _two_support_record(noise: float = 0.01, **truth):
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.excitation.ground_motion import SupportMotions, prepare
    from pidyn.systems import LinearSDOF

    gm = SupportMotions.from_motions(
        {
            "a": prepare("el_centro", dt=0.02, duration=20.0),
            "b": prepare("kobe", dt=0.02, duration=20.0, scale=0.6),
        }
    )
    p = {"c": 0.8, "k": 400.0, "r_a": 0.7, "r_b": 0.3, **truth}
    system = LinearSDOF(
        c=p["c"], k=p["k"], inputs=["a", "b"], params={"r_a": {"true": p["r_a"]}, "r_b": {"true": p["r_b"]}}
    )
    return synthetic_from_motion(system, gm, noise=noise, channels=["a"]), p


def test_the_start_from_the_data_finds_the_supports_and_a_stiffness_far_from_the_config():
    from pidyn.config import make_system
    from pidyn.data.sources import synthetic
    from pidyn.starts.data import start_from_data
    from pidyn.systems import LinearSDOF

    config = make_system("linear")
    k_config = next(s.init for s in config.param_specs() if s.name == "k")
    rec = synthetic(LinearSDOF(c=1.0, k=150.0 * k_config), "kobe", noise=0.02, channels=("a",), duration=30.0)
    start = start_from_data(rec, config)
    assert start.method == "equation_error"
    assert start.values["k"] == pytest.approx(150.0 * k_config, rel=0.01)
    assert start.values["c"] == pytest.approx(1.0, rel=0.1)
    rec, p = _two_support_record()
    start = start_from_data(rec, LinearSDOF(inputs=["a", "b"]))
    for n in ("k", "r_a", "r_b"):
        assert start.values[n] == pytest.approx(p[n], rel=0.02), n


@pytest.mark.slow
def test_a_measured_record_starts_pidynnet_from_the_data(tmp_path):
    """Without the truth (a measured record) the train task starts from the data unless the user
    gave a start; the config's k = 10 for a structure of k = 1500 is not used."""
    from dataclasses import replace

    import pidyn
    from pidyn.data.sources import synthetic
    from pidyn.systems import LinearSDOF

    rec = synthetic(LinearSDOF(c=1.0, k=1500.0), "kobe", noise=0.01, channels=("a",), duration=20.0)
    measured = replace(rec, truth=None, clean=None)
    # two workers (pidyn.parallel): the period's scan and profile, and the figures, side by side
    res = pidyn.identify(
        measured, "linear", baselines="none", debug="smoke", workers=2, out_dir=tmp_path / "data"
    )
    import json

    start = json.loads((tmp_path / "data" / "data_start.json").read_text())
    assert start["used_by_pidynnet"] and start["values"]["k"] == pytest.approx(1500.0, rel=0.01)
    assert res.params["k"] == pytest.approx(1500.0, rel=0.005)
    modal = json.loads((tmp_path / "data" / "modal.json").read_text())["modes"][0]
    lo, hi = modal["period_ci95"]
    assert lo < 2 * np.pi / np.sqrt(1500.0) < hi and set(modal) >= {
        "period_s",
        "period_ci95",
        "frequency_hz",
        "damping_ratio",
        "damping_ci95",
    }
    # a measured record's modes: its stabilisation diagram stands at the one mode; the period
    # window by window against the amplitude, flat for a linear structure
    figures = tmp_path / "data" / "figures"
    for name in ("stabilization.png", "period_vs_amplitude.png"):
        assert (figures / name).stat().st_size > 10_000, name
    metrics = json.loads((tmp_path / "data" / "metrics.json").read_text())
    f_n = np.sqrt(1500.0) / (2 * np.pi)
    assert any(abs(m["frequency_hz"] / f_n - 1) < 0.01 for m in metrics["stabilization"]["stable_modes"])
    pva = metrics["period_vs_amplitude"]
    period = 2 * np.pi / np.sqrt(1500.0)
    assert len(pva["period"]) >= 4 and np.median(pva["period"]) == pytest.approx(period, rel=0.005)
    assert np.mean([lo <= period <= hi for lo, hi in zip(pva["period_lo"], pva["period_hi"])]) >= 0.8
    res = pidyn.identify(
        measured, "linear", baselines="none", debug="smoke", init={"k": 900.0}, out_dir=tmp_path / "user"
    )
    start = json.loads((tmp_path / "user" / "data_start.json").read_text())
    assert start["used_by_pidynnet"] and res.pidynnet["k"] != pytest.approx(start["values"]["k"], rel=0.01)


@pytest.mark.slow
def test_a_two_support_sdof_is_recovered_with_its_influences(tmp_path):
    import pidyn

    rec, p = _two_support_record(noise=0.01)
    res = pidyn.identify(
        rec,
        "linear",
        system__inputs=["a", "b"],
        model__start="data",
        baselines="none",
        out_dir=tmp_path,
        model__schedule__max_windows=1,
        # a short PIDynNet stage: the data's start and the refinement after it are under test
        model__schedule__pretrain_iters=200,
        model__schedule__max_iters=300,
    )
    # within three standard errors of the truth (1.5 half-widths of the 95 % interval): for eight
    # parameters from one noise draw, a 95 % interval alone misses one of them one time in three
    truth = {**p, "g_a": 0.0, "g_b": 0.0, "e_a": 0.0, "e_b": 0.0}
    for n, t in truth.items():
        lo, hi = res.ci95[n]
        assert abs(res.params[n] - t) <= 0.75 * (hi - lo), (n, res.params[n], lo, hi)
    for n in ("c", "k", "r_a", "r_b"):
        assert res.params[n] == pytest.approx(p[n], rel=0.01), n


def test_classical_estimators_run_on_a_record_of_several_supports():
    from pidyn.baselines.least_squares import equation_error
    from pidyn.baselines.peers import transfer_function_estimate
    from pidyn.baselines.sindy import weak_sindy
    from pidyn.baselines.ukf import unscented_kalman_filter
    from pidyn.systems import LinearSDOF

    rec, p = _two_support_record(noise=0.01)
    system = LinearSDOF(inputs=["a", "b"])
    ee = equation_error(rec, system)
    assert ee.params["k"] == pytest.approx(p["k"], rel=0.02)
    assert codes(weak_sindy(rec, system).note) == {"not_applicable"}
    ukf = unscented_kalman_filter(rec, system, tune=(1e-8, 1e-6), init=ee.params)
    assert np.isfinite(ukf.loglik) and ukf.params["k"] == pytest.approx(p["k"], rel=0.05)
    # the transfer function assumes one input (the supports' mean): close on two supports, exact on one
    assert transfer_function_estimate(rec).modes[0]["period_s"] == pytest.approx(2 * np.pi / 20.0, rel=0.03)
    from pidyn.data.sources import synthetic

    one = synthetic(
        LinearSDOF(c=0.8, k=400.0), "el_centro", noise=0.01, channels=("a",), duration=20.0, dt=0.02
    )
    mode = transfer_function_estimate(one).modes[0]
    assert mode["period_ci95"][0] < 2 * np.pi / 20.0 < mode["period_ci95"][1]
    assert mode["damping_ci95"][0] < 0.8 / 40.0 < mode["damping_ci95"][1]


def test_mdof_peers_on_a_shipped_record():
    pytest.importorskip("mdof")
    from pidyn.baselines.peers import okid_era, realization_params, spans, srim
    from pidyn.reporting import nrmse
    from pidyn.simulate import simulate_response
    from pidyn.systems import LinearSDOF

    rec = csmip_record(RECORDS / "nc73667866_ce89324p.zip", station="CE89324", max_outputs=1)
    for peer in (srim(rec), okid_era(rec)):
        assert peer.stable and 0.2 < peer.modes[0]["period_s"] < 0.26, peer.note
        assert peer.heldout_nrmse_a is not None and np.isfinite(peer.heldout_nrmse_a)
    # SRIM's order-2 model as the supports' model (a refinement start) simulates the record as SRIM's does
    peer = srim(rec, orders=(2,))
    system = LinearSDOF(inputs=rec.inputs)
    values = {
        **{s.name: s.init for s in system.param_specs()},
        **realization_params(system, peer.realization, rec.dt),
    }
    fit, _ = spans(rec)
    a = simulate_response(system, values, rec)["a"][:, 0]
    assert nrmse(a[fit], rec.a[fit, 0]) == pytest.approx(peer.fit_nrmse_a, rel=0.05)


def test_a_record_cut_to_its_fitting_part_has_no_held_out_part_for_the_peers():
    """The diagnosis gives the peers the fitting part with its split kept: no held-out part, not an
    empty one (an empty mask's mean warned on every diagnosis of a strong-motion record)."""
    from pidyn.baselines.peers import spans

    rec = csmip_record(RECORDS / "nc73667866_ce89324p.zip", station="CE89324", max_outputs=1)
    fit, held = spans(rec)
    assert held is not None and held.any() and fit.any()
    cut = rec.segment(None, rec.meta.split.fit[1])
    fit, held = spans(cut)
    assert held is None and fit.all()


def test_an_order_two_realization_maps_onto_the_supports_model_exactly():
    """A peer's state-space model of order 2 is the single degree of freedom on several supports:
    the model's first-order-hold discretization (the input linear between samples) maps back to its own parameters."""
    from scipy.signal import cont2discrete

    from pidyn.baselines.peers import realization_params
    from pidyn.systems import LinearSDOF

    p = dict(c=1.3, k=400.0, r_a=0.6, r_b=0.45, g_a=0.8, g_b=-0.3, e_a=0.1, e_b=-0.05)
    c, k = p["c"], p["k"]
    B, D = [], []
    for j in "ab":  # observable canonical form of (n2 s^2 + n1 s + n0) / (s^2 + c s + k)
        e, r, g = p[f"e_{j}"], p[f"r_{j}"], p[f"g_{j}"]
        n2, n1, n0 = e, g + (r + e) * c, (r + e) * k
        B.append([n0 - n2 * k, n1 - n2 * c])
        D.append(n2)
    cont = (np.array([[0.0, -k], [1.0, -c]]), np.array(B).T, np.array([[0.0, 1.0]]), np.array([D]))
    Ad, Bd, Cd, Dd, _ = cont2discrete(cont, 0.02, method="foh")
    got = realization_params(LinearSDOF(inputs=["a", "b"]), (Ad, Bd, Cd, Dd), 0.02)
    assert got == pytest.approx(p, rel=1e-9, abs=1e-9)
    # one input: the model's input terms are fixed, only the oscillator is taken
    assert set(realization_params(LinearSDOF(), (Ad, Bd[:, :1], Cd, Dd[:, :1]), 0.02)) == {"c", "k"}
    # real poles (no oscillator) and a model of another class give nothing
    assert realization_params(LinearSDOF(), (np.diag([0.9, 0.8]), Bd[:, :1], Cd, Dd[:, :1]), 0.02) == {}
    assert (
        realization_params(LinearSDOF(), (np.eye(4) * 0.5, np.ones((4, 1)), np.ones((1, 4)), Dd[:, :1]), 0.02)
        == {}
    )


def test_the_running_period_sees_a_change_and_no_change_where_there_is_none():
    """Window by window by output error: a stiffness that falls by 30 % at 10 s shows as a period
    that moves beyond its intervals; the same structure without the change does not."""
    from pidyn.data.sources import synthetic
    from pidyn.discrepancy.running import period_varies, running_modes
    from pidyn.systems import LinearSDOF, SDOFSystem
    from pidyn.systems.terms import LinearStiffness, StiffnessLoss, ViscousDamping

    k, c = 400.0, 1.0
    changed = SDOFSystem(
        [ViscousDamping(c), LinearStiffness(k), StiffnessLoss(0.3, 10.0, t_min=0.0, t_max=20.0)]
    )
    nominal = LinearSDOF(c=c, k=k)
    values = {"m": 1.0, "c": c, "k": k}
    width = 2.0
    for system, expect in ((changed, True), (nominal, False)):
        rec = synthetic(system, "el_centro", noise=0.02, channels=("a",), duration=20.0, dt=0.02)
        run = running_modes(rec, nominal, values, width=width, step=width)
        before = np.nanmedian(run["period"][run["t"] < 9.0])
        after = np.nanmedian(run["period"][run["t"] > 11.0])
        assert before == pytest.approx(2 * np.pi / np.sqrt(k), rel=0.02)
        assert after == pytest.approx(2 * np.pi / np.sqrt(k * (0.7 if expect else 1.0)), rel=0.03)
        assert period_varies(run, width)["varies"] is expect


@pytest.mark.slow
def test_the_diagnosis_of_an_accelerometer_record_names_a_hidden_cubic_spring(tmp_path):
    from helpers import make_cfg

    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(
        [
            "data.source.channels=[a]",
            "noise=0.02",
            "diagnosis.max_effects=1",
            "model.schedule.max_windows=3",
            # a short PIDynNet stage: the refinement from the accelerations' start decides
            "model.schedule.pretrain_iters=150",
            "model.schedule.pretrain_iters_window=150",
            "model.schedule.max_iters=200",
        ],
        tmp_path,
        config_name="diagnose",
    )
    d = diagnose(cfg)
    assert d["verdict"] == "discrepancy" and d["causes"] == ["cubic_stiffness"], d["causes"]
    assert d["gain"]["metric"] == "heldout_nrmse_a" and d["gain"]["extended"] < 0.2 * d["gain"]["nominal"]
    assert d["accelerometers"] is not None and d["modal"][0]["period_ci95"][0] is not None
    tested = {r["effect"]: r for r in d["confirmation"]}
    assert tested["cubic_stiffness"]["score"] > tested["gap_contact"]["score"] + 10


def test_an_accelerometer_diagnosis_starts_from_the_accelerations_when_the_weak_form_misreads(tmp_path):
    """The weak form reads an integrated motion; where its start is not physical (a negative
    damping, as on a longitudinal Painter Street record) or simulates the accelerations worse, the
    diagnosis starts from the output-error fit that combined the supports."""
    from pidyn.discrepancy import case as diagnosis_case
    from pidyn.discrepancy import nominal
    from pidyn.discrepancy.accelerometers import motion_view
    from pidyn.discrepancy.settings import DiagnosisSettings
    from pidyn.systems import LinearSDOF

    rec, p = _two_support_record(noise=0.02)
    settings = DiagnosisSettings()
    fit = diagnosis_case.split_spans(rec, settings.fit_share)[0]
    view = motion_view(rec, LinearSDOF(inputs=["a", "b"]), fit, tol=settings.polish_tol)
    base = LinearSDOF(c=0.5, k=15.0)
    case = diagnosis_case.prepare(view, base, {}, settings, 1.0, tmp_path, identify=None)
    fitted = view.meta.accelerometers.nominal
    assert fitted["k"] == pytest.approx(p["k"], rel=0.02)
    bad = {"m": 1.0, "c": -3.0, "k": 0.12 * p["k"]}
    values, period = nominal._accelerometer_start(case, bad, 1.0)
    assert values["k"] == pytest.approx(fitted["k"]) and values["c"] > 0
    assert period == pytest.approx(2 * np.pi / np.sqrt(fitted["k"]), rel=1e-6)
    good = {"m": 1.0, "c": fitted["c"], "k": fitted["k"] * 1.0001}
    wrong = {"m": 1.0, "c": fitted["c"], "k": 0.5 * fitted["k"]}
    assert nominal._accelerometer_start(case, wrong, 1.0)[0]["k"] == pytest.approx(fitted["k"])
    assert nominal._fit_error(case, good) < 0.5 * nominal._fit_error(case, wrong)


def test_the_nominal_model_of_an_accelerometer_record_starts_from_the_better_of_data_and_peers(monkeypatch):
    """A real record can hold linear optima far apart: the diagnosis fits its nominal model from the
    data's start and from the peer's realization that simulates the fitting part best, and keeps
    the lower fitted cost (without mdof, from the data's start alone)."""
    from pidyn.discrepancy import accelerometers
    from pidyn.starts import cheapest
    from pidyn.systems import LinearSDOF

    rec, p = _two_support_record(noise=0.02)
    seg = rec.segment(0.0, 13.0)
    system = LinearSDOF(inputs=["a", "b"])
    truth = {"c": p["c"], "k": p["k"], "r_a": p["r_a"], "r_b": p["r_b"]}
    near, worse = {**truth, "k": 0.9 * p["k"]}, {**truth, "k": 0.8 * p["k"]}
    assert cheapest(seg, system, {"near": near, "worse": worse, "truth": truth}) == "truth"
    monkeypatch.setattr(
        accelerometers, "peer_starts", lambda record, system: {"srim": worse, "okid_era": truth}
    )
    assert accelerometers._peer_options(seg, system, near) == {"okid_era's realization": truth}
    calls = []
    real_fit = accelerometers._influence_fit

    def spy(seg, system, values, tol):
        out = real_fit(seg, system, values, tol)
        calls.append((values["k"], out[1].cost))
        return out

    monkeypatch.setattr(accelerometers, "_influence_fit", spy)
    _, values, note, _ = accelerometers._nominal_influence(
        rec, LinearSDOF(inputs=["a", "b"]), (0.0, 13.0), 1e-6
    )
    assert len(calls) == 2 and values["k"] == pytest.approx(p["k"], rel=0.02)
    kept = min(calls, key=lambda c: c[1])
    assert ("okid_era" in note) == (kept[0] == truth["k"])
    monkeypatch.setattr(accelerometers, "peer_starts", lambda record, system: {})
    calls.clear()
    note = accelerometers._nominal_influence(rec, LinearSDOF(inputs=["a", "b"]), (0.0, 13.0), 1e-6)[2]
    assert len(calls) == 1 and note.startswith("start from the data")


def test_the_running_period_widens_its_intervals_for_a_model_error_and_not_for_white_noise(monkeypatch):
    """A linear window fitted to a hardening spring leaves a smooth, correlated residual: its
    intervals are the sandwich, wider than white-noise ones; on a linear structure with white
    noise they are the white-noise ones."""
    from pidyn.data.sources import synthetic
    from pidyn.discrepancy import running
    from pidyn.refine import uncertainty
    from pidyn.systems import LinearSDOF, SDOFSystem
    from pidyn.systems.terms import CubicStiffness, LinearStiffness, ViscousDamping

    k, c = 400.0, 1.0
    nominal = LinearSDOF(c=c, k=k)
    values = {"m": 1.0, "c": c, "k": k}

    def white(problem, r, J, C):
        cov, cond = uncertainty.covariance(problem, J, C)
        return cov * float(r @ r) / max(len(r) - problem.n_theta - problem.ns, 1), cond, 0

    def widths(rec):
        run = running.running_modes(rec, nominal, values, width=4.0, step=4.0)
        ok = np.isfinite(run["period"])
        return np.asarray(run["period_hi"])[ok] - np.asarray(run["period_lo"])[ok]

    hard = SDOFSystem([ViscousDamping(c), LinearStiffness(k), CubicStiffness(4e6)])
    for system, noise, wider in ((hard, 0.002, True), (nominal, 0.02, False)):
        rec = synthetic(system, "el_centro", noise=noise, channels=("a",), duration=20.0, dt=0.02)
        sandwich = widths(rec)
        with monkeypatch.context() as m:
            m.setattr(running, "residual_covariance", white)
            plain = widths(rec)
        ratio = float(np.median(sandwich / plain))
        assert (ratio > 1.5) if wider else ratio == pytest.approx(1.0, abs=0.05), ratio
