"""Progress as a log line now and then, for logs that are files rather than terminals.

A redrawn progress bar written to a file is megabytes of carriage returns. Where Lightning
shows no bar (stdout is not a terminal, or ``trainer.enable_progress_bar=false``), this
callback logs one line every ``every_s`` seconds: the window as k of n, the phase, the
iteration as k of n with the time this fit has left at its pace so far, the losses and the
physical parameters.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import lightning as L

from pidyn.progress import time_left

log = logging.getLogger("pidyn.progress")


class LineProgress(L.Callback):
    def __init__(self, every_s: float = 30.0) -> None:
        if every_s <= 0:
            raise ValueError(f"LineProgress: every_s must be positive, got {every_s}")
        self.every_s = float(every_s)
        self._last = self._start = 0.0
        self._first = 0  # the fit's iteration when it started (a resumed fit starts past 0)

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._last = self._start = time.monotonic()
        self._first = int(getattr(pl_module, "window_iteration", 0))

    def on_train_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        if trainer.progress_bar_callback is not None:  # a bar already shows it
            return
        now = time.monotonic()
        if now - self._last < self.every_s:
            return
        self._last = now
        log.info("%s", self.line(pl_module, now))

    def line(self, pl_module: Any, now: float) -> str:
        """``window 2/5 identify: iteration 400/1500 (~1 min 10 s left), loss ...; c=0.5, ...``."""
        window = getattr(pl_module, "window", None)
        n = getattr(pl_module, "n_windows", None)
        where = f"{getattr(window, 'index', -1) + 1}/{n}" if n else str(getattr(window, "index", "?"))
        done, budget = int(getattr(pl_module, "window_iteration", 0)), int(getattr(pl_module, "budget", 0))
        losses = getattr(pl_module, "last_losses", {}) or {}
        net = getattr(pl_module, "net", None)
        params = net.params.as_floats() if net is not None and hasattr(net, "params") else {}
        return (
            f"window {where} {getattr(pl_module, 'phase', '')}: iteration {done}/{budget}"
            f"{self._left(now, done, budget)}, loss "
            + ", ".join(f"{k} {v:.3g}" for k, v in losses.items())
            + "; "
            + ", ".join(f"{k}={v:.5g}" for k, v in params.items())
        )

    def _left(self, now: float, done: int, budget: int) -> str:
        """The time this fit has left at the pace of its iterations so far ('' before any)."""
        ran = done - self._first
        if ran <= 0 or budget <= done:
            return ""
        return f" ({time_left((now - self._start) / ran * (budget - done))})"
