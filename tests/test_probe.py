"""The command line as a hostile new user meets it: every bad input and fault ends with exit status
2 (130/143 when interrupted) and one line that names the problem, and leaves a run folder that
tells the truth (no ``metrics.json`` or ``complete.json`` where the run did not finish, the
reason in ``failed.json``, another run's folder untouched); a killed run resumes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT, make_cfg

from pidyn.data.sources import Record
from pidyn.runs.folder import COMPLETE, FAILED, LOCK

PAINTER = ROOT / "data" / "painter_street" / "records" / "nc73821046_ce89324p.zip"


def _cli(args: list[str], script: str = "train.py", timeout: float = 240) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, script, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, env=env
    )


def _error_line(proc: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in (proc.stdout + proc.stderr).splitlines() if "ERROR" in ln or "Error" in ln]
    return lines[-1] if lines else (proc.stdout + proc.stderr)[-500:]


@pytest.fixture(scope="module")
def clean_csv(tmp_path_factory) -> Path:
    rec = Record.simulate("duffing", excitation="kobe", duration=12, noise=0.02)
    path = tmp_path_factory.mktemp("csv") / "clean.csv"
    pd.DataFrame({"t": rec.t, "ag": rec.f, "x": rec.x[:, 0], "v": rec.v[:, 0]}).to_csv(path, index=False)
    return path


def _variant(clean: Path, tmp_path: Path, name: str, change) -> Path:
    df = pd.read_csv(clean)
    out = tmp_path / f"{name}.csv"
    change(df).to_csv(out, index=False)
    return out


def _assert_refused(proc, run: Path, *words: str) -> None:
    line = _error_line(proc)
    assert proc.returncode == 2, (proc.returncode, line)
    for w in words:
        assert w in line, line
    assert not (run / "metrics.json").exists() and not (run / COMPLETE).exists()


def _zeros(df):
    return df.assign(ag=0.0, x=0.0, v=0.0)


def _text(df):
    df = df.astype({"x": object})
    df.loc[5, "x"] = "abc"
    return df


def _ms(df):
    return df.assign(t=df.t * 1000.0)


def _train_refused(overrides: list[str], run: Path, *words: str) -> None:
    """The same refusal in-process, as the command line's own call makes it (``_cli`` proves the
    exit status and the one line once; each further start of a process costs seconds)."""
    from pidyn.tasks.train import train

    with pytest.raises(ValueError) as exc:  # every user error (the command line exits 2 on them)
        train(make_cfg(overrides, run))
    for w in words:
        assert w in str(exc.value), str(exc.value)
    assert not (run / "metrics.json").exists() and not (run / COMPLETE).exists()


@pytest.mark.parametrize(
    "name,change,words,cli",
    [
        ("zeros", _zeros, ["no excitation"], True),
        ("text", _text, ["column 'x' is not numeric", "row 7", "abc"], False),
        ("ms", _ms, ["milliseconds"], False),
    ],
)
def test_bad_files_are_refused_by_name(clean_csv, tmp_path, name, change, words, cli):
    path = _variant(clean_csv, tmp_path, name, change)
    run = tmp_path / "run"
    overrides = ["data=csv", f"data.path={path}"]
    if cli:
        _assert_refused(_cli([*overrides, f"hydra.run.dir={run}"]), run, str(path), *words)
    else:
        _train_refused(overrides, run, str(path), *words)
    assert json.loads((run / FAILED).read_text())["error"] == "DataError"


def test_a_building_csv_with_more_floors_than_the_model_is_refused(clean_csv, tmp_path):
    df = pd.read_csv(clean_csv)
    path = tmp_path / "b4.csv"
    pd.DataFrame({"t": df.t, "ag": df.ag, **{f"a{i}": df.x * i for i in range(1, 5)}}).to_csv(
        path, index=False
    )
    overrides = ["system=shear_building", "system.n_storeys=3", "data=csv", f"data.path={path}"]
    _train_refused(overrides, tmp_path / "run", "a4", "n_storeys=4")


@pytest.mark.parametrize(
    "override,words",
    [
        ("noise=nan", ["setting 'noise' is nan"]),
        ("seed=abc", ["setting 'seed'", "integer"]),
        ("noise=abc", ["setting 'noise'"]),
        ("eq_scale=0", ["setting 'eq_scale'", "positive"]),
    ],
)
def test_bad_settings_are_refused_by_name(tmp_path, override, words):
    run = tmp_path / "run"
    _assert_refused(_cli([override, f"hydra.run.dir={run}"]), run, *words)


def test_a_misspelled_setting_exits_2_like_every_user_error(tmp_path):
    run = tmp_path / "run"
    proc = _cli(["sytem=duffing", f"hydra.run.dir={run}"])
    assert proc.returncode == 2 and "sytem" in proc.stdout + proc.stderr
    proc = _cli(["system=dufing", f"hydra.run.dir={run}"], script="diagnose.py")
    assert proc.returncode == 2 and "dufing" in proc.stdout + proc.stderr


def test_an_archive_of_another_station_is_refused(tmp_path):
    other = tmp_path / "other_station.zip"
    with zipfile.ZipFile(PAINTER) as src, zipfile.ZipFile(other, "w") as dst:
        for info in src.infolist():
            dst.writestr(info.filename, src.read(info).replace(b"Station No. 89324", b"Station No. 58658"))
    overrides = ["data=csmip", "system=linear", f"data.path={other}", "data.station=CE89324"]
    _train_refused(overrides, tmp_path / "run", "station CE58658", "data.station=CE89324")


def test_a_folder_another_run_holds_is_refused_and_left_as_it_is(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / LOCK).write_text(json.dumps({"pid": os.getpid(), "host": os.uname().nodename, "started": "now"}))
    (run / "metrics.json").write_text('{"theirs": true}')
    before = sorted(p.name for p in run.iterdir())
    proc = _cli([f"hydra.run.dir={run}"])
    assert proc.returncode == 2 and "holds this run folder" in _error_line(proc)
    # the other run's files as they were; its log gains the refusal's lines, nothing else
    assert sorted(p.name for p in run.iterdir() if p.name != "cli.log") == before
    assert json.loads((run / "metrics.json").read_text()) == {"theirs": True}
    assert "holds this run folder" in (run / "cli.log").read_text()
    assert not (run / ".hydra").exists()  # Hydra's record of the refused run is not written over the other's


def test_an_output_folder_that_cannot_be_made_is_a_user_error(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    proc = _cli([f"hydra.run.dir={blocker / 'run'}"])
    assert proc.returncode == 2


FAST = [
    "model.schedule.pretrain_iters=20",
    "model.schedule.pretrain_iters_window=10",
    "model.schedule.max_iters=20",
    "model.schedule.max_windows=2",
    "excitation.duration=12",
    "baselines=none",
]


def _start_until_first_window(args: list[str], run: Path, **popen) -> subprocess.Popen:
    """``train.py`` started in ``run``, returned once its first window's state is saved."""
    proc = subprocess.Popen(
        [sys.executable, "train.py", *args, f"hydra.run.dir={run}"],
        cwd=ROOT,
        stderr=subprocess.STDOUT,
        **popen,
    )
    deadline = time.time() + 180
    while not (run / "subperiod_state.json").exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.2)
    return proc


@pytest.mark.slow
def test_killed_failed_and_resumed_run_folder_tells_the_truth(tmp_path, monkeypatch, caplog):
    """Killed (SIGKILL, no handler) after its first window; then a write that fails as on a full
    disk; then resumed to the end, refusing on the way a run with another seed."""
    run = tmp_path / "run"
    proc = _start_until_first_window(FAST, run, stdout=subprocess.DEVNULL, start_new_session=True)
    time.sleep(float(np.random.default_rng().uniform(0.0, 1.0)))  # a point inside the second window
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert (run / "subperiod_state.json").exists()
    assert not (run / "metrics.json").exists() and not (run / COMPLETE).exists()
    assert (run / LOCK).exists()  # SIGKILL leaves its lock; its process is gone, so it is taken over

    from pidyn.runs import report
    from pidyn.tasks.train import train

    # another seed in the killed run's folder is refused (in-process: the command line exits 2 on
    # every such ValueError, proven above)
    with pytest.raises(ValueError, match="seed: 0 -> 1"):
        train(make_cfg([*FAST, "seed=1"], run))

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(report, "write_run_report", full_disk)
    with pytest.raises(OSError, match="No space left"):
        train(make_cfg(FAST, run))
    failed = json.loads((run / FAILED).read_text())
    assert failed["error"] == "OSError" and "No space left" in failed["message"]
    for claim in ("metrics.json", COMPLETE, "identified_params.yaml", "report.md", LOCK):
        assert not (run / claim).exists(), claim

    monkeypatch.undo()
    caplog.set_level("INFO")
    metrics = train(make_cfg(FAST, run))
    assert any("resuming at window" in r.getMessage() for r in caplog.records)
    assert (run / COMPLETE).exists() and not (run / FAILED).exists() and not (run / LOCK).exists()
    saved = json.loads((run / "metrics.json").read_text())
    assert saved["adequate"] is metrics["adequate"] and "adequacy" in saved


def test_the_api_raises_value_errors_not_a_frameworks(tmp_path):
    import pidyn

    with pytest.raises(ValueError, match="k3.*init > 0") as exc:
        pidyn.identify(None, "duffing", init={"k3": -5.0}, out_dir=tmp_path / "run", baselines="none")
    assert type(exc.value) is ValueError
    assert json.loads((tmp_path / "run" / FAILED).read_text())["error"] == "ValueError"
    proc = _cli(["system.params.k3.init=-5", f"hydra.run.dir={tmp_path / 'cli'}"])
    assert proc.returncode == 2 and "init > 0" in _error_line(proc)


@pytest.mark.slow
def test_sigterm_is_logged_and_the_folder_says_interrupted(tmp_path):
    run = tmp_path / "run"
    # windows long enough (400 iterations, seconds) that the signal, sent within 0.2 s of the
    # first window's end, lands inside the second
    longer = [o for o in FAST if "max_iters" not in o] + ["model.schedule.max_iters=400"]
    proc = _start_until_first_window(longer, run, stdout=subprocess.PIPE, text=True)
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 143, out[-2000:]
    assert "interrupted at" in out and "SIGTERM" in out and "run the same command again to resume" in out
    failed = json.loads((run / FAILED).read_text())
    assert (
        failed["error"] == "Interrupted" and not (run / "metrics.json").exists() and not (run / LOCK).exists()
    )
