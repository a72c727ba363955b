import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
import aggregate  # noqa: E402


def job(d: Path, seed: int, k3: float, ukf_err: float) -> None:
    d.mkdir(parents=True)
    (d / "complete.json").write_text('{"task": "train"}')  # a finished run says so last
    (d / "metrics.json").write_text(
        json.dumps(
            {
                "system": "duffing",
                "record": "kobe",
                "noise": 0.05,
                "batch_size": 500,
                "eq_scale": 1.0,
                "seed": seed,
                "params": {"k3": k3},
                "truth": {"k3": 120.0},
                "error_pct": {"k3": abs(k3 - 120) / 1.2},
                "wall_seconds": 10.0,
            }
        )
    )
    (d / "baselines.json").write_text(
        json.dumps(
            {
                "baselines": [
                    {
                        "method": "ukf",
                        "params": {"k3": 0.0},
                        "error_pct": {"k3": ukf_err},
                        "seconds": 1.0,
                        "trajectory": [{"t": 0.1 * i, "k3": 100.0 + i} for i in range(30)],
                    }
                ]
            }
        )
    )
    (d / "subperiod_state.json").write_text(
        json.dumps(
            {"trajectory": [{"iteration": 10 * i, "t": 0.2 * i, "k3": 110.0 + 0.1 * i} for i in range(20)]}
        )
    )
    (d / "cramer_rao.json").write_text(json.dumps({"std_pct": {"k3": 0.1}}))


def test_aggregate_means_rms_and_failed_jobs(tmp_path):
    job(tmp_path / "0_seed=0", 0, 121.2, 3.0)
    job(tmp_path / "1_seed=1", 1, 118.8, 4.0)
    (tmp_path / "2_seed=2").mkdir()  # a failed job: no metrics.json
    job(tmp_path / "3_seed=3", 3, 50.0, 1.0)  # results written, but the run did not finish: not counted
    (tmp_path / "3_seed=3" / "complete.json").unlink()
    for d in ("0_seed=0", "1_seed=1"):  # a baseline that cannot apply: no error, no seconds, its reason shown
        b = json.loads((tmp_path / d / "baselines.json").read_text())
        b["baselines"].append(
            {
                "method": "equation_error",
                "params": {},
                "seconds": 0.0,
                "note": "not applicable: unmeasured latent state",
            }
        )
        (tmp_path / d / "baselines.json").write_text(json.dumps(b))
    df, failed = aggregate.aggregate(tmp_path)
    row = df.iloc[0]
    assert np.isnan(row.equation_error_rms_err) and np.isnan(row.equation_error_seconds)
    assert failed == ["2_seed=2", "3_seed=3"]
    assert row.seeds == 2 and row.pidynnet_mean == pytest.approx(120.0)
    assert row.pidynnet_rms_err == pytest.approx(1.0)
    assert row.ukf_rms_err == pytest.approx((12.5) ** 0.5)
    md = aggregate.to_markdown(df, "t", "cmd", failed)
    assert "Failed jobs" in md and "| k3 |" in md
    assert "EE -," in md and "EE: not applicable: unmeasured latent state." in md


def test_aggregate_joins_sweeps_reads_stretch_from_config_and_summarises(tmp_path):
    """Cells from several sweep folders in one table; a job whose metrics.json predates the
    eq_stretch key takes it from its own .hydra/config.yaml instead of counting as stretch 1."""
    a, b = tmp_path / "scaling", tmp_path / "scaling_t1.5"
    job(a / "0_seed=0", 0, 121.2, 3.0)
    job(b / "0_seed=0", 0, 114.0, 6.0)
    (b / "0_seed=0" / ".hydra").mkdir()
    (b / "0_seed=0" / ".hydra" / "config.yaml").write_text("eq_scale: 1.0\neq_stretch: 1.5\nseed: 0\n")
    (b / "1_seed=1").mkdir()
    df, failed = aggregate.aggregate([a, b])
    assert failed == ["scaling_t1.5/1_seed=1"]
    assert sorted(df.eq_stretch) == [1.0, 1.5]
    assert df.set_index("eq_stretch").pidynnet_rms_err[1.5] == pytest.approx(5.0)
    md = aggregate.to_markdown(df, "t", "cmd", failed)
    assert "(stretch 1.5)" in md and "(stretch 1)" in md
    summary = md.split("## Summary, duffing")[1].split("\n## ")[0]
    rows = [r for r in summary.splitlines() if r.startswith("| kobe")]
    assert rows == [
        "| kobe | 1 | 1 | 5 | 500 | 1 | 1 / - / - / 3 (0.1) |",
        "| kobe | 1 | 1.5 | 5 | 500 | 1 | 5 / - / - / 6 (0.1) |",
    ]
    one, _ = aggregate.aggregate(a)
    assert "## Summary" not in aggregate.to_markdown(one, "t", "cmd", [])


def test_refined_runs_give_the_refinement_column_and_interval_coverage(tmp_path):
    """A run with a refinement stage: PIDynNet's column reads ``pidynnet``, the refined one
    ``params``; coverage counts the seeds whose 95 % interval holds the truth."""
    for seed, (k3, ci) in enumerate([(120.1, [119.9, 120.3]), (120.4, [120.2, 120.6])]):
        d = tmp_path / f"{seed}_seed={seed}"
        job(d, seed, k3, 3.0)
        m = json.loads((d / "metrics.json").read_text())
        m.update(
            {
                "refine": "multiple_shooting",
                "pidynnet": {"params": {"k3": 126.0}, "error_pct": {"k3": 5.0}},
                "ci95": {"k3": ci},
                "refinement": {"seconds": 4.0},
            }
        )
        (d / "metrics.json").write_text(json.dumps(m))
    df, _ = aggregate.aggregate(tmp_path)
    row = df.iloc[0]
    assert row.pidynnet_rms_err == pytest.approx(5.0) and row.pidynnet_mean == pytest.approx(126.0)
    assert row.refined_mean == pytest.approx(120.25)
    assert row.coverage == pytest.approx(0.5) and row.refine_seconds == pytest.approx(4.0)
    assert row.refined_over_crb == pytest.approx(row.refined_rms_err / 0.1)


def test_aggregate_draws_figure_3_per_cell_and_links_it(tmp_path):
    job(tmp_path / "sweep" / "0_seed=0", 0, 121.2, 3.0)
    job(tmp_path / "sweep" / "1_seed=1", 1, 118.8, 4.0)
    out = tmp_path / "results" / "table9"
    r = subprocess.run(
        [
            sys.executable,
            "experiments/aggregate.py",
            str(tmp_path / "sweep"),
            "--out",
            str(out),
            "--title",
            "t",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    (png,) = (tmp_path / "results" / "figures").glob("table9_*.png")
    assert png.name == "table9_duffing_kobe_x1_stretch1_noise5_batch500.png"
    from PIL import Image

    rgb = np.asarray(Image.open(png).convert("RGB")).reshape(-1, 3).astype(int)
    r, b = rgb[:, 0], rgb[:, 2]
    assert (b > r + 40).sum() > 200, "no PIDynNet (blue) curve"
    assert (r > b + 60).sum() > 200, "no UKF (orange) curve"
    assert f"](figures/{png.name})" in out.with_suffix(".md").read_text()


@pytest.mark.slow
def test_tables_smoke_runs_a_multirun_and_aggregates(tmp_path):
    r = subprocess.run(
        [sys.executable, "experiments/run_tables.py", "--smoke", "--only", "table2", "--jobs", "1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    mds = sorted((ROOT / "outputs" / "tables-smoke").glob("*/table2.md"))
    assert mds and "| beta |" in mds[-1].read_text()


@pytest.mark.second_proof  # a multirun and its table: test_tables_smoke_runs_a_multirun_and_aggregates
def test_submitit_launcher_runs_a_multirun_locally(tmp_path):
    """The cluster path: the same multirun through submitit (its local executor, as on a
    SLURM node), each job in its own process and folder."""
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    root = Path(__file__).resolve().parents[1]
    cmd = [
        sys.executable,
        "train.py",
        "-m",
        "hydra/launcher=submitit_local",
        "debug=smoke",
        "logger=none",
        "baselines=none",
        "seed=0,1",
        f"hydra.sweep.dir={tmp_path}",
        "hydra.launcher.timeout_min=10",
    ]
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    jobs = sorted(p for p in tmp_path.iterdir() if (p / "metrics.json").exists())
    assert len(jobs) == 2, list(tmp_path.iterdir())
    assert (tmp_path / ".submitit").is_dir()
    # the sweep's progress, counted across the jobs' processes: 2 of 2 ended
    assert json.loads((tmp_path / "sweep_progress.json").read_text())["jobs"] == 2
    assert sorted((tmp_path / "sweep_progress.log").read_text().split()) == [
        "0",
        "1",
        "COMPLETED",
        "COMPLETED",
    ]


def test_a_sweep_counts_its_jobs_in_advance():
    from pidyn.runs.sweep_progress import sweep_size

    assert sweep_size(["noise=0,0.025,0.05", "seed=range(3)", "system=duffing"]) == 9
    assert sweep_size(["system=duffing"]) == 1
    # a command line's sweep of a key replaces the config's (the experiment's events, make real's subset)
    assert sweep_size(["data.event=a,b,c", "data.direction=x,y", "data.event=a,b"]) == 4
    assert sweep_size(["noise=0,0.025,0.05", "noise=0.05"]) == 1
