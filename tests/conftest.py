from __future__ import annotations

from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig, open_dict

CONF = str(Path(__file__).resolve().parents[1] / "conf")


@pytest.fixture(autouse=True)
def _clean_state():
    GlobalHydra.instance().clear()
    torch.set_default_dtype(torch.float32)
    yield
    GlobalHydra.instance().clear()
    torch.set_default_dtype(torch.float32)


def make_cfg(overrides: list[str], out: Path | None = None, config_name: str = "train") -> DictConfig:
    """Compose ``conf/<config_name>.yaml`` as ``python <config_name>.py <overrides>`` would."""
    with initialize_config_dir(CONF, version_base="1.3"):
        cfg = compose(config_name, overrides=overrides, return_hydra_config=True)
    with open_dict(cfg):
        if out is not None:
            cfg.paths.output_dir = str(out)
            cfg.paths.root_dir = str(Path(CONF).parent)
        cfg.trainer.enable_progress_bar = False
        cfg.raise_errors = True
    from hydra.core.hydra_config import HydraConfig

    HydraConfig.instance().set_config(cfg)
    return cfg
