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
    """Run a task; user errors (bad files, bad values) end with one clear line and exit 2. In a
    multirun the job writes its reason to ``failed.json`` in its run folder instead, and the
    sweep goes on with the other jobs (a missing channel in one event must not stop the rest)."""
    try:
        return task(cfg)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        log.error("%s: %s", type(exc).__name__, exc)
        if cfg.get("raise_errors", False):
            raise
        if _in_multirun():
            _write_failure(cfg, exc)
            return {}
        sys.exit(2)


def _in_multirun() -> bool:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    try:
        return HydraConfig.get().mode == RunMode.MULTIRUN
    except ValueError:
        return False


def _write_failure(cfg: DictConfig, exc: BaseException) -> None:
    import json

    folder = Path(cfg.paths.output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "failed.json").write_text(
        json.dumps({"error": type(exc).__name__, "message": str(exc)}, indent=2)
    )


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def train_main(cfg: DictConfig) -> float | None:
    from pidyn.tasks.train import train

    metrics = _guarded(train, cfg) or {}
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
    if not result:
        return None
    return result["gain"]["extended"] if result["gain"]["extended"] is not None else result["gain"]["nominal"]
