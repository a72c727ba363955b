"""pidyn installs as a package: a wheel carries its configs, records and commands.

The wheel is built from a copy of the sources, installed into a fresh virtual environment
outside the checkout (its dependencies seen through this environment's site-packages, so
nothing is downloaded), and ``pidyn-train debug=smoke`` runs from an empty directory.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _build_wheel(tmp: Path) -> Path:
    src = tmp / "src_copy"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "src", src / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    out = tmp / "wheel"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            str(src),
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(out),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    (wheel,) = out.glob("pidyn-*.whl")
    return wheel


def _fresh_env(tmp: Path, wheel: Path) -> Path:
    env_dir = tmp / "fresh"
    subprocess.run([sys._base_executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    purelib = Path(
        subprocess.check_output(
            [
                str(env_dir / "bin" / "python"),
                "-c",
                "import sysconfig; print(sysconfig.get_paths()['purelib'])",
            ],
            text=True,
        ).strip()
    )
    # the dependencies (torch, lightning, hydra, ...) come from this environment, pidyn from the wheel
    (purelib / "_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(env_dir / "bin" / "python"),
            "install",
            "--no-deps",
            "-q",
            str(wheel),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return env_dir


@pytest.mark.slow
def test_wheel_installs_and_pidyn_train_runs_from_any_directory(tmp_path):
    wheel = _build_wheel(tmp_path)
    names = zipfile.ZipFile(wheel).namelist()
    assert "pidyn/conf/train.yaml" in names and "pidyn/conf/system/bouc_wen.yaml" in names
    assert any(n.startswith("pidyn/excitation/records/") and n.endswith(".AT2") for n in names)
    assert "pidyn/py.typed" in names and any(n.endswith("licenses/LICENSE") for n in names)
    meta = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("METADATA"))).decode()
    import pidyn

    assert f"Version: {pidyn.__version__}" in meta and "quakeio" not in meta  # the version written once

    env_dir = _fresh_env(tmp_path, wheel)
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    where = subprocess.check_output(
        [str(env_dir / "bin" / "python"), "-c", "import pidyn; print(pidyn.__file__)"],
        cwd=work,
        env=env,
        text=True,
    ).strip()
    assert Path(where).is_relative_to(env_dir), f"pidyn imported from {where}, not from the installed wheel"

    run = subprocess.run(
        [
            str(env_dir / "bin" / "pidyn-train"),
            "debug=smoke",
            "logger=none",
            "baselines=none",
            "model.refine=none",
            "hydra.run.dir=run",
        ],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    metrics = json.loads((work / "run" / "metrics.json").read_text())
    assert set(metrics["params"]) == {"c", "k1", "k3"}
