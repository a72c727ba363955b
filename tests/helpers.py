"""What the tests share besides fixtures: the config directory and ``make_cfg`` (on the test path
through ``pythonpath`` in pyproject.toml)."""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig

from pidyn.config import CONF_DIR as CONF_PATH
from pidyn.config import compose

CONF = str(CONF_PATH)

ROOT = Path(__file__).resolve().parents[1]


def make_cfg(overrides: list[str], out: Path | None = None, config_name: str = "train") -> DictConfig:
    """Compose ``conf/<config_name>.yaml`` as ``python <config_name>.py <overrides>`` would."""
    return compose(
        config_name,
        overrides=overrides,
        output_dir=out,
        root_dir=ROOT,
        values={"trainer.enable_progress_bar": False, "raise_errors": True},
    )
