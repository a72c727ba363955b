"""End-to-end runs of the training task at toy budgets: outputs, checkpoints, resume."""

import json

import pytest
import torch
import yaml
from helpers import make_cfg

from pidyn.tasks.train import train

FAST = [
    "model.schedule.pretrain_iters=20",
    "model.schedule.pretrain_iters_window=10",
    "model.schedule.max_iters=20",
    "excitation.duration=15",
    "baselines=none",
]


@pytest.mark.slow
def test_run_folder_holds_everything(tmp_path):
    cfg = make_cfg(
        [o for o in FAST if o != "baselines=none"]
        + ["model.schedule.max_windows=2", "baselines.run=[equation_error,ukf]"],
        tmp_path,
    )
    metrics = train(cfg)
    for f in [
        "identified_params.yaml",
        "metrics.json",
        "windows.json",
        "subperiod_state.json",
        "figures/param_convergence.png",
        "figures/response.png",
        "figures/transfer_function.png",
        "figures/restoring_force.png",
        "checkpoints/last.pt",
        "baselines.json",
        "cramer_rao.json",
    ]:
        assert (tmp_path / f).exists(), f
    events = list((tmp_path / "tensorboard").glob("events.out.tfevents.*"))
    assert events
    # the HParams tab: the run's knobs beside its scores, a multirun's jobs side by side
    written = b"".join(e.read_bytes() for e in events)
    assert b"_hparams_/session_start_info" in written and b"hparams/max_error_pct" in written
    assert b"eq_scale" in written and b"noise" in written
    table = yaml.safe_load((tmp_path / "identified_params.yaml").read_text())["params"]
    assert set(table) == {"c", "k1", "k3"} and table["k3"]["truth"] == 120.0 and "error_pct" in table["k3"]
    assert set(metrics["baselines"]) == {"equation_error", "ukf"}
    assert metrics["transfer_function"]["channel"] == "x" and metrics["transfer_function"]["segments"] >= 1
    # where the time went, stage by stage (make bench reads it)
    stages = metrics["stage_seconds"]
    assert set(stages) == {"build", "pidynnet", "baselines_wait", "refinement", "report"}
    assert all(v >= 0 for v in stages.values()) and stages["pidynnet"] > 0
    # the excitation keys that separate the cells of a scaling sweep when it is aggregated
    assert (metrics["eq_scale"], metrics["eq_stretch"]) == (cfg.eq_scale, cfg.eq_stretch)
    assert metrics["windows"] == 2 and json.loads((tmp_path / "metrics.json").read_text())["iterations"] > 0


def test_tensorboard_has_params_and_losses(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    cfg = make_cfg(FAST + ["model.schedule.max_windows=1", "model.module.log_every=10"], tmp_path)
    train(cfg)
    tags = set()
    for ev in (tmp_path / "tensorboard").glob("events.out.tfevents.*"):
        acc = EventAccumulator(str(ev))
        acc.Reload()
        tags |= set(acc.Tags()["scalars"])
    assert {"params/c", "params/k1", "params/k3", "params_relerr/k3", "subperiod/index"} <= tags
    assert any(t.startswith("identify/physics_motion") for t in tags), tags


def test_checkpoint_round_trip_keeps_physical_parameters(tmp_path):
    cfg = make_cfg(FAST + ["model.schedule.max_windows=1"], tmp_path)
    metrics = train(cfg)
    blob = torch.load(tmp_path / "checkpoints/last.pt", weights_only=False)
    raw = {k.split(".")[-1]: v for k, v in blob["module"].items() if ".params.raw." in k}
    assert set(raw) >= {"c", "k1", "k3"}
    pidyn = metrics["pidynnet"]["params"]  # the module holds PIDynNet's own estimate
    assert abs(float(torch.exp(raw["k3"]) * 50.0) - pidyn["k3"]) < 1e-3 * pidyn["k3"]
    refined = torch.load(tmp_path / "checkpoints/refined.pt", weights_only=False)  # the final one beside it
    assert refined["values"] == metrics["params"] and set(refined["ci95"]) == {"c", "k1", "k3"}


def test_resume_continues_from_next_window(tmp_path):
    cfg = make_cfg(FAST + ["model.schedule.max_windows=1"], tmp_path)
    first = train(cfg)
    state = json.loads((tmp_path / "subperiod_state.json").read_text())
    done = [w["index"] for w in state["windows"]]
    cfg2 = make_cfg(FAST + ["model.schedule.max_windows=2"], tmp_path)
    second = train(cfg2)
    state2 = json.loads((tmp_path / "subperiod_state.json").read_text())
    assert [w["index"] for w in state2["windows"]][: len(done)] == done
    assert len(state2["windows"]) == 2 and second["iterations"] > first["iterations"]
    # the first window was not redone: its record is unchanged
    assert state2["windows"][0] == state["windows"][0]


def test_resume_of_a_latent_system_carries_z_across(tmp_path):
    """A Bouc-Wen run resumes with the LNN's z at the end of the last finished window."""
    over = FAST + [
        "system=bouc_wen",
        "model.refine=none",
    ]  # the resume is PIDynNet's; the stage after it is not
    cfg = make_cfg(over + ["model.schedule.max_windows=1"], tmp_path)
    train(cfg)
    z_end = json.loads((tmp_path / "subperiod_state.json").read_text())["windows"][0]["z_end"]
    assert len(z_end) == 1 and z_end[0] != 0.0
    train(make_cfg(over + ["model.schedule.max_windows=2"], tmp_path))
    state = json.loads((tmp_path / "subperiod_state.json").read_text())
    assert len(state["windows"]) == 2 and state["windows"][0]["z_end"] == z_end
    assert all(len(w["z_end"]) == 1 for w in state["windows"])


def test_baselines_take_the_noise_a_data_source_drew(tmp_path):
    """``noise=null`` lets the data source draw the level (the diagnosis benchmark does): the
    baselines and the bound read it from the record, not from the config."""
    from pidyn.runs.methods import start_baselines
    from pidyn.runs.metrics import record_noise

    cfg = make_cfg(
        [
            "data=hidden",
            "noise=null",
            "baselines.run=[equation_error]",
            "baselines.parallel=false",
            "logger=none",
        ],
        tmp_path,
    )
    import hydra

    from pidyn.runs.build import build_record

    system = hydra.utils.instantiate(cfg.system)
    record = build_record(cfg, system)
    level = record_noise(cfg, record)
    assert 0.0 <= level <= 0.05 and level == record.meta.noise
    rows = start_baselines(cfg, system, record).result()
    assert rows[0]["method"] == "equation_error" and rows[0]["params"]


def test_a_config_with_integer_keys_compares_equal_to_itself_as_the_folder_keeps_it():
    """A deck layout's channel positions are a mapping with integer keys; the folder keeps the
    configuration as JSON (string keys), and the same run must not be refused as another."""
    import json

    from helpers import make_cfg

    from pidyn.runs.folder import comparable_config, config_differences

    cfg = make_cfg(["system=rigid_deck", "+system.layout.positions={1: 0.0, 2: 45.0}"])
    now = comparable_config(cfg)
    assert config_differences(json.loads(json.dumps(now)), now) == []


def test_an_empty_mapping_and_null_are_the_same_setting_for_a_resumed_run():
    """``system.storey_terms`` was ``{}`` and is now null: a run folder kept from before resumes."""
    from pidyn.runs.folder import config_differences

    saved = {"system": {"storey_terms": {}, "n_storeys": 3}}
    assert config_differences(saved, {"system": {"storey_terms": None, "n_storeys": 3}}) == []
    assert config_differences(saved, {"system": {"storey_terms": {1: "x"}, "n_storeys": 3}}) != []
    assert config_differences(saved, {"system": {"storey_terms": None, "n_storeys": 4}}) == [
        "system.n_storeys: 3 -> 4"
    ]
