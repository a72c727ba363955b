from __future__ import annotations

import os

import pytest
import torch
from hydra.core.global_hydra import GlobalHydra

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
