"""Lightning wrapper: drives the PIDynNet core through one subperiod and one phase.

Manual optimisation with ``inner_steps`` Adam steps per ``training_step`` keeps
Lightning's per-step overhead small for a network this size (see ``make bench``).
A fresh Trainer runs each (window, phase); this module, carried across them, keeps a
global iteration counter so TensorBoard shows one continuous run.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import lightning as L
import torch

from pidyn.data.windows import Window
from pidyn.errors import error_pct
from pidyn.models.pidynnet import PIDynNet
from pidyn.params import from_raw

Phase = Literal["pretrain", "identify", "finetune", "finetune_lbfgs"]


class PIDynNetModule(L.LightningModule):
    """Trains RPN/LNN and physical parameters on the current window.

    Args:
        net: the PIDynNet core.
        loss_weights: weight per named loss term (``physics/motion``, ``data/x``, ...);
            unlisted terms weigh 1.
        lr_net, lr_phys: Adam learning rates for network weights and (raw) physical parameters.
        lr_decay: factor by which both rates decay over a window's iteration budget.
        inner_steps: optimiser steps per Lightning ``training_step``.
        log_every: iterations between TensorBoard scalars.
        lbfgs_max_iter: function evaluations per L-BFGS step in the ``finetune_lbfgs`` phase
            (full collocation pool, strong-Wolfe line search; see ``predict_response``).
        lbfgs_tol: the L-BFGS phase stops once the (normalised) physics loss is below this.
    """

    def __init__(
        self,
        net: PIDynNet,
        loss_weights: dict[str, float] | None = None,
        lr_net: float = 1e-3,
        lr_pretrain: float = 3e-3,
        lr_phys: float = 1e-2,
        lr_decay: float = 0.1,
        inner_steps: int = 10,
        log_every: int = 50,
        lbfgs_max_iter: int = 50,
        lbfgs_tol: float = 1e-5,
    ) -> None:
        super().__init__()
        self.automatic_optimization = False
        self.net = net
        self.loss_weights = dict(loss_weights or {})
        self.lr_net, self.lr_pretrain, self.lr_phys, self.lr_decay = lr_net, lr_pretrain, lr_phys, lr_decay
        self.inner_steps = inner_steps
        self.log_every = log_every
        self.lbfgs_max_iter = lbfgs_max_iter
        self.lbfgs_tol = lbfgs_tol
        self.phase: Phase = "identify"
        self.window: Window | None = None
        self.n_windows: int | None = None
        self.budget = 1000  # iterations planned for the current fit (sets the LR decay)
        self.register_buffer("iteration", torch.zeros((), dtype=torch.long))
        self.window_iteration = 0
        self.trajectory: list[torch.Tensor] = []  # raw physical parameters, one row per iteration
        self.last_losses: dict[str, float] = {}

    # ------------------------------------------------------------ configuration
    def start(self, window: Window, phase: Phase, budget: int, n_windows: int | None = None) -> None:
        """The next fit: its window, phase and iteration budget; ``n_windows`` the run's windows
        (the progress line's k of n)."""
        self.window, self.phase, self.budget = window, phase, max(int(budget), 1)
        self.n_windows = n_windows
        self.window_iteration = 0
        self.trajectory = []

    def on_fit_start(self) -> None:
        # Lightning has put the module on its device by now (and puts it back on the CPU at the
        # end of the fit): the window's tensors follow it, the caller's window stays on the host
        if self.window is not None and self.window.t_pool.device != self.device:
            self.window = self.window.to(self.device)

    def configure_optimizers(self) -> Any:
        if self.phase == "finetune_lbfgs":
            return torch.optim.LBFGS(
                self.net.net_parameters(),
                lr=1.0,
                max_iter=self.lbfgs_max_iter,
                history_size=50,
                line_search_fn="strong_wolfe",
                tolerance_grad=1e-10,
                tolerance_change=1e-14,
            )
        # foreach: one kernel call per operation over every tensor (a scalar physical parameter
        # is a tensor of its own), the same arithmetic as the per-tensor loop, 30 % less time
        if self.phase == "pretrain":
            opt = torch.optim.Adam(self.net.net_parameters(), lr=self.lr_pretrain, foreach=True)
        elif self.phase == "finetune":
            opt = torch.optim.Adam(self.net.net_parameters(), lr=self.lr_net, foreach=True)
        else:
            groups = [{"params": self.net.net_parameters(), "lr": self.lr_net, "name": "net"}]
            phys = self.net.physical_parameters()
            if phys:
                groups.append({"params": phys, "lr": self.lr_phys, "weight_decay": 0.0, "name": "phys"})
            opt = torch.optim.Adam(groups, foreach=True)
        decay = self.lr_decay
        budget = self.budget
        sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: decay ** min(i / budget, 1.0))
        return [opt], [sched]

    # ------------------------------------------------------------ training
    def losses(
        self,
        t_c: torch.Tensor | None,
        f_c: torch.Tensor | None,
        q_c: torch.Tensor | None = None,
        qd_c: torch.Tensor | None = None,
    ) -> dict[str, torch.Tensor]:
        assert self.window is not None
        out: dict[str, torch.Tensor] = {}
        if self.phase != "finetune":
            # pretraining shapes floors without a sensor after their neighbours; the fit itself sees data only
            out.update(self.net.data_losses(self.window, fill=self.phase == "pretrain"))
        if self.phase != "pretrain":
            assert t_c is not None and f_c is not None
            out.update(self.net.physics_losses(t_c, f_c, q_c, qd_c))
        return out

    def total(self, losses: dict[str, torch.Tensor]) -> torch.Tensor:
        return sum(self.loss_weights.get(k, 1.0) * v for k, v in losses.items())  # type: ignore[return-value]

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        if self.phase == "finetune_lbfgs":
            return self._lbfgs_step()
        # the plain torch optimizer: Lightning's wrapper adds a strategy round trip per Adam
        # step, which at ~7 ms an iteration was most of its overhead (single device, no AMP)
        opt = self.optimizers(use_pl_optimizer=False)
        sched = self.lr_schedulers()
        t_c, f_c, q_c, qd_c = batch.get("t"), batch.get("f"), batch.get("q"), batch.get("qd")
        k_steps = t_c.shape[0] if t_c is not None else self.inner_steps
        pick = lambda a, k: None if a is None else a[k]  # noqa: E731
        for k in range(k_steps):
            losses = self.losses(pick(t_c, k), pick(f_c, k), pick(q_c, k), pick(qd_c, k))
            loss = self.total(losses)
            opt.zero_grad(set_to_none=True)
            self.manual_backward(loss)
            opt.step()
            sched.step()
            self.iteration += 1
            self.window_iteration += 1
            if self.phase == "identify":
                self.trajectory.append(self.net.params.raw_vector().detach().clone())
        self.last_losses = {k: float(v.detach()) for k, v in losses.items()}
        self.last_losses["total"] = float(loss.detach())
        if not math.isfinite(self.last_losses["total"]):
            raise FloatingPointError(
                f"loss became {self.last_losses['total']} in window {self.window.index if self.window else '?'} "
                f"({self.phase}, iteration {self.window_iteration}); lower the learning rates"
            )
        if self._trainer is not None and self.trainer.progress_bar_callback is not None:
            # what the progress bar shows; skipped without one (it costs more than an Adam step)
            self.log("loss", self.last_losses["total"], prog_bar=True, on_step=True, logger=False)
            if self.phase == "identify":
                for name, v in self.net.params.as_floats().items():
                    if self.net.params.spec(name).trainable:
                        self.log(name, v, prog_bar=True, on_step=True, logger=False)
        if int(self.iteration) % self.log_every < k_steps:
            self._tb_scalars()

    def _lbfgs_step(self) -> None:
        """One L-BFGS step on the physics residual over the window's whole pool.

        Deterministic (no collocation draws), as a quasi-Newton method needs. Stops the
        fit when the loss is below ``lbfgs_tol`` or a step improves it by less than 1e-3 of
        itself; a non-finite loss
        stops it too and is left in ``last_losses`` for the caller to reject."""
        w = self.window
        assert w is not None
        opt = self.optimizers()
        box: dict[str, dict[str, torch.Tensor]] = {}

        def closure() -> torch.Tensor:
            opt.zero_grad(set_to_none=True)
            losses = self.net.physics_losses(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)
            loss = self.total(losses)
            self.manual_backward(loss)
            box["losses"] = losses
            return loss

        before = self.last_losses.get("total", math.inf)
        opt.step(closure=closure)
        self.iteration += 1
        self.window_iteration += 1
        with torch.no_grad():
            losses = self.net.physics_losses(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)
        self.last_losses = {k: float(v) for k, v in losses.items()}
        self.last_losses["total"] = float(self.total(losses))
        now = self.last_losses["total"]
        if (
            not math.isfinite(now)
            or now < self.lbfgs_tol
            or (math.isfinite(before) and before - now < 1e-3 * abs(now))
        ):
            self.trainer.should_stop = True

    def _tb_scalars(self) -> None:
        tb = tensorboard_writer(self.logger)
        if tb is None:
            return
        step = int(self.iteration)
        for k, v in self.last_losses.items():
            tb.add_scalar(
                f"{self.phase}/loss_{k}".replace("/loss_physics/", "/physics_").replace(
                    "/loss_data/", "/data_"
                ),
                v,
                step,
            )
        if self.phase == "identify":
            truths = self.net.params.truths()
            for name, v in self.net.params.as_floats().items():
                if not self.net.params.spec(name).trainable:
                    continue
                tb.add_scalar(f"params/{name}", v, step)
                if truths[name]:
                    tb.add_scalar(f"params_relerr/{name}", error_pct(v, truths[name]) / 100.0, step)

    def trajectory_values(self) -> torch.Tensor:
        """Physical-value trajectory of the trainable parameters in this fit, (iters, n)."""
        if not self.trajectory:
            return torch.empty(0, len(self.net.params.trainable_names))

        raw = torch.stack(self.trajectory).cpu()
        specs = [self.net.params.spec(n) for n in self.net.params.trainable_names]
        return torch.stack([from_raw(s, raw[:, i]) for i, s in enumerate(specs)], dim=1)


def tensorboard_writer(logger: Any) -> Any:
    if logger is None:
        return None
    exp = getattr(logger, "experiment", None)
    return exp if hasattr(exp, "add_scalar") else None
