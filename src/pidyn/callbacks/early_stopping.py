"""Parameter early stopping, paper Eq. 10.

Every ``check_every`` (N_c) iterations from ``start`` (N_0) on, compare the parameters
with a reference; stop when the relative change stays below ``eps`` for ``patience`` (n)
successive checks:  ||theta_{N0 + i Nc} - theta_{N0}|| / ||theta_{N0}|| < eps, i = 1..n.

``reference="fixed"`` is the paper's test (the reference is theta at N_0 and is only moved
when a check fails). ``space="raw"`` uses physical values as the paper does (the norm is
then dominated by the largest parameter); ``space="log"`` compares the unconstrained
parameters, so every parameter counts in relative terms. ``smooth`` averages the
trajectory over the last ``smooth`` iterations before comparing, which removes Adam's
step-size jitter from the test.
"""

from __future__ import annotations

from typing import Literal

import lightning as L
import torch


class ParameterEarlyStopping(L.Callback):
    def __init__(
        self,
        check_every: int = 100,
        eps: float = 1e-4,
        patience: int = 3,
        start: int = 500,
        space: Literal["raw", "log"] = "log",
        reference: Literal["fixed", "previous"] = "fixed",
        smooth: int = 100,
    ) -> None:
        self.check_every, self.eps, self.patience, self.start = check_every, eps, patience, start
        self.space, self.reference, self.smooth = space, reference, max(1, smooth)
        self.reset()

    def reset(self) -> None:
        self.ref: torch.Tensor | None = None
        self.passed = 0
        self.next_check = self.start
        self.stopped_at: int | None = None

    def on_fit_start(self, trainer, pl_module) -> None:  # noqa: D102
        self.reset()

    def _theta(self, pl_module) -> torch.Tensor | None:
        traj = pl_module.trajectory
        if not traj:
            return None
        window = torch.stack(traj[-self.smooth :])
        if self.space == "raw":
            vals = pl_module.trajectory_values()[-self.smooth :]
            return vals.mean(0)
        return window.mean(0)

    def check(self, theta: torch.Tensor) -> bool:
        """Feed one check; returns True when the stopping condition holds."""
        if self.ref is None:
            self.ref = theta.clone()
            return False
        rel = float(
            torch.linalg.vector_norm(theta - self.ref) / torch.linalg.vector_norm(self.ref).clamp_min(1e-12)
        )
        if rel < self.eps:
            self.passed += 1
        else:
            self.passed = 0
            self.ref = theta.clone()
        if self.reference == "previous":
            self.ref = theta.clone()
        return self.passed >= self.patience

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:  # noqa: D102
        if getattr(pl_module, "phase", None) != "identify":
            return
        it = pl_module.window_iteration
        while it >= self.next_check:
            self.next_check += self.check_every
            theta = self._theta(pl_module)
            if theta is not None and self.check(theta):
                self.stopped_at = it
                trainer.should_stop = True
                return
