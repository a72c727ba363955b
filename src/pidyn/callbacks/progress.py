"""Progress as a log line now and then, for logs that are files rather than terminals.

A redrawn progress bar written to a file is megabytes of carriage returns. Where Lightning
shows no bar (stdout is not a terminal, or ``trainer.enable_progress_bar=false``), this
callback logs one line every ``every_s`` seconds: window, phase, iteration, losses and the
physical parameters.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import lightning as L

log = logging.getLogger("pidyn.progress")


class LineProgress(L.Callback):
    def __init__(self, every_s: float = 30.0) -> None:
        if every_s <= 0:
            raise ValueError(f"LineProgress: every_s must be positive, got {every_s}")
        self.every_s = float(every_s)
        self._last = 0.0

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._last = time.monotonic()

    def on_train_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        if trainer.progress_bar_callback is not None:  # a bar already shows it
            return
        now = time.monotonic()
        if now - self._last < self.every_s:
            return
        self._last = now
        window = getattr(pl_module, "window", None)
        losses = getattr(pl_module, "last_losses", {}) or {}
        net = getattr(pl_module, "net", None)
        params = net.params.as_floats() if net is not None and hasattr(net, "params") else {}
        log.info(
            "window %s %s: iteration %d/%d, loss %s; %s",
            getattr(window, "index", "?"),
            getattr(pl_module, "phase", ""),
            getattr(pl_module, "window_iteration", 0),
            getattr(pl_module, "budget", 0),
            ", ".join(f"{k} {v:.3g}" for k, v in losses.items()),
            ", ".join(f"{k}={v:.5g}" for k, v in params.items()),
        )
