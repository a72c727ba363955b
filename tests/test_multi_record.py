"""Several records of one structure identified as one, and a record the model never saw predicted."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pidyn import Record
from pidyn.config import make_system
from pidyn.data.errors import DataError
from pidyn.data.meta import RecordMeta
from pidyn.data.multi import concatenate, pieces, split
from pidyn.data.windows import make_windows
from pidyn.refine.problem import ShootingProblem, record_channels, segment_bounds
from pidyn.simulate import simulate_response

ROOT = Path(__file__).resolve().parents[1]


def _records(system="duffing", noise=0.0):
    kw = dict(duration=8.0, channels=("x", "v"), noise=noise)
    return (
        Record.simulate(system, "el_centro", scale=0.5, seed=1, **kw),
        Record.simulate(system, "kobe", scale=1.0, seed=2, **kw),
    )


def test_concatenated_record_keeps_its_pieces_and_truth():
    r1, r2 = _records()
    both = concatenate([r1, r2])
    assert len(both.t) == len(r1.t) + len(r2.t)
    assert np.allclose(np.diff(both.t), r1.dt)
    assert [p.name for p in pieces(both)] == [r1.name, r2.name]
    assert pieces(both)[1].i0 == len(r1.t)
    assert both.truth == r1.truth
    assert both.clean is not None and len(both.clean.x) == len(both.t)


def test_records_of_another_step_or_structure_are_refused_by_name():
    r1, r2 = _records()
    coarse = Record.simulate("duffing", "kobe", duration=8.0, dt=0.02, channels=("x", "v"))
    with pytest.raises(DataError, match="time step"):
        concatenate([r1, coarse])
    other = Record.simulate("duffing", "kobe", duration=8.0, channels=("x", "v"), k1=30.0)
    with pytest.raises(DataError, match="another true structure"):
        concatenate([r1, other])
    with pytest.raises(DataError, match="no record"):
        concatenate([])


def test_a_free_run_starts_each_record_from_rest():
    """The model simulated over the records laid end to end is each record simulated on its own."""
    system = make_system("bouc_wen")
    values = {s.name: s.true if s.true is not None else s.init for s in system.param_specs()}
    r1, r2 = _records("bouc_wen")
    both = concatenate([r1, r2])
    whole = simulate_response(system, values, both)["x"]
    apart = np.concatenate([simulate_response(system, values, r)["x"] for r in (r1, r2)])
    assert np.allclose(whole, apart, rtol=0, atol=1e-12 * np.abs(apart).max())
    assert np.allclose(apart, both.clean.x, atol=1e-4 * np.abs(apart).max())


def test_shooting_segments_end_where_a_record_begins_and_no_defect_joins_records():
    system = make_system("duffing")
    r1, r2 = _records()
    both = concatenate([r1, r2])
    start = pieces(both)[1].i0
    bounds = segment_bounds(both.t, 1.0, breaks=[start])
    assert start in bounds
    prob = ShootingProblem(
        system, both.t, both.f, record_channels(both, 1), bounds, restarts=[start], fixed_state0=np.zeros(2)
    )
    assert prob.link.sum() == prob.S - 2  # every boundary but the records' junction
    truth = {s.name: s.true for s in system.param_specs() if s.trainable}
    states = np.stack([[both.clean.x[b, 0], both.clean.v[b, 0]] for b in bounds[:-1]])
    r, c = prob.residuals(prob.pack(truth, states))
    assert len(c) == 2 * (prob.S - 2)
    assert np.max(np.abs(c)) < 1e-3 and np.max(np.abs(r)) < 1e-2
    _, J, _, C = prob.linearize(prob.pack(truth, states))
    assert C.shape == (len(c), prob.n_unknowns) and J.shape[1] == prob.n_unknowns


def test_several_records_cost_the_sum_of_their_squared_nrmse():
    """Joined records of different amplitudes count alike: each record's residuals are in units of
    its own spread, so a wrong model's free-run cost is the records' squared NRMSE summed (times
    their lengths), the weaker record's as heavy as the stronger's, and one record is unweighted."""
    system = make_system("duffing")
    r1, r2 = _records()
    both = concatenate([r1, r2])
    start = pieces(both)[1].i0
    chans = record_channels(both, 1)
    assert record_channels(r1, 1)[0].weight is None
    prob = ShootingProblem(
        system,
        both.t,
        both.f,
        chans,
        np.array([0, len(both.t) - 1]),
        restarts=[start],
        fixed_state0=np.zeros(2),
    )
    wrong = {s.name: 1.15 * s.true for s in system.param_specs() if s.trainable}
    theta = prob.pack(wrong, np.zeros((1, 2)))[: prob.n_theta]
    Y, _ = prob.free_run(theta, np.zeros(2))
    expected, per_record = 0.0, []
    for ch, sim in zip(chans, (Y[:, 0], Y[:, 1])):
        whole = np.std(ch.data)
        for i0, i1 in ((0, start), (start, len(both.t))):
            d = ch.data[i0:i1]
            nrmse = np.sqrt(np.mean((sim[i0:i1] - d) ** 2)) / np.std(d)
            per_record.append(nrmse)
            expected += (i1 - i0) * (whole / ch.sigma) ** 2 * nrmse**2
    assert prob.free_run_cost(theta, np.zeros(2)) == pytest.approx(expected, rel=1e-9)
    assert min(per_record) > 0.01  # the wrong model misses both records


def test_windows_take_turns_between_records_and_never_span_two():
    r1, r2 = _records()
    both = concatenate([r1, r2])
    spans = [(both.t[p.i0], both.t[p.i1 - 1]) for p in pieces(both)]
    wins = make_windows(both.t, both.f, both.x, both.v, None, 2.0, 50, pieces=spans)
    assert [w.piece for w in wins[:4]] == [0, 1, 0, 1]
    for w in wins:
        lo, hi = spans[w.piece]
        assert lo - 1e-9 <= w.t0 and w.t1 <= hi + 1e-9


def test_predict_refuses_a_record_of_other_channels():
    from pidyn.runs.prediction import Identified, check_channels

    run = Identified(Path("RUN"), None, {"record_meta": {"station": "CE89324", "output_channels": [7]}})
    rec = Record(name="other", t=np.arange(100) * 0.02, f=np.sin(np.arange(100)), a=np.cos(np.arange(100)))
    rec.meta = RecordMeta(station="CE89324", output_channels=[9])
    with pytest.raises(ValueError, match="output_channels"):
        check_channels(run, rec)
    rec.meta.output_channels = [7]
    check_channels(run, rec)


def test_a_record_of_another_direction_is_refused_by_its_channels_not_by_missing_values(tmp_path):
    """A run of the longitudinal supports asked to predict a transverse record: the model would take
    the record's supports (ch3, ch17, ch20) and find no value for them; the error names the
    direction and channels that differ, which is what the user has to change."""
    from omegaconf import OmegaConf

    from pidyn.config import compose
    from pidyn.runs.build import system_and_record
    from pidyn.runs.prediction import CHANNEL_KEYS, Identified

    path = ROOT / "data" / "painter_street" / "records" / "capemendocino_31jul1987_ce89324p.zip"
    over = [f"data.path={path}", "data.station=CE89324", "data.direction=longitudinal"]
    cfg = compose("train", groups={"data": "csmip", "system": "linear"}, overrides=over)
    system, record = system_and_record(cfg, None)
    metrics = {
        "params": {s.name: float(s.init) for s in system.param_specs()},
        "record_meta": {**record.meta.to_dict(CHANNEL_KEYS), "inputs": record.inputs},
    }
    run = Identified(tmp_path, cfg, metrics)
    run.for_record(cfg.data)  # its own channels: read
    other = OmegaConf.merge(cfg.data, {"direction": "transverse"})
    with pytest.raises(
        ValueError, match="does not match run .*direction 'transverse' .*the run: 'longitudinal'"
    ):
        run.for_record(other)


def test_predict_needs_a_finished_run(tmp_path):
    from pidyn.runs.prediction import Identified

    (tmp_path / "metrics.json").write_text("{}")
    with pytest.raises(FileNotFoundError, match="not a finished identification"):
        Identified.load(tmp_path)


@pytest.mark.slow
def test_bouc_wen_from_two_earthquakes_predicts_a_third(tmp_path):
    """Two simulated earthquakes at different amplitudes of one Bouc-Wen structure give its
    parameters within their intervals, and the model predicts a third earthquake it never saw
    (simulated from rest) within 1 % NRMSE; predict.py writes the same from a CSV and refuses a
    record of other channels with a named error."""
    import pidyn

    kw = dict(duration=12.0, channels=("x", "v"))
    r1 = Record.simulate("bouc_wen", "el_centro", scale=0.5, noise=0.01, seed=1, **kw)
    r2 = Record.simulate("bouc_wen", "kobe", scale=1.0, noise=0.01, seed=2, **kw)
    r3 = Record.simulate("bouc_wen", "northridge", scale=0.8, **kw)
    res = pidyn.identify(
        [r1, r2],
        "bouc_wen",
        out_dir=tmp_path / "run",
        model__schedule__max_windows=1,
        baselines="none",
        # PIDynNet runs, the refinement on both records from the better start does the rest
        model__schedule__pretrain_iters=300,
        model__schedule__pretrain_iters_window=300,
        model__schedule__max_iters=500,
    )
    frame = res.to_frame()
    for name, row in frame.iterrows():
        assert row.ci95_lo <= row.truth <= row.ci95_hi, name
        assert abs(row.error_pct) < 2.0, name
    assert [r["name"] for r in res.metrics["record_meta"]["records"]] == [r1.name, r2.name]
    pred = pidyn.predict(res, r3)
    assert max(pred.scores["nrmse"].values()) < 0.01
    assert pred.scores["seen_by_run"] is False and pidyn.predict(res, r1).scores["seen_by_run"] is True
    # the command line, from a CSV of the third earthquake
    csv = tmp_path / "northridge.csv"
    pd.DataFrame({"t": r3.t, "ag": r3.f, "x": r3.x[:, 0], "v": r3.v[:, 0]}).to_csv(csv, index=False)
    out = tmp_path / "pred"
    cmd = [
        sys.executable,
        str(ROOT / "predict.py"),
        f"run={tmp_path / 'run'}",
        "data=csv",
        f"data.path={csv}",
    ]
    done = subprocess.run([*cmd, f"hydra.run.dir={out}"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    saved = json.loads((out / "prediction.json").read_text())
    assert set(saved) >= {"mean_nrmse_a", "nrmse", "span", "linear_mean_nrmse_a"}
    assert saved["nrmse"]["x1"] == pytest.approx(pred.scores["nrmse"]["x1"], rel=1e-9)
    assert (out / "figures" / "prediction.png").is_file()
    # a record with an acceleration channel only: not what the model was identified on (refused
    # in-process, as the command line's call refuses it: a ValueError, which it ends with exit 2)
    from pidyn.config import compose
    from pidyn.tasks.predict import predict

    pd.DataFrame({"t": r3.t, "ag": r3.f, "a": r3.x[:, 0]}).to_csv(csv, index=False)
    bad = tmp_path / "bad"
    with pytest.raises(ValueError, match="channels"):
        overrides = [f"run={tmp_path / 'run'}", "data=csv", f"data.path={csv}"]
        predict(compose("predict", overrides=overrides, output_dir=bad, root_dir=ROOT))
    assert not (bad / "prediction.json").exists()


def test_the_api_reads_what_the_command_line_reads():
    """``Record.from_csmip`` and ``Record.from_xsens`` read as ``data=csmip`` and ``data=xsens`` do."""
    rec = Record.from_csmip(
        ROOT / "data" / "painter_street" / "records" / "petrolia_25apr1992_ce89324p.zip",
        station="CE89324",
        max_outputs=1,
    )
    assert rec.inputs == ["ch3", "ch17", "ch20"] and rec.meta.output_channels == [7]
    imu = Record.from_xsens(ROOT / "data" / "mini_shake_table" / "Stiff 3 story", run="Sine 1.5")
    assert imu.a.shape[1] == 3 and imu.meta.run == "Sine 1.5"


def test_one_amplitude_dependent_model_from_a_weak_and_a_strong_earthquake():
    """The model whose stiffness falls and damping rises with the response's amplitude (the
    ``amplitude`` system, one model for a bridge's weak and strong events) is found from a weak
    and a strong record together, started away from the truth."""
    from pidyn.refine import RefineSettings, refine

    system = make_system("amplitude", soft=0.3, gain=1.5, tau=1.0)
    kw = dict(duration=10.0, dt=0.02, channels=("x", "v"))
    weak = Record.simulate(system, "el_centro", scale=0.1, **kw)
    strong = Record.simulate(system, "kobe", scale=0.5, **kw)
    truth = system.true_values()
    guess = {**truth, "soft": 0.1, "gain": 0.5, "c": 2.5, "k": 550.0, "tau": 2.0}
    res = refine(system, concatenate([weak, strong]), {"guess": guess}, RefineSettings(states="simulated"))
    for name in ("c", "k", "soft", "gain", "tau"):
        assert res.params[name] == pytest.approx(truth[name], rel=1e-4), name
    # several records: the estimate is finished from rest, as a prediction simulates it
    assert res.polish["evaluations"] > 0 and res.polish["cost_after"] <= res.polish["cost_before"]
    assert res.initial_state_mode == "rest" and res.initial_state == [0.0] * system.n_state
    assert any(n.endswith("[polished_from_rest]") for n in res.notes)
    assert all(
        res.intervals[n]["ci95"][0] < res.params[n] < res.intervals[n]["ci95"][1] for n in ("k", "soft")
    )
    one = refine(system, strong, {"guess": res.params}, RefineSettings(states="simulated", period_scan=False))
    assert one.polish == {}  # one record: the shooting estimate, its initial state free where the data say so


def test_the_amplitude_models_scale_is_read_from_its_records_and_kept_for_prediction(tmp_path):
    """``system.w0=null system.a_ref=null``: the structure's circular frequency is the records'
    resonance and its amplitude scale the strongest record's relative response; the run keeps
    both, and a prediction of another record uses them, not the new record's."""
    from pidyn.config import compose
    from pidyn.runs.build import system_and_record
    from pidyn.runs.prediction import Identified
    from pidyn.signals import fundamental
    from pidyn.starts.data import structure_scale

    system = make_system("amplitude", soft=0.3, gain=1.5, tau=1.0)
    kw = dict(duration=12.0, dt=0.02, channels=("a",))
    weak = Record.simulate(system, "el_centro", scale=0.1, **kw)
    strong = Record.simulate(system, "kobe", scale=0.5, **kw)
    both = concatenate([weak, strong])
    scale = structure_scale(both)
    assert scale["w0"] == pytest.approx(np.sqrt(600.0), rel=0.2)  # k = 600 per unit mass, softened
    assert scale["w0"] == pytest.approx(2 * np.pi * fundamental(both)[0])  # the joined records' resonance
    x = simulate_response(system, system.true_values(), strong)["x"][:, 0]
    assert scale["a_ref"] == pytest.approx(np.max(np.abs(x)), rel=0.6)  # a displacement of the strong one
    cfg = compose("train", groups={"system": "amplitude"}, values={"system.w0": None, "system.a_ref": None})
    built, _ = system_and_record(cfg, both)
    term = next(t for t in built.terms if t.name == "amplitude_softening")
    assert (term.w0, term.a_ref) == (pytest.approx(scale["w0"]), pytest.approx(scale["a_ref"]))
    assert cfg.system.w0 == pytest.approx(scale["w0"])  # the run's config says what it used
    # a finished run read back: the new record's own scale is not the model's
    run = Identified(
        tmp_path,
        compose("train", groups={"system": "amplitude"}, values={"system.w0": None, "system.a_ref": None}),
        {"scale": scale, "params": system.true_values()},
    )
    rebuilt, _, _ = run.for_record(record=weak)
    again = next(t for t in rebuilt.terms if t.name == "amplitude_softening")
    assert again.a_ref == pytest.approx(scale["a_ref"]) != pytest.approx(structure_scale(weak)["a_ref"])


def test_an_amplitude_system_built_directly_asks_for_its_scale():
    from pidyn.systems import AmplitudeDependent

    with pytest.raises(ValueError, match="a_ref and w0 are null"):
        AmplitudeDependent(a_ref=None, w0=None)


def test_a_strong_motion_archive_from_several_events_gets_the_amplitude_model_by_default(tmp_path):
    """``data=csmip`` without ``system=``: one event gets the linear model, several events the
    amplitude model on the same layout with its scale read from them; a named system wins; a run
    read back settles its model by its own records, not by the record it predicts."""
    from omegaconf import OmegaConf, open_dict

    from pidyn.config import compose
    from pidyn.runs.folder import COMPLETE
    from pidyn.runs.prediction import Identified

    one = compose("train", groups={"data": "csmip"}, overrides=["data.path=a.zip"])
    several = compose("train", groups={"data": "csmip"}, overrides=["data.paths=[a.zip,b.zip]"])
    named = compose(
        "train", groups={"data": "csmip", "system": "linear"}, overrides=["data.paths=[a.zip,b.zip]"]
    )
    assert one.system._target_ == "pidyn.systems.LinearSDOF" and "several_records" not in one.system
    assert several.system._target_ == "pidyn.systems.AmplitudeDependent"
    assert several.system.w0 is None and several.system.a_ref is None  # read from the records
    assert several.system.inputs is None  # the records' supports, as the linear model's
    assert named.system._target_ == "pidyn.systems.LinearSDOF"
    # Hydra keeps the config as composed: the run read back chooses again, by its own data.paths
    raw = compose("train", groups={"data": "csmip"}, overrides=["data.paths=[a.zip,b.zip]"])
    with open_dict(raw):
        raw.system = compose("train", groups={"data": "csmip"}).system  # nothing chosen yet
        raw.system.several_records = OmegaConf.to_container(several.system)
    (tmp_path / ".hydra").mkdir()
    OmegaConf.save(raw, tmp_path / ".hydra" / "config.yaml")
    (tmp_path / "metrics.json").write_text(json.dumps({"params": {}}))
    (tmp_path / COMPLETE).write_text("{}")
    assert Identified.load(tmp_path).cfg.system._target_ == "pidyn.systems.AmplitudeDependent"


def test_the_default_several_event_run_fits_its_linear_model_beside_and_a_prediction_scores_it(tmp_path):
    """The amplitude model that several events get by default keeps the linear model of its layout
    beside it, fitted on the same fitting part; a prediction scores that linear model
    (``linear_mean_nrmse_a``) without a second run. With no softening and no added damping the
    amplitude model is that linear model, and the two predictions agree."""
    from pidyn.config import compose
    from pidyn.runs.build import system_and_record
    from pidyn.runs.linear_beside import fit_linear_beside
    from pidyn.runs.prediction import Identified, predict_record

    records = ROOT / "data" / "painter_street" / "records"
    paths = [str(records / f"{e}_ce89324p.zip") for e in ("nc73947830", "capemendocino_21nov1986")]
    over = [f"data.paths=[{','.join(paths)}]", "data.station=CE89324"]
    cfg = compose("train", groups={"data": "csmip"}, overrides=over)
    assert cfg.linear_system._target_ == "pidyn.systems.LinearSDOF"
    system, record = system_and_record(cfg, None)
    assert system.name == "amplitude" and cfg.system.w0 > 0  # the scale read from the two events
    linear = fit_linear_beside(cfg, record, hold_out=True)
    assert linear is not None and linear["system"] == "linear_sdof" and linear["start"] == "data"
    assert linear["params"]["k"] > 0 and set(linear["params"]) < {s.name for s in system.param_specs()}
    values = {**{s.name: s.init for s in system.param_specs()}, **linear["params"], "soft": 0.0, "gain": 0.0}
    metrics = {"params": values, "scale": {k: cfg.system[k] for k in ("w0", "a_ref")}, "linear_model": linear}
    run = Identified(tmp_path, cfg, metrics)
    new = Record.from_csmip(
        records / "riodell82_ce89324p.zip", station="CE89324", max_outputs=1, on_missing="drop"
    )
    out, _ = predict_record(run, new)
    assert out["linear_mean_nrmse_a"] == pytest.approx(out["mean_nrmse_a"], rel=1e-6)
    assert (
        compose("train", groups={"data": "csmip"}, overrides=over[:1][:0] + ["data.path=x.zip"]).linear_system
        is None
    )


def test_a_record_of_several_splits_back_into_its_records():
    a, b = _records()
    parts = split(concatenate([a, b]))
    assert [p.name for p in parts] == [a.name, b.name]
    for part, own in zip(parts, (a, b), strict=True):
        assert np.allclose(part.t, own.t - own.t[0], rtol=0, atol=1e-9) and np.array_equal(part.x, own.x)
        assert np.array_equal(part.f, own.f) and part.meta.pieces is None
    assert split(a) == [a]
    # a run that held out the end of its last record chooses its model without that part
    from dataclasses import replace

    from pidyn.data.meta import Split
    from pidyn.runs.model_choice import fitting_records

    held = [replace(r, meta=r.meta.with_(split=Split.at(5.0, float(r.t[-1])))) for r in (a, b)]
    joined = concatenate(held)
    first, last = fitting_records(joined, hold_out=True)
    assert first.t[-1] == pytest.approx(a.t[-1]) and last.t[-1] == pytest.approx(5.0)
    assert fitting_records(joined, hold_out=False)[1].t[-1] == pytest.approx(b.t[-1])


def _amplitude_runs(soft: float, gain: float):
    """Three records of an amplitude-dependent structure, weak to strong, and the config of a run
    from several records with the linear model of the same layout beside it."""
    from omegaconf import open_dict

    from pidyn.config import compose
    from pidyn.data.multi import concatenate
    from pidyn.starts.data import structure_scale

    system = make_system("amplitude", soft=soft, gain=gain, tau=1.0)
    kw = dict(duration=10.0, dt=0.02, channels=("a",))
    recs = [
        Record.simulate(system, ev, scale=s, seed=i, noise=0.01, **kw)
        for i, (ev, s) in enumerate((("el_centro", 0.1), ("kobe", 0.3), ("northridge", 0.5)))
    ]
    joined = concatenate(recs)
    cfg = compose(
        "train",
        groups={"system": "amplitude"},
        values={f"system.{k}": v for k, v in structure_scale(joined).items()},
    )
    with open_dict(cfg):
        cfg.linear_system = compose("train", groups={"system": "linear"}).system
    return cfg, joined


def test_the_run_keeps_its_amplitude_model_where_its_left_out_records_say_it_predicts_better():
    """``model_choice``: each record predicted by both models refitted without it. Records of a
    structure that softens in strong shaking: the amplitude model predicts every left-out record
    better than the linear model of its layout, and is kept."""
    from pidyn.refine.output_error import fit_output_error
    from pidyn.runs.build import system_and_record
    from pidyn.runs.linear_beside import linear_config
    from pidyn.runs.model_choice import ChoiceSettings, choose_model

    cfg, joined = _amplitude_runs(soft=0.8, gain=1.5)
    system, _ = system_and_record(cfg, joined)
    linear, _ = system_and_record(linear_config(cfg), joined)
    lin_fit = fit_output_error(joined, linear, {"k": 500.0, "c": 3.0})
    truth = make_system("amplitude", soft=0.8, gain=1.5, tau=1.0).true_values()
    out = choose_model(cfg, system, joined, truth, {"params": lin_fit.params}, ChoiceSettings(folds=5))
    assert out is not None and out["chosen"] == "nonlinear" and "note" not in out
    assert [r["record"] for r in out["records"]] == [p.name for p in pieces(joined)]  # each left out once
    assert out["nonlinear_better"] == "3 of 3"
    assert out["mean_nrmse_a"]["nonlinear"] < 0.5 * out["mean_nrmse_a"]["linear"]
    assert (
        choose_model(cfg, system, split(joined)[0], truth, {"params": lin_fit.params}) is None
    )  # one record


def test_a_left_out_record_enters_no_refit_of_the_choice():
    """``model_choice.start: data``: a fold's refits start from the other records alone, so the
    run's fitted values (which saw every record) change nothing in the choice; started from them
    (``start: run``), the left-out records' predictions move with them."""
    from pidyn.runs.build import system_and_record
    from pidyn.runs.model_choice import ChoiceSettings, choose_model

    cfg, joined = _amplitude_runs(soft=0.8, gain=1.5)
    system, _ = system_and_record(cfg, joined)
    truth = make_system("amplitude", soft=0.8, gain=1.5, tau=1.0).true_values()
    other = {**truth, "k": 1.3 * truth["k"], "c": 0.7 * truth["c"], "soft": 0.3, "gain": 0.5}
    linear = {"params": {"k": 450.0, "c": 4.0}}

    def rows(values, start):
        out = choose_model(cfg, system, joined, values, linear, ChoiceSettings(folds=5, start=start))
        return [(r["nonlinear"], r["linear"]) for r in out["records"]]

    assert rows(truth, "data") == rows(other, "data")
    assert rows(truth, "run") != rows(other, "run")
    with pytest.raises(ValueError, match="model_choice.start"):
        ChoiceSettings.of({"start": "fold"})


def test_a_run_whose_records_chose_the_linear_model_predicts_with_it(tmp_path):
    """Where ``model_choice`` chose the linear model beside the run's own, ``predict.py`` and
    ``pidyn.predict`` simulate that one: its prediction is the linear model's score."""
    from pidyn.runs.model_choice import ChoiceSettings, _decide
    from pidyn.runs.prediction import Identified, predict_record

    rows = [
        {"record": "a", "nonlinear": 0.9, "linear": 0.5},
        {"record": "b", "nonlinear": 0.4, "linear": 0.45},
    ]
    choice = _decide("amplitude", "linear_sdof", rows, 1.0)
    assert choice["chosen"] == "linear" and choice["note"].endswith("[nonlinear_not_earned]")
    assert choice["nonlinear_better"] == "1 of 2"
    cfg, joined = _amplitude_runs(soft=0.8, gain=1.5)
    truth = make_system("amplitude", soft=0.8, gain=1.5, tau=1.0).true_values()
    linear = {"system": "linear_sdof", "params": {"k": 450.0, "c": 4.0}}
    scale = {k: cfg.system[k] for k in ("w0", "a_ref")}
    run = Identified(
        tmp_path, cfg, {"params": truth, "scale": scale, "linear_model": linear, "system": "amplitude"}
    )
    own, _ = predict_record(run, split(joined)[2])
    chosen = Identified(tmp_path, cfg, {**run.metrics, "model_choice": choice}).chosen()
    assert chosen.metrics["system"] == "linear_sdof" and run.chosen() is run
    out, _ = predict_record(chosen, split(joined)[2])
    assert out["mean_nrmse_a"] == pytest.approx(out["linear_mean_nrmse_a"], rel=1e-9)
    assert out["mean_nrmse_a"] > own["mean_nrmse_a"] and out["model_choice"] == "linear"
    assert out["model_choice_decisive"] is False  # two records cannot tell the models apart
    assert own["model_choice_decisive"] is None  # a run that did not choose
    with pytest.raises(ValueError, match="model_choice: unknown setting"):
        ChoiceSettings.of({"fold": 3})


def test_the_choice_says_when_its_records_cannot_tell_the_two_models_apart():
    """``decisive``: the paired log ratio of the left-out records' NRMSEs more than two standard
    errors from 0. A consistent 20 % gain on eight records decides; a gain on most records and one
    record lost badly (the mean ratio near 1) does not, and says so in a note; a model that could
    not predict a record at all is decided against."""
    from pidyn.runs.model_choice import _decide, paired_ratio
    from pidyn.runs.report import _choice_lines

    steady = [{"record": f"r{i}", "nonlinear": 0.4 * (1 + 0.02 * i), "linear": 0.5} for i in range(8)]
    out = _decide("amplitude", "linear_sdof", steady, 1.0)
    assert out["chosen"] == "nonlinear" and out["decisive"] and "undecided" not in out
    assert out["log_ratio"] == pytest.approx(np.mean([np.log(r["nonlinear"] / 0.5) for r in steady]))
    mixed = [{"record": f"r{i}", "nonlinear": 0.45, "linear": 0.5} for i in range(7)]
    mixed.append({"record": "bad", "nonlinear": 1.0, "linear": 0.5})
    out = _decide("amplitude", "linear_sdof", mixed, 1.0)
    assert out["chosen"] == "linear" and out["nonlinear_better"] == "7 of 8"  # the mean's choice stands
    assert out["decisive"] is False and out["undecided"].endswith("[model_choice_undecided]")
    assert "cannot tell amplitude from linear_sdof" in out["undecided"]
    assert _choice_lines(out, "amplitude")[-1] == f"Undecided: {out['undecided']}."
    failed = [
        {"record": "a", "nonlinear": float("inf"), "linear": 0.5},
        {"record": "b", "nonlinear": 0.4, "linear": 0.5},
    ]
    assert paired_ratio(failed)["decisive"] is True


def test_a_prediction_says_when_its_record_shakes_harder_or_more_weakly_than_the_runs_records(tmp_path):
    from pidyn.runs.prediction import Identified, training_range

    records = [{"name": "a", "pga": 1.0}, {"name": "b", "pga": 3.0}]
    run = Identified(tmp_path, None, {"record_meta": {"records": records, "pga": 3.0}})
    assert training_range(run, 4.5) == {"training_pga": [1.0, 3.0], "beyond_training": 1.5}
    assert training_range(run, 0.5)["beyond_training"] == 0.5
    assert training_range(run, 2.0)["beyond_training"] is None
    one = Identified(tmp_path, None, {"record_meta": {"pga": 2.0}})  # one record: its own peak
    assert training_range(one, 2.0) == {"training_pga": [2.0, 2.0], "beyond_training": None}
    assert training_range(one, None) == {"training_pga": None, "beyond_training": None}


def test_a_prediction_carries_the_runs_verdict_on_the_model_that_predicts(tmp_path):
    """A model its own records reject (here: one RK4 cannot simulate at the record's step) is
    said so in prediction.json, however it scores on the new record; the linear model beside it
    was not what the run's adequacy test judged, so its verdict is unknown, not borrowed."""
    from pidyn.config import compose
    from pidyn.runs.prediction import Identified, run_verdict

    why = "the identified model cannot be simulated stably at the record's step"
    rejected = {"adequacy": {"adequate": False, "reasons": [why]}, "params": {"k": 1.0}}
    assert run_verdict(Identified(tmp_path, None, rejected)) == {
        "model_adequate": False,
        "model_rejected_because": [why],
    }
    kept = {"adequacy": {"adequate": True, "reasons": []}, "params": {"k": 1.0}}
    assert run_verdict(Identified(tmp_path, None, kept)) == {
        "model_adequate": True,
        "model_rejected_because": [],
    }
    assert run_verdict(Identified(tmp_path, None, {"params": {}}))["model_adequate"] is None

    over = ["data.paths=[a.zip,b.zip]", "data.station=CE89324"]
    cfg = compose("train", groups={"data": "csmip"}, overrides=over)
    linear = {"system": "linear_sdof", "params": {"c": 1.0, "k": 600.0}}
    beside = Identified(tmp_path, cfg, {**rejected, "linear_model": linear}).linear_beside()
    assert beside is not None and run_verdict(beside)["model_adequate"] is None


def test_the_records_weighting_runs_from_the_joined_spread_to_each_records_own():
    """``data.record_weighting`` p: each record's weight is (joined spread / own) ** p; 0 leaves the
    joined spread (no weights), 1 each record's own, and a value outside [0, 1] is a named error."""
    from pidyn.data.errors import DataError
    from pidyn.refine.problem import record_weights

    r1, r2 = _records()
    own = record_channels(concatenate([r1, r2]), 1)[0]
    assert record_channels(concatenate([r1, r2], weighting=0.0), 1)[0].weight is None
    half = record_channels(concatenate([r1, r2], weighting=0.5), 1)[0]
    np.testing.assert_allclose(half.weight**2, own.weight, rtol=1e-12)
    assert own.weight.min() < 1.0 < own.weight.max()  # the stronger record weighs less, the weaker more
    joined = concatenate([r1, r2], weighting=0.5)
    assert concatenate(split(joined)).meta.record_weighting == 0.5  # a model choice's refits keep it
    assert record_weights(r1, r1.x) is None
    with pytest.raises(DataError, match="data.record_weighting must be a number from 0 to 1"):
        concatenate([r1, r2], weighting=2)


def test_data_record_weighting_reaches_the_joined_record(tmp_path):
    """``data.record_weighting`` from the config to the joined record a run fits."""
    from pidyn.config import compose
    from pidyn.runs.build import build_record

    paths = []
    for i, r in enumerate(_records()):
        path = tmp_path / f"r{i}.csv"
        pd.DataFrame({"t": r.t, "x": r.x[:, 0], "v": r.v[:, 0], "ag": r.f}).to_csv(path, index=False)
        paths.append(str(path))
    cfg = compose(
        "train", groups={"data": "csv"}, values={"data.paths": paths, "data.record_weighting": 0.25}
    )
    record = build_record(cfg, make_system("duffing"))
    assert len(pieces(record)) == 2 and record.meta.record_weighting == 0.25
    cfg.data.record_weighting = "half"
    with pytest.raises(DataError, match="data.record_weighting .* got 'half'"):
        build_record(cfg, make_system("duffing"))
