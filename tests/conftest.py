from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

from pidyn.config import CONF_DIR as CONF_PATH
from pidyn.config import compose

CONF = str(CONF_PATH)

ROOT = Path(__file__).resolve().parents[1]

if os.environ.get("PYTEST_XDIST_WORKER"):  # one torch thread per worker: the workers fill the cores
    torch.set_num_threads(1)


def pytest_collection_modifyitems(config, items):
    """The slow tests first (a stable sort, otherwise in file order): a minute-long test that
    starts last keeps one worker busy while the others idle."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(autouse=True)
def _clean_state():
    GlobalHydra.instance().clear()
    torch.set_default_dtype(torch.float32)
    yield
    GlobalHydra.instance().clear()
    torch.set_default_dtype(torch.float32)


def make_cfg(overrides: list[str], out: Path | None = None, config_name: str = "train") -> DictConfig:
    """Compose ``conf/<config_name>.yaml`` as ``python <config_name>.py <overrides>`` would."""
    return compose(
        config_name,
        overrides=overrides,
        output_dir=out,
        root_dir=ROOT,
        values={"trainer.enable_progress_bar": False, "raise_errors": True},
    )
