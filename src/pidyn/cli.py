"""Console entry points ``pidyn-train``, ``pidyn-diagnose``, ``pidyn-generalize``.

The configs ship inside the package (``pidyn/conf``, Hydra's ``pkg://pidyn.conf``), so the
commands work from any directory and from an installed wheel; ``train.py``, ``diagnose.py`` and
``generalize.py`` at the repository root are shims to these functions.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

from pidyn.config import CONF_DIR as _CONF_PATH

#: the package's config directory, for ``hydra.initialize_config_dir``
CONF_DIR = str(_CONF_PATH)
log = logging.getLogger("pidyn")


def _guarded(task, cfg: DictConfig) -> dict:
    """Run a task; user errors (bad files, bad values) end with one clear line and exit 2."""
    try:
        return task(cfg)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        log.error("%s: %s", type(exc).__name__, exc)
        if cfg.get("raise_errors", False):
            raise
        sys.exit(2)


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def train_main(cfg: DictConfig) -> float | None:
    from pidyn.tasks.train import train

    metrics = _guarded(train, cfg)
    value = metrics.get(cfg.get("optimized_metric", "max_error_pct"))
    return float(value) if value is not None else None


@hydra.main(version_base="1.3", config_path="conf", config_name="generalize")
def generalize_main(cfg: DictConfig) -> float | None:
    from pidyn.tasks.generalize import generalize

    summary = _guarded(generalize, cfg)
    return summary.get("share_gamma_ge_0.95_pidynnet")


@hydra.main(version_base="1.3", config_path="conf", config_name="diagnose")
def diagnose_main(cfg: DictConfig) -> float | None:
    from pidyn.tasks.diagnose import diagnose

    result = _guarded(diagnose, cfg)
    return result["gain"]["extended"] if result["gain"]["extended"] is not None else result["gain"]["nominal"]
