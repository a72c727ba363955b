"""The Python API: plain values checked against the configs, a Result that a notebook can use,
and the walk-through example run end to end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pidyn

ROOT = Path(__file__).resolve().parents[1]
SMOKE = {"debug": "smoke", "baselines": "none", "logger": "none"}


def test_public_surface_is_listed_and_loads():
    for name in pidyn.__all__:
        assert getattr(pidyn, name) is not None, name
    assert "duffing" in pidyn.system_names() and "shear_building" in pidyn.system_names()
    with pytest.raises(AttributeError):
        pidyn.not_a_name  # noqa: B018


@pytest.mark.parametrize(
    "options, message",
    [
        ({"system": "dufing"}, "did you mean 'duffing'"),
        ({"model__schedule__max_windowz": 3}, "did you mean 'model.schedule.max_windows'"),
        ({"refine": "multiple"}, "choose from multiple_shooting, none"),
        ({"sytem__params__k3__init": 1.0}, "did you mean 'system'"),
    ],
)
def test_a_misspelled_option_names_the_valid_ones(options, message, tmp_path):
    record = pidyn.Record.simulate("duffing", duration=5.0)
    with pytest.raises(ValueError, match=message):
        pidyn.identify(record, out_dir=tmp_path, **options)
    assert not (tmp_path / "metrics.json").exists()


def test_record_constructors_agree(tmp_path):
    """simulate, from_at2 (a PEER file) and from_csv (the same samples written out) give one record."""
    sim = pidyn.Record.simulate("linear_sdof", excitation="el_centro", duration=4.0)
    at2 = ROOT / "src" / "pidyn" / "excitation" / "records"
    path = at2 / "ELCENTRO1940_RSN6_IMPVALL.I_I-ELC180.AT2"  # the record the name el_centro stands for
    from_file = pidyn.Record.from_at2(path, "linear_sdof", duration=4.0)
    assert np.allclose(sim.f, from_file.f) and np.allclose(sim.x, from_file.x)
    csv = tmp_path / "rec.csv"
    pd.DataFrame({"t": sim.t, "ag": sim.f, "x": sim.x[:, 0], "v": sim.v[:, 0]}).to_csv(csv, index=False)
    back = pidyn.Record.from_csv(csv)
    assert np.allclose(back.x, sim.x) and back.excitation == "ground"
    with pytest.raises(FileNotFoundError, match="no such AT2 file"):
        pidyn.Record.from_at2(tmp_path / "missing.AT2", "duffing")


def test_identify_returns_a_result_a_notebook_can_use(tmp_path):
    record = pidyn.Record.simulate("duffing", duration=12.0)
    res = pidyn.identify(record, "duffing", init={"k3": 100.0}, out_dir=tmp_path / "run", **SMOKE)
    frame = res.to_frame()
    assert list(frame.index) == ["c", "k1", "k3"]
    assert {"value", "ci95_lo", "ci95_hi", "std", "truth", "error_pct", "pidynnet"} <= set(frame.columns)
    assert (frame.ci95_lo <= frame.value).all() and (frame.value <= frame.ci95_hi).all()
    assert frame.loc["k3", "truth"] == 120.0
    assert "x^3" in res.equation and len(res.history) > 0
    assert res.plot() is not None
    saved = res.save(tmp_path / "copy")
    assert (
        (saved / "params.csv").exists()
        and (saved / "history.csv").exists()
        and (saved / "metrics.json").exists()
    )
    again = pidyn.Result.load(saved)
    assert again.params == res.params and again.ci95 == res.ci95
    with pytest.raises(ValueError, match="networks of an identification run"):
        pidyn.predict(again, "el_centro")
    with pytest.raises(ValueError, match="unknown setting"):
        pidyn.predict(res, "el_centro", iteration=10)


@pytest.mark.second_proof  # the API is proven by test_identify_returns_a_result_a_notebook_can_use
def test_walkthrough_example_runs(tmp_path):
    """examples/api_walkthrough.py --quick: identification, prediction and diagnosis through the API."""
    run = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "api_walkthrough.py"), "--quick", "--out", str(tmp_path)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert "verdict: discrepancy, causes ['quadratic_damping']" in run.stdout, run.stdout[-2000:]
    assert (tmp_path / "duffing_saved" / "params.csv").exists()
    assert (tmp_path / "diagnosis" / "report.md").exists()
    pred = pd.read_csv(tmp_path / "prediction_el_centro.csv")
    assert np.corrcoef(pred.x1_pidynnet, pred.x1_simulated)[0, 1] > 0.95


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="the baselines run in a worker only with a second core")
@pytest.mark.slow
def test_a_plain_script_without_a_main_guard_runs_once(tmp_path):
    """The baselines' worker must not import the caller's script: a top-level
    ``pidyn.identify(...)`` without ``if __name__ == "__main__"`` runs (and prints) once."""
    script = tmp_path / "plain.py"
    script.write_text(
        "import pidyn\n"
        "record = pidyn.Record.simulate('duffing', duration=12.0)\n"
        "res = pidyn.identify(record, 'duffing', out_dir='run', debug='smoke', logger='none',\n"
        "                     baselines__run=['equation_error'], baselines__parallel=True)\n"
        "print('IDENTIFIED', res.to_frame().shape[0])\n"
    )
    out = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.count("IDENTIFIED") == 1, out.stdout
    assert "baseline worker failed" not in out.stderr, out.stderr[-2000:]
    rows = json.loads((tmp_path / "run" / "baselines.json").read_text())["baselines"]
    assert rows[0]["method"] == "equation_error" and rows[0]["params"], rows


def test_a_notebook_without_logging_sees_the_progress_lines_and_a_configured_program_keeps_its_own(capfd):
    import logging

    from pidyn.api import _progress

    root = logging.getLogger()
    saved = root.handlers[:]
    root.handlers.clear()  # a notebook: nobody configured logging
    try:
        with _progress():
            logging.getLogger("pidyn.models.identify").info("window 1 of 8")
        assert "window 1 of 8" in capfd.readouterr().err
        assert not logging.getLogger("pidyn").handlers  # removed after the call
        with _progress(False):  # a call's progress=False: silent
            logging.getLogger("pidyn.models.identify").info("window 2 of 8")
        assert "window 2 of 8" not in capfd.readouterr().err
        mine = logging.StreamHandler()
        root.addHandler(mine)
        with _progress():
            assert not logging.getLogger("pidyn").handlers  # the program's own handler decides
    finally:
        root.handlers[:] = saved


@pytest.mark.slow
def test_a_notebooks_diagnosis_shows_its_steps_with_the_time_left(capfd, tmp_path):
    """``pidyn.diagnose`` in a notebook (nobody configured logging): the diagnosis's steps as k of
    6 and its output-error checks as k of n, with the time left at the pace so far, on stderr."""
    import logging

    import pidyn

    root = logging.getLogger()
    saved = root.handlers[:]
    root.handlers.clear()
    try:
        pidyn.diagnose(None, "linear", debug="smoke", data__source__effect="none", out_dir=tmp_path / "d")
    finally:
        root.handlers[:] = saved
    err = capfd.readouterr().err
    for k, label in enumerate(["the nominal model", "screening", "held-out check", "the first cause"], 1):
        assert f"diagnosis {k}/6: {label}" in err, err[-3000:]
    assert "s left at this pace" in err and "diagnosis 6/6: simulations and modes" in err


def test_a_data_reader_is_a_group_choice_and_its_settings_follow_it():
    """``data="csmip", data__station="CE89324"``: the reader chosen as a group (not a string
    written over the data node), its settings applied after it."""
    from pidyn.api import _split_options
    from pidyn.config import compose

    groups, values = _split_options({"data": "csmip", "data__station": "CE89324"})
    assert groups == {"data": "csmip"} and values == {"data.station": "CE89324"}
    cfg = compose("diagnose", groups=groups, values=values)
    assert cfg.data.station == "CE89324" and cfg.data.on_missing == "error"  # the csmip reader's node
