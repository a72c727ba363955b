from pathlib import Path

import hydra
import pytest
from helpers import CONF, make_cfg
from hydra.errors import ConfigCompositionException
from omegaconf.errors import ConfigAttributeError

SYSTEMS = sorted(p.stem for p in (Path(CONF) / "system").glob("*.yaml"))
EXPERIMENTS = sorted(p.stem for p in (Path(CONF) / "experiment").glob("*.yaml"))


#: what a system needs of its data to be built (a deck: its station's layout)
NEEDS = {"rigid_deck": ["data=csmip", "data.station=CE89324"]}


@pytest.mark.parametrize("system", SYSTEMS)
def test_every_system_composes_and_instantiates(system, tmp_path):
    cfg = make_cfg([f"system={system}", *NEEDS.get(system, [])], tmp_path)
    s = hydra.utils.instantiate(cfg.system)
    assert s.param_specs() and all(sp.true is not None for sp in s.param_specs())
    hydra.utils.instantiate(cfg.model.rpn, out_features=s.n_dof)
    hydra.utils.instantiate(cfg.callbacks.clamp)
    hydra.utils.instantiate(cfg.callbacks.early_stopping)


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_experiment_composes(experiment, tmp_path):
    cfg = make_cfg([f"experiment={experiment}"], tmp_path)
    assert cfg.system._target_


def test_bouc_wen_defaults_to_el_centro_and_record_override_wins(tmp_path):
    assert make_cfg(["system=bouc_wen"], tmp_path).excitation.record == "el_centro"
    assert make_cfg(["system=bouc_wen", "excitation=kobe"], tmp_path).excitation.record == "kobe"
    assert make_cfg([], tmp_path).excitation.record == "kobe"


def test_sweep_knobs_reach_the_nested_nodes(tmp_path):
    cfg = make_cfg(["noise=0.05", "batch_size=400", "eq_scale=3", "data_seed=7"], tmp_path)
    assert cfg.data.source.noise == 0.05 and cfg.data.windows.batch_size == 400
    assert cfg.data.source.eq_scale == 3 and cfg.data.source.data_seed == 7


def test_a_storey_term_is_given_on_the_command_line_as_the_readme_writes_it(tmp_path):
    """A plain ``system.storey_terms={1: [...]}`` (README, docs/buildings.md), not ``++``: the
    default must not be a dict that refuses new keys."""
    over = "system.storey_terms={2: [{term: hysteresis, beta: 400, gamma: 800, n: 2, shape_scale: 100}]}"
    cfg = make_cfg(["system=shear_building", over], tmp_path)
    s = hydra.utils.instantiate(cfg.system)
    assert {"beta2", "gamma2"} <= {sp.name for sp in s.param_specs()}
    assert make_cfg(["system=shear_building"], tmp_path).system.storey_terms is None


@pytest.mark.parametrize("bad", ["nosie=0.05", "system=dufing", "model.rpn.widht=3"])
def test_config_typos_fail_loudly(bad, tmp_path):
    with pytest.raises((ConfigCompositionException, ConfigAttributeError)):
        make_cfg([bad], tmp_path)


@pytest.mark.parametrize(
    "overrides",
    [
        [],
        ["data=silverbox", "system=linear"],
        ["data=bouc_wen_benchmark", "system=linear"],
        ["data=csv", "data.path=x.csv", "data.mass=2.0"],
    ],
)
def test_diagnose_configs_compose(overrides, tmp_path):
    cfg = make_cfg(overrides, tmp_path, config_name="diagnose")
    assert cfg.task_name == "diagnose" and cfg.diagnosis.thresholds.min_delta_bic > 0
    if "data=silverbox" in overrides or "data=bouc_wen_benchmark" in overrides:
        assert cfg.data.mass is None and cfg.model.schedule.max_windows == 10
        assert cfg.diagnosis.polish_seconds == 10.0
    else:
        assert cfg.model.schedule.max_windows is None and cfg.diagnosis.polish_seconds is None


def test_a_misspelled_schedule_option_names_the_valid_ones(tmp_path):
    from pidyn.tasks.train import train

    for over, word in (
        ("model.schedule.fusion=informaton", "information, last"),
        ("model.schedule.ls_init=frist", "none, first, every"),
    ):
        with pytest.raises(ValueError, match=word):
            train(make_cfg(["debug=smoke", "logger=none", "baselines=none", over], tmp_path))
