"""One source of truth for every setting: a code default never disagrees with the config.

Walks every ``_target_`` of pidyn's own in the package's configs, every typed settings
dataclass the configs mirror, and the baselines' keyword settings. A key the code does not
take fails too (a typo in a YAML file would otherwise be ignored or crash late).
"""

from __future__ import annotations

import dataclasses
import inspect

import hydra
import pytest
from omegaconf import OmegaConf

from pidyn.baselines.registry import entries
from pidyn.config import compose, group_options

#: compositions in order of precedence: the first that sets a target's key is its reference
#: (later options, e.g. data=silverbox's short windows, are the config's deliberate choices)
COMPOSITIONS = (
    [("train", {})]
    + [("diagnose", {}), ("generalize", {})]
    + [("train", {g: o}) for g in ("system", "data", "callbacks", "model/refine") for o in group_options(g)]
)


#: starting guesses of the identification live in the system configs only: the code's None
#: there means "no guess", not a competing default
GUESSES = {"params", "guess"}


def _same(a, b) -> bool:
    """Equal as settings: YAML has no tuples, and None and an empty mapping both mean none."""

    def norm(v):
        if isinstance(v, tuple):
            return list(v)
        return None if isinstance(v, dict) and not v else v

    return norm(a) == norm(b)


def _targets(node, path=""):
    if isinstance(node, dict):
        if "_target_" in node:
            yield path, node
        for k, v in node.items():
            yield from _targets(v, f"{path}.{k}" if path else str(k))


def _reference_values() -> dict[tuple[str, str], tuple[str, object]]:
    ref: dict[tuple[str, str], tuple[str, object]] = {}
    for name, groups in COMPOSITIONS:
        cfg = OmegaConf.to_container(compose(name, groups=groups), resolve=False)
        cfg.pop("hydra", None)
        for path, node in _targets(cfg):
            if not node["_target_"].startswith("pidyn."):
                continue  # Lightning's own defaults are not ours to mirror
            for key, value in node.items():
                if not key.startswith("_") and key not in GUESSES:
                    ref.setdefault((node["_target_"], key), (f"{name} {groups or ''} {path}", value))
    return ref


def test_every_target_default_agrees_with_its_config():
    bad = []
    for (target, key), (where, value) in sorted(_reference_values().items()):
        params = inspect.signature(hydra.utils._locate(target)).parameters
        if key not in params:
            if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
                bad.append(f"{where}: {target} takes no '{key}'")
            continue
        default = params[key].default
        if default is inspect.Parameter.empty or (isinstance(value, str) and "${" in value):
            continue  # required in code, or set by a sweep knob
        if not _same(default, value):
            bad.append(
                f"{where}: {target}({key}=...) defaults to {default!r} in code, {value!r} in the config"
            )
    assert not bad, "\n".join(bad)


def _settings_classes():
    from pidyn.discrepancy.screening_rules import Thresholds
    from pidyn.discrepancy.settings import DiagnosisSettings
    from pidyn.models.predict import PredictSettings
    from pidyn.models.schedule import Schedule
    from pidyn.refine import RefineSettings

    # (dataclass, config, key, config keys the task itself reads beside the dataclass)
    return [
        (Schedule, "train", "model.schedule", set()),
        (RefineSettings, "train", "model.refine", {"method", "starts", "compare_states"}),
        (
            PredictSettings,
            "generalize",
            "generalization",
            {
                "duration",
                "own_scales",
                "own_stretches",
                "other_records",
                "other_scales",
                "match_pga",
                "align",
                "lead",
                "max_cases",
            },
        ),
        (Thresholds, "diagnose", "diagnosis.thresholds", set()),
        (DiagnosisSettings, "diagnose", "diagnosis", set()),
    ]


@pytest.mark.parametrize(
    "cls, config, key, task_keys", _settings_classes(), ids=lambda v: getattr(v, "__name__", "")
)
def test_settings_dataclasses_mirror_their_config(cls, config, key, task_keys):
    # without a data set's budget (conf/budget/<data>.yaml): it overrides the defaults by design
    over = ["~budget"] if config == "train" else []
    node = OmegaConf.to_container(OmegaConf.select(compose(config, overrides=over), key), resolve=True)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    assert set(node) - set(fields) <= task_keys, (
        f"{key}: keys {sorted(set(node) - set(fields) - task_keys)} are not fields of {cls.__name__}"
    )
    assert not set(fields) - set(node), (
        f"{cls.__name__} fields {sorted(set(fields) - set(node))} missing in {key}"
    )
    for name, f in fields.items():
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        if dataclasses.is_dataclass(default):  # a nested settings block: compared whole
            default = dataclasses.asdict(default)
        assert _same(default, node[name]), (
            f"{cls.__name__}.{name}: {default!r} in code, {node[name]!r} in {key}"
        )


def test_task_read_settings_default_to_the_config():
    from pidyn.runs.methods import default_starts, refine_plan

    plan = refine_plan(compose("train"))
    assert plan is not None and plan[0] == set(default_starts())


#: (config file, its node holding a schema's overrides, the schema's name in pidyn.schemas)
SCHEMA_FILES = [
    ("diagnose.yaml", "diagnosis", "diagnosis"),
    ("model/pidynnet.yaml", "schedule", "schedule"),
    ("model/refine/multiple_shooting.yaml", "", "refine"),
    ("generalize.yaml", "generalization", "generalization"),
]


@pytest.mark.parametrize("path, key, schema", SCHEMA_FILES, ids=[s for *_, s in SCHEMA_FILES])
def test_config_files_hold_overrides_only(path, key, schema):
    """Defaults live once, in the settings dataclass: a file's value equal to its default is a
    second copy that would drift; the file names the schema in its defaults list."""
    import yaml

    from pidyn.config import CONF_DIR
    from pidyn.schemas import SCHEMAS

    raw = yaml.safe_load((CONF_DIR / path).read_text())
    assert any(f"schema/{schema}@" in str(d) for d in raw.get("defaults", [])), (
        f"{path} names no schema/{schema}"
    )
    node = (raw.get(key) if key else {k: v for k, v in raw.items() if k != "defaults"}) or {}
    cls = SCHEMAS[schema]
    defaults = OmegaConf.to_container(OmegaConf.structured(cls))

    def copies(n, d, where):
        for k, v in n.items():
            if isinstance(v, dict) and isinstance(d.get(k), dict):
                yield from copies(v, d[k], f"{where}{k}.")
            elif k in d and _same(v, d[k]) and not (isinstance(v, str) and "${" in v):
                yield f"{where}{k}"

    # a refinement file's method names the file's choice, not a copied default
    same = [k for k in copies(node, defaults, "") if k != "method"]
    assert not same, f"{path}: {same} repeat {cls.__name__}'s defaults"


def test_a_setting_of_the_wrong_type_fails_at_composition():
    with pytest.raises(Exception, match="max_effects"):
        compose("diagnose", overrides=["diagnosis.max_effects=two"])


@pytest.mark.parametrize("method", list(entries()))
def test_baseline_settings_agree_with_their_functions(method):
    fn = entries()[method].function
    node = OmegaConf.to_container(compose("train").baselines, resolve=True).get(method) or {}
    params = inspect.signature(fn).parameters
    for k, v in node.items():
        assert k in params, f"baselines.{method}.{k}: {fn.__name__} takes no such argument"
        assert params[k].default is inspect.Parameter.empty or _same(params[k].default, v), (
            f"baselines.{method}.{k}: {params[k].default!r} in code, {v!r} in the config"
        )


@pytest.mark.parametrize(
    "override, message",
    [
        ("baselines.run=[ukf,sindi]", "baselines.run: unknown method"),
        ("model.refine.starts=[output_eror]", "model.refine.starts: unknown method"),
        ("model.schedule.fusion=informaton", "model.schedule.fusion"),
        ("model.refine.states=network", "refine.states must be one of"),
    ],
)
def test_enumerated_options_are_checked_before_any_work(override, message, tmp_path):
    from pidyn.tasks.train import train

    cfg = compose(
        "train", overrides=[override, "logger=none"], output_dir=tmp_path, values={"raise_errors": True}
    )
    with pytest.raises(ValueError, match=message):
        train(cfg)
    assert not (tmp_path / "subperiod_state.json").exists()
