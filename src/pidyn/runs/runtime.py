"""How a run behaves in its surroundings: inside a Hydra multirun or not, and the framework
notices that do not apply to it."""

from __future__ import annotations

import warnings

from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode


def in_multirun() -> bool:
    """True inside a Hydra multirun job (progress bars of parallel jobs would interleave)."""
    try:
        return HydraConfig.get().mode == RunMode.MULTIRUN
    except ValueError:
        return False


def quiet_framework_warnings() -> None:
    """Silence Lightning notices that do not apply to a one-window-at-a-time loop."""
    for msg in (
        ".*LeafSpec.*",
        ".*IterableDataset.*has `__len__`.*",
        ".*smaller than the logging interval.*",
        ".*does not have many workers.*",
        ".*litlogger.*",
    ):
        warnings.filterwarnings("ignore", message=msg)
