"""Sequential identification over subperiods (paper, Methodology), resumable.

For each window: map the networks to the window, supervised pretraining of the RPN,
transfer-learning initialisation of the LNN with the (z0 - x0) offset, an optional
least-squares initialisation of the parameters the motion residual is linear in, then
joint physics + data training under the clamp and early-stopping callbacks. A fresh
Trainer runs every (window, phase) and the LightningModule is carried over, so callback
and loop state never leak between windows. After each window the estimate is fused with
the previous ones (or simply carried, as in the paper) and the state is written to
``subperiod_state.json`` plus a checkpoint, from which an interrupted run resumes.

A parameter the first window does not determine (a cubic stiffness before the strong motion)
is not frozen at its guess: its least-squares start is tried again in the next windows until
one determines it, and the clamp box that follows a window is at least three posterior
standard deviations of what the windows so far know (see ``ParameterClamp``), so an
uninformed start cannot lock the rest of the record.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import lightning as L
import torch

from pidyn.callbacks.clamp import ParameterClamp
from pidyn.callbacks.early_stopping import ParameterEarlyStopping
from pidyn.data.datamodule import SubperiodDataModule
from pidyn.data.windows import Window
from pidyn.errors import error_pct
from pidyn.models.fusion import InformationFusion, posterior_std, residual_information
from pidyn.models.latent_start import (
    latent_least_squares_start,
    latent_shape_params,
    motion_on_samples,
    teach_current_path,
)
from pidyn.models.lit_module import PIDynNetModule, tensorboard_writer
from pidyn.models.schedule import Schedule, WindowResult
from pidyn.notes import note

log = logging.getLogger(__name__)


class SubperiodIdentifier:
    """Runs the window sequence; ``trainer_factory(**overrides)`` builds a fresh Trainer."""

    def __init__(
        self,
        module: PIDynNetModule,
        datamodule: SubperiodDataModule,
        trainer_factory: Callable[..., L.Trainer],
        schedule: Schedule,
        clamp: ParameterClamp | None,
        early_stopping: ParameterEarlyStopping | None,
        run_dir: str | Path,
        extra_callbacks: list[L.Callback] | None = None,
    ) -> None:
        self.module, self.dm, self.make_trainer = module, datamodule, trainer_factory
        self.schedule, self.clamp, self.early_stopping = schedule, clamp, early_stopping
        self.extra_callbacks = list(extra_callbacks or [])
        self.run_dir = Path(run_dir)
        self.ckpt_dir = self.run_dir / "checkpoints"
        self.state_path = self.run_dir / "subperiod_state.json"
        self.fusion = InformationFusion()
        self.results: list[WindowResult] = []
        self.ls_pending: list[str] = []  # parameters no least-squares start has determined yet
        self.motions: list[dict[str, torch.Tensor]] = []  # the networks' motion per window (latent start)
        self.trajectory: list[dict[str, Any]] = []  # (iteration, time, values) for figures

    # ------------------------------------------------------------------ state
    def save_state(self, next_window: int) -> None:
        self.ckpt_dir.mkdir(parents=True, exist_ok=True)
        ckpt = self.ckpt_dir / "last.pt"
        torch.save(
            {
                "module": self.module.state_dict(),
                "fusion": self.fusion.state_dict(),
                "clamp": self.clamp.state_dict() if self.clamp else None,
                "next_window": next_window,
                "motions": self.motions,
            },
            ckpt.with_suffix(".tmp"),
        )
        ckpt.with_suffix(".tmp").replace(ckpt)
        state = {
            "next_window": next_window,
            "n_windows": len(self.dm.windows),
            "iteration": int(self.module.iteration),
            "checkpoint": str(ckpt.relative_to(self.run_dir)),
            "windows": [r.__dict__ for r in self.results],
            "trajectory": self.trajectory,
            "ls_pending": self.ls_pending,
            "fingerprint": self.fingerprint(),
        }
        tmp = self.state_path.with_suffix(".tmp")
        tmp.write_text(json.dumps(state, indent=1))
        tmp.replace(self.state_path)

    def fingerprint(self) -> dict:
        """What a saved state must match to be resumed: the model's parameters with their starts,
        and the windows of the record."""
        specs = self.module.net.params.specs
        return {
            "params": {sp.name: round(float(sp.init), 12) for sp in specs},
            "windows": [[round(w.t0, 9), round(w.t1, 9)] for w in self.dm.windows],
        }

    def try_resume(self) -> int:
        """Restore from ``subperiod_state.json`` if present; returns the next window index. A state
        of another model or record (a run folder used again with other settings) is not resumed:
        the run starts afresh and says so."""
        if not self.state_path.exists():
            return 0
        state = json.loads(self.state_path.read_text())
        saved = state.get("fingerprint")
        if saved is not None and saved != self.fingerprint():
            log.warning(
                "%s holds the state of another run (its model or windows differ): not resumed, starting "
                "afresh",
                self.state_path,
            )
            return 0
        blob = torch.load(self.run_dir / state["checkpoint"], weights_only=False)
        try:
            self.module.load_state_dict(blob["module"])
        except RuntimeError as exc:  # a state saved before fingerprints, of another model
            log.warning(
                "%s holds the state of another model (%s): not resumed, starting afresh",
                self.state_path,
                str(exc).splitlines()[0],
            )
            return 0
        self.fusion.load_state_dict(blob["fusion"])
        if self.clamp and blob.get("clamp"):
            self.clamp.load_state_dict(blob["clamp"])
        self.results = [WindowResult(**r) for r in state["windows"]]
        self.motions = list(blob.get("motions") or [])
        self.trajectory = state.get("trajectory", [])
        self.ls_pending = list(state.get("ls_pending", []))
        log.info(
            "resuming at window %d of %d (iteration %d)",
            state["next_window"],
            state["n_windows"],
            state["iteration"],
        )
        return int(state["next_window"])

    # ------------------------------------------------------------------ phases
    def _fit(self, w: Window, phase: str, iters: int, physics: bool, callbacks: list[L.Callback]) -> None:
        self.module.start(w, phase, iters, len(self.dm.windows))  # type: ignore[arg-type]
        inner = self.module.inner_steps
        self.dm.activate(w.index, iters, inner, physics)
        trainer = self.make_trainer(max_steps=-1, callbacks=callbacks + self.extra_callbacks)
        trainer.fit(self.module, datamodule=self.dm)

    def run(
        self, resume: bool = True, behind: Callable[[dict[str, float]], str | None] | None = None
    ) -> list[WindowResult]:
        """The windows, from where a saved state left off. ``behind``: asked after every window but
        the last with the estimate so far; a text (a note) ends PIDynNet there, as its last window
        (``Schedule.stop_behind``: a peer's estimate simulates the record so much better that the
        refinement will start from it)."""
        start = self.try_resume() if resume else 0
        net = self.module.net
        z_end: torch.Tensor | None = None
        if start > 0 and net.lnn is not None:
            z_end = torch.tensor(self.results[-1].z_end if self.results[-1].z_end is not None else [0.0])
        first_done = start > 0
        todo = self._todo()
        for w in todo:
            if w.index < start:
                continue
            t_start = time.perf_counter()
            it0 = int(self.module.iteration)
            if self.results and self.dm.windows[self.results[-1].index].piece != w.piece:
                z_end = None  # another record: its latent state is not the last window's
            net.enter_window(w)
            self._pretrain(w, first_done, z_end)
            notes = self._starts(w, first_done, z_end)
            box = dict(self.clamp.bounds) if self.clamp is not None else {}
            held = self._train(w)
            stopped = bool(self.early_stopping and self.early_stopping.stopped_at is not None)
            names = net.params.trainable_names
            estimate = net.params.as_floats()
            states = net.states_at_samples(w)
            self._combine(w, it0, names, estimate, held)
            fused = net.params.as_floats()
            if net.lnn is not None:
                with torch.no_grad():
                    z_end = net.latent_state_at(w).detach()
                if self._latent_names():
                    self.motions.append(motion_on_samples(net, w))
            res = WindowResult(
                index=w.index,
                t0=w.t0,
                t1=w.t1,
                iterations=int(self.module.iteration) - it0,
                seconds=time.perf_counter() - t_start,
                estimate={n: estimate[n] for n in names},
                fused={n: fused[n] for n in names},
                losses=dict(self.module.last_losses),
                stopped_early=stopped,
                clamp_bounds={k: list(v) for k, v in (self.clamp.bounds.items() if self.clamp else [])},
                z_end=None if z_end is None else z_end.tolist(),
                states=states,
                notes=notes + self._clamp_notes(names, estimate, box),
            )
            self.results.append(res)
            first_done = True
            ahead = behind(fused) if behind is not None and w is not todo[-1] else None
            self._end_window(res, ahead, next_window=todo[-1].index + 1 if ahead else w.index + 1)
            if ahead:
                break
        return self.results

    def _end_window(self, res: WindowResult, ahead: str | None, next_window: int) -> None:
        """Report the window and save the state; ``ahead``: the note that ends PIDynNet here."""
        if ahead:
            res.notes.append(ahead)
            log.info(ahead)
        self._report(res)
        self._log_window(res)
        self.save_state(next_window=next_window)

    def _todo(self) -> list[Window]:
        """The windows to run: the informative ones (unless told otherwise), at most max_windows
        (and windows_per_record for each record of the run)."""
        sch = self.schedule
        todo = [w for w in self.dm.windows if (w.informative or not sch.skip_uninformative)]
        limit = sch.window_limit(len({w.piece for w in self.dm.windows}))
        if limit is not None:
            todo = todo[:limit]
        if not todo:
            raise ValueError("no informative window: lower data.min_peak_fraction or check the record")
        return todo

    def _latent_names(self) -> list[str]:
        """Latent shape parameters the variable-projection start handles (empty when it is off)."""
        sch, net = self.schedule, self.module.net
        if net.lnn is None or not sch.latent_init or sch.ls_init == "none":
            return []
        return latent_shape_params(net.system)

    def _pretrain(self, w: Window, first_done: bool, z_end: torch.Tensor | None) -> None:
        """Supervised pretraining of the RPN, then the paper's transfer of the RPN to the LNN with
        the (z0 - x0) offset, z0 carried from the last window (at rest before the record)."""
        sch, net = self.schedule, self.module.net
        pre = sch.pretrain_iters if not first_done else sch.pretrain_iters_window
        if pre > 0:
            self._fit(w, "pretrain", pre, physics=False, callbacks=[])
        if net.lnn is not None and sch.transfer_lnn:
            net.transfer_rpn_to_lnn()
            net.set_latent_offset(torch.zeros(1), torch.zeros(1))
            with torch.no_grad():
                x0 = net.response_at_start(w)
                z_init = net.latent_state_at(w, end=False)  # = x0 right after the transfer
            z0 = z_end if z_end is not None else x0[:1] * 0
            net.set_latent_offset(z0, z_init[:1])

    def _starts(self, w: Window, first_done: bool, z_end: torch.Tensor | None) -> list[str]:
        """The least-squares starts of the window (linear parameters, the drift, a latent shape),
        tried again while an earlier window left a parameter undetermined; returns the notes."""
        sch, net = self.schedule, self.module.net
        notes: list[str] = []
        latent = self._latent_names()
        ls_now = sch.ls_init == "every" or (
            sch.ls_init == "first" and (not first_done or bool(self.ls_pending))
        )
        pending_before = set(self.ls_pending) if first_done else set()
        if latent and first_done and z_end is not None and not set(self.ls_pending) & set(latent):
            misfit = teach_current_path(net, w, z_end)
            log.info(
                "window %d: LNN started on the latent path of the held shape parameters (relative misfit %.2g)",
                w.index,
                misfit,
            )
        if net.use_drift:  # displacement not measured: the physics pins the networks' drift
            notes += self._drift_start(w, ls_now)
        elif ls_now:
            notes += self._least_squares_start(w)
        if ls_now and latent:
            notes += self._latent_start(w)
        if ls_now:
            self._release_clamp(pending_before - set(self.ls_pending), w.index, notes)
        return notes

    def _train(self, w: Window) -> dict[str, float]:
        """Physics + data training of the window under the clamp and early stopping. A
        determined latent shape is held: its gradient through a network-made z is not
        information (measured: a quiet window moved beta from 15 to 60 % off), and a longer
        variable projection on the networks' motion drifts (``latent_start``). Returns the
        held values."""
        net = self.module.net
        cbs: list[L.Callback] = [c for c in (self.clamp, self.early_stopping) if c is not None]
        held = {n: net.params.as_floats()[n] for n in self._latent_names() if n not in self.ls_pending}
        for n in held:
            net.params.raw[n].requires_grad_(False)
            if self.clamp is not None:
                self.clamp.bounds.pop(n, None)
        try:
            self._fit(w, "identify", self.schedule.max_iters, physics=True, callbacks=cbs)
        finally:
            for n in held:
                net.params.raw[n].requires_grad_(True)
        return held

    def _combine(
        self, w: Window, it0: int, names: list[str], estimate: dict[str, float], held: dict[str, float]
    ) -> None:
        """The next window's clamp box, the convergence trajectory, and the fusion of this
        window's estimate with the earlier ones (the held latent shape stays as it is)."""
        sch, net = self.schedule, self.module.net
        traj = self.module.trajectory_values()
        info = (
            residual_information(net, w) if (sch.fusion == "information" or self.clamp is not None) else None
        )
        if self.clamp is not None:
            # what the windows so far know: the fused information where it is kept (a quiet
            # window alone knows little, and must not open the box of a parameter that
            # earlier windows pinned), this window's otherwise
            known = self.fusion.info + info if (self.fusion.info is not None and info is not None) else info
            self.clamp.update_from_trajectory(
                names, traj, estimate, posterior_std(known, names), {n: net.params.spec(n) for n in names}
            )
        # per-iteration trajectory (thinned) for the convergence figure
        dt_it = (w.t1 - w.t0) / max(len(traj), 1)
        for j in range(0, len(traj), max(1, len(traj) // 50)):
            self.trajectory.append(
                {
                    "iteration": it0 + j,
                    "t": w.t0 + j * dt_it,
                    **{n: float(traj[j, i]) for i, n in enumerate(names)},
                }
            )
        if sch.fusion == "information":
            assert info is not None
            theta = self.fusion.add(net.params.raw_vector(names).detach(), info)
            if self.fusion.fallback:
                log.info(
                    "window %d: the joint information product fell outside the windows' estimates "
                    "(ill-conditioned parameters); fused by each window's marginal precision",
                    w.index,
                )
            with torch.no_grad():
                for i, n in enumerate(names):
                    net.params.raw[n].copy_(theta[i])
        if held:
            net.params.set_values(held)
        fused = net.params.as_floats()
        self.trajectory.append(
            {"iteration": int(self.module.iteration), "t": w.t1, **{n: fused[n] for n in names}}
        )

    def _least_squares_start(self, w: Window) -> list[str]:
        """Least-squares values of the linear parameters; a value outside a parameter's range is
        reported (and that parameter kept), not clipped."""
        net = self.module.net
        est, rejected = net.least_squares_init(w)
        log.info("window %d: least-squares init %s", w.index, {k: f"{v:.5g}" for k, v in est.items()})
        self.ls_pending = sorted(rejected)
        notes = []
        for n, v in rejected.items():
            notes.append(
                note(
                    "ls_start_rejected",
                    f"window {w.index}: the least-squares start puts {n} at {v:.4g}, outside its range or not "
                    f"determined by this window (standard error above half the value); {n} keeps "
                    f"{net.params.as_floats()[n]:.4g}",
                )
            )
            log.warning(notes[-1])
        return notes

    def _latent_start(self, w: Window) -> list[str]:
        """Start the latent states' shape parameters (Bouc-Wen's beta, gamma, n) by variable
        projection on the networks' motion, and teach the LNN their path (see ``latent_start``)."""
        t0 = time.perf_counter()
        at_rest = (self.motions[0]["t"][0] if self.motions else w.t0) <= self.dm.windows[0].t0 + 1e-9
        accepted, rejected, line = latent_least_squares_start(
            self.module.net, w, self.motions, at_rest=at_rest
        )
        log.info("%s (%.1f s)", line, time.perf_counter() - t0)
        self.ls_pending = sorted(set(self.ls_pending) - set(accepted) | set(rejected))
        if accepted and self.fusion.thetas:
            # the earlier windows' estimates were made with a latent shape no window determined
            # (measured: their beta, gamma, n pulled a determined start back by 20-30 %)
            self.fusion = InformationFusion()
        if rejected:
            msg = note(
                "latent_start_undetermined",
                f"window {w.index}: the latent least-squares start does not determine "
                f"{', '.join(sorted(rejected))} from this window; they keep their values and the next window tries again",
            )
            log.info(msg)
            return [msg]
        return []

    def _drift_start(self, w: Window, with_params: bool) -> list[str]:
        net = self.module.net
        est, rejected = net.solve_drift(w, net.system.linear_params() if with_params else [])
        if est:
            log.info(
                "window %d: least-squares init with the displacement drift %s",
                w.index,
                {k: f"{v:.5g}" for k, v in est.items()},
            )
        if with_params:
            self.ls_pending = sorted(rejected)
        notes = []
        for n, v in rejected.items():
            notes.append(
                note(
                    "ls_start_rejected",
                    f"window {w.index}: the least-squares start puts {n} at {v:.4g}, outside its range or not "
                    f"determined by this window; {n} keeps {net.params.as_floats()[n]:.4g}",
                )
            )
            log.warning(notes[-1])
        return notes

    def _release_clamp(self, determined: set[str], index: int, notes: list[str]) -> None:
        """A parameter an earlier window left undetermined and this window's least-squares start
        determined drops its clamp box: the box came from a window that knew nothing of it."""
        if not determined:
            return
        if self.clamp is not None:
            for n in determined:
                self.clamp.bounds.pop(n, None)
        vals = self.module.net.params.as_floats()
        msg = note(
            "ls_start_determined",
            f"window {index}: the least-squares start determined {', '.join(sorted(determined))} "
            f"({', '.join(f'{n}={vals[n]:.4g}' for n in sorted(determined))}), which earlier windows did not",
        )
        log.info(msg)
        notes.append(msg)

    @staticmethod
    def _clamp_notes(names: list[str], estimate: dict[str, float], boxes: dict) -> list[str]:
        """A parameter that ended the window on its clamp box is reported, not silently held."""
        out = []
        for n in names:
            if n not in boxes:
                continue
            lo, hi = boxes[n]
            v = estimate[n]
            if min(abs(v - lo), abs(v - hi)) <= 1e-6 * max(abs(v), 1e-12):
                msg = note(
                    "on_clamp_bound",
                    f"{n} = {v:.5g} ended the window on its clamp bound [{lo:.5g}, {hi:.5g}]",
                )
                log.warning(msg)
                out.append(msg)
        return out

    def _report(self, r: WindowResult) -> None:
        truth = self.module.net.params.truths()
        parts = []
        for n, v in r.fused.items():
            e = f" ({error_pct(v, truth[n]):.2f}%)" if truth.get(n) else ""
            parts.append(f"{n}={v:.5g}{e}")
        log.info(
            "window %d [%.1f-%.1f s] %d it, %.1f s%s: %s",
            r.index,
            r.t0,
            r.t1,
            r.iterations,
            r.seconds,
            " (early stop)" if r.stopped_early else "",
            ", ".join(parts),
        )

    def _log_window(self, r: WindowResult) -> None:

        tb = tensorboard_writer(self.module.logger)  # None when no trainer or no TensorBoard
        if tb is None:
            return
        step = int(self.module.iteration)
        tb.add_scalar("subperiod/index", r.index, step)
        tb.add_scalar("subperiod/t_end", r.t1, step)
        for n, v in r.fused.items():
            tb.add_scalar(f"params_fused/{n}", v, step)
