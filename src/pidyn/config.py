"""Compose the package's Hydra configs outside ``@hydra.main``, with plain values checked.

The command line composes through ``@hydra.main``; the Python API, the experiments and the
tests compose here, from the same files, so a setting has one source whichever way a run
starts. Plain keyword values are validated against the composed config: a misspelled key or
option names the valid ones instead of being silently ignored.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import hydra
from hydra import compose as hydra_compose
from hydra import initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf, open_dict
from omegaconf.errors import OmegaConfBaseException

from pidyn.named import RESOLVERS
from pidyn.schemas import register as register_schemas

CONF_DIR = Path(__file__).resolve().parent / "conf"
register_schemas()  # the settings dataclasses, which the config files' defaults lists name

#: config groups chosen by name (a file of the group), as ``system=bouc_wen`` on the command line
GROUPS = (
    "system",
    "excitation",
    "data",
    "model",
    "model/refine",
    "trainer",
    "callbacks",
    "logger",
    "baselines",
    "experiment",
    "debug",
)


def group_options(group: str) -> list[str]:
    """The names a config group offers (its YAML files)."""
    return sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


def _check_choice(group: str, value: Any) -> None:
    options = group_options(group)
    if str(value) not in options:
        near = difflib.get_close_matches(str(value), options, n=1)
        hint = f" (did you mean '{near[0]}'?)" if near else ""
        raise ValueError(f"{group}: unknown option '{value}'{hint}; choose from {', '.join(options)}")


def _check_key(cfg: DictConfig, key: str) -> None:
    node: Any = cfg
    walked: list[str] = []
    for part in key.split("."):
        keys = list(node.keys()) if isinstance(node, DictConfig) else []
        if part not in keys:
            where = ".".join(walked) or "the config"
            public = sorted(k for k in keys if not str(k).startswith("_") and k != "hydra")
            near = difflib.get_close_matches(part, public, n=1)
            hint = f" (did you mean '{'.'.join(walked + [near[0]])}'?)" if near else ""
            raise ValueError(f"unknown setting '{key}'{hint}; {where} has: {', '.join(map(str, public))}")
        node = node._get_node(part)  # the child node, not its value: a mandatory '???' is set, not read
        walked.append(part)


def compose(
    config_name: str = "train",
    groups: dict[str, Any] | None = None,
    values: dict[str, Any] | None = None,
    overrides: Iterable[str] = (),
    output_dir: str | Path | None = None,
    root_dir: str | Path | None = None,
) -> DictConfig:
    """The config ``python <config_name>.py`` would run, with

    ``groups``: group choices (``{"system": "bouc_wen", "model/refine": "none"}``), checked;
    ``values``: settings by dotted key (``{"noise": 0.05, "model.schedule.max_windows": 4}``),
    checked to exist and applied after composition, so any Python value works;
    ``overrides``: raw Hydra override strings, passed through.
    """
    groups = dict(groups or {})
    for group, value in groups.items():
        if group not in GROUPS:
            raise ValueError(f"unknown config group '{group}'; the groups are {', '.join(GROUPS)}")
        if value is not None:
            _check_choice(group, value)
    strings = [f"{g}={'null' if v is None else v}" for g, v in groups.items()] + list(overrides)
    GlobalHydra.instance().clear()
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = hydra_compose(config_name, overrides=strings, return_hydra_config=True)
    for key, value in (values or {}).items():
        _check_key(cfg, key)
        OmegaConf.update(cfg, key, value, merge=False)
    with open_dict(cfg):
        # settings given as values count as the user's, as on the command line (``user_settings``)
        cfg.hydra.overrides.task = list(cfg.hydra.overrides.task) + [
            f"{k}={v}" for k, v in (values or {}).items()
        ]
        if output_dir is not None:
            cfg.paths.output_dir = str(output_dir)
        cfg.paths.root_dir = str(root_dir if root_dir is not None else Path.cwd())
    HydraConfig.instance().set_config(cfg)  # ${hydra:...} interpolations resolve as under @hydra.main
    return choose_system(cfg)


#: a system config's model for a run from several records (``conf/system/for_data/csmip.yaml``)
SEVERAL = "several_records"


def choose_system(cfg: DictConfig) -> DictConfig:
    """A data set's default model may differ for one record and for several (``data.paths`` or
    ``data.runs`` of two or more): its ``several_records`` node is the model for several, and the
    one-record model, its linear model of the same layout, stays beside it as ``linear_system``
    (fitted beside it, scored beside it in a prediction: ``pidyn.runs.linear_beside``). Settles
    ``cfg.system`` in place to the one this run's own records call for (idempotent); a run read
    back (``pidyn.runs.prediction.Identified``) settles it by its own records, not a new one's."""
    node = cfg.get("system")
    if not OmegaConf.is_dict(node) or SEVERAL not in node:
        return cfg
    many = [OmegaConf.select(cfg, f"data.{k}", default=None) for k in ("paths", "runs")]
    several = any(OmegaConf.is_list(v) and len(v) > 1 for v in many)
    with open_dict(cfg):
        chosen = node[SEVERAL]
        del node[SEVERAL]
        if several:
            cfg.linear_system = node
            cfg.system = chosen
    return cfg


def make_system(name: str, **values: Any):
    """A structural system from ``conf/system/<name>.yaml``; ``values`` set its keys
    (``make_system("shear_building", n_storeys=5)``, ``make_system("duffing", **{"params.k3.init": 50})``)."""
    cfg = compose("train", groups={"system": name}, values={f"system.{k}": v for k, v in values.items()})
    return hydra.utils.instantiate(cfg.system)


RESOLVERS["system"] = make_system  # Record.simulate("duffing") resolves names here


def user_settings() -> list[str]:
    """The keys the user set for this run (command-line overrides, and ``compose``'s values),
    without Hydra's prefixes: what the config's own defaults must not overrule."""
    try:
        task = list(HydraConfig.get().overrides.task)
    except ValueError:  # no Hydra context: nothing was set by the user
        return []
    return [o.split("=", 1)[0].lstrip("+~") for o in task]


#: the sweep knobs of every task, and what each must be
_KNOBS: dict[str, tuple[type, ...]] = {
    "seed": (int,),
    "data_seed": (int,),
    "batch_size": (int,),
    "eq_scale": (int, float),
    "eq_stretch": (int, float),
}


def check_settings(cfg: DictConfig) -> None:
    """Every setting resolvable and finite, the sweep knobs of their type: a NaN, an infinity, a
    word where a number belongs or an interpolation to a missing key is refused by name before
    any work (``noise=nan`` would otherwise pass a ``>= 0`` check and run without noise)."""
    for key in cfg:
        if key == "hydra":
            continue
        try:
            value = (
                OmegaConf.to_container(cfg[key], resolve=True) if OmegaConf.is_config(cfg[key]) else cfg[key]
            )
        except OmegaConfBaseException as exc:
            raise ValueError(f"setting '{key}' cannot be resolved: {str(exc).splitlines()[0]}") from None
        for path, leaf in _leaves(value, str(key)):
            if isinstance(leaf, float) and not math.isfinite(leaf):
                raise ValueError(f"setting '{path}' is {leaf}: a finite number is needed")
    for key, kinds in _KNOBS.items():
        if key in cfg and (isinstance(cfg[key], bool) or not isinstance(cfg[key], kinds)):
            want = "an integer" if kinds == (int,) else "a number"
            raise ValueError(f"setting '{key}' is {cfg[key]!r}: {want} is needed")
    noise = cfg.get("noise")
    if isinstance(noise, bool) or (noise is not None and not isinstance(noise, (int, float, DictConfig))):
        raise ValueError(
            f"setting 'noise' is {noise!r}: a number (a fraction of each channel's RMS) is needed"
        )
    if isinstance(noise, (int, float)) and noise < 0:
        raise ValueError(f"setting 'noise' is {noise}: it must be 0 or more")
    for key in ("batch_size", "eq_scale", "eq_stretch"):
        if key in cfg and cfg[key] <= 0:
            raise ValueError(f"setting '{key}' is {cfg[key]}: it must be positive")


def _leaves(value: Any, path: str):
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, f"{path}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, value
