"""Where long work stands, as k of n with the time left at its pace so far: one log line per step
(the diagnosis's steps, its output-error checks, a building's storeys), so that a log file, a
terminal and a notebook (``pidyn.api`` shows the package's log lines there) all say it. PIDynNet's
iterations have their own line (``pidyn.callbacks.progress``), which formats time the same way."""

from __future__ import annotations

import logging
import time


def time_left(seconds: float) -> str:
    """``~1 min 10 s left`` or ``~40 s left``."""
    if seconds >= 60:
        return f"~{int(seconds // 60)} min {int(seconds % 60)} s left"
    return f"~{seconds:.0f} s left"


class Steps:
    """``n`` steps of ``what``; ``step(label)`` logs ``what k/n: label`` with the time so far and,
    after the first step, the time the rest would take at the pace of the steps done."""

    def __init__(self, what: str, n: int, logger: logging.Logger | None = None) -> None:
        if n < 1:
            raise ValueError(f"Steps: n must be at least 1, got {n}")
        self.what, self.n, self.k = what, int(n), 0
        self.log = logger or logging.getLogger("pidyn.progress")
        self._start = time.monotonic()

    def step(self, label: str, last: bool = False) -> None:
        """Log the next step (``last``: the final one, where a loop ended before its bound)."""
        self.k = self.n if last else min(self.k + 1, self.n)
        ran = time.monotonic() - self._start
        done = self.k - 1
        pace = f", {time_left(ran / done * (self.n - done))} at this pace" if done > 0 else ""
        self.log.info("%s %d/%d: %s (%.0f s so far%s)", self.what, self.k, self.n, label, ran, pace)
