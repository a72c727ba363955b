"""Response prediction for unseen excitations by physics-only fine-tuning (paper Eq. 14).

The identified parameters stay fixed; the RPN (and LNN) are trained window by window on
the physics residual alone (from a fresh start or from the identification networks), with
the state at each window start handed over from the previous window (zero at rest before
the record). No measurement of the new response is used.
"""

from __future__ import annotations

import copy
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import lightning as L
import numpy as np
import torch

from pidyn.data.datamodule import SubperiodDataModule
from pidyn.data.sources import Record
from pidyn.models.lit_module import PIDynNetModule
from pidyn.models.predict_settings import PredictSettings

log = logging.getLogger(__name__)


@dataclass
class Prediction:
    name: str
    t: np.ndarray
    x: np.ndarray
    seconds: float
    windows: list[tuple[float, float, float]] = field(default_factory=list)  # (t0, t1, final physics loss)

    @property
    def max_window_loss(self) -> float:
        return max((w[2] for w in self.windows), default=float("nan"))


@dataclass
class _Scales:
    x: torch.Tensor
    v: torch.Tensor
    f: torch.Tensor


def predict_response(
    module: PIDynNetModule,
    record: Record,
    trainer_factory: Callable[..., L.Trainer],
    settings: PredictSettings | None = None,
    window_length: float = 3.0,
    pool_size: int = 1000,
    batch_size: int = 500,
    x_scale: float | None = None,
    v_scale: float | None = None,
    data_seed: int = 0,
    seed: int = 0,
) -> Prediction:
    """Fine-tune the networks on the physics of ``record``'s excitation; returns predicted x.

    The state handed over between windows is imposed exactly through the output (see
    ``PIDynNet._anchored``), so the only loss is the physics residual, as in Eq. 14. The
    identified parameters are held and the identification networks restored afterwards.
    ``x_scale``, ``v_scale``: the response scales (the identification record's), since the new
    response is not measured.
    """
    cfg = settings or PredictSettings()
    t_start = time.perf_counter()
    net = module.net
    for p in net.physical_parameters():
        p.requires_grad_(False)
    accel = net.system.excitation_as_acceleration(record.f)
    blank, dm = _blank_windows(net, record, accel, window_length, pool_size, batch_size, data_seed)
    scales = _prediction_scales(net, record, x_scale, v_scale)
    x_pred = np.zeros((len(record.t), net.system.n_dof))
    saved = _nets_state(net)
    if cfg.start_from == "fresh":
        _reset_networks(net, seed)
    try:
        done = _march(
            module,
            blank,
            deque((w.t0, w.t1) for w in dm.windows),
            accel,
            scales,
            trainer_factory,
            cfg,
            x_pred,
            pool_size,
            batch_size,
            data_seed,
        )
        log.info("predicted %s: %d windows, %.1f s", record.name, len(done), time.perf_counter() - t_start)
    finally:
        net.anchor = None
        _load_nets(net, saved)
        for p in net.physical_parameters():
            p.requires_grad_(True)
    return Prediction(record.name, record.t, x_pred, time.perf_counter() - t_start, done)


def _blank_windows(
    net, record: Record, accel, window_length: float, pool_size: int, batch_size: int, data_seed: int
):
    """The record with a zero response (the DataModule needs response columns for its windows;
    fine-tuning never uses them) and its windows, covering the record's tail."""
    blank = Record(
        name=record.name,
        t=record.t,
        f=record.f,
        x=np.zeros((len(record.t), net.system.n_dof)),
        excitation=record.excitation,
    )
    dm = SubperiodDataModule(
        blank,
        window_length=window_length,
        pool_size=pool_size,
        batch_size=batch_size,
        min_peak_fraction=0.0,
        data_seed=data_seed,
        accel_signal=accel,
        cover_tail=True,
    )
    return blank, dm


def _prediction_scales(net, record: Record, x_scale: float | None, v_scale: float | None) -> _Scales:
    """The response scales of the identification (the new response is not measured) and the
    new excitation's own scale."""
    dt = net.scale_x.dtype
    return _Scales(
        x=torch.full_like(net.scale_x, float(x_scale)) if x_scale else net.scale_x.clone(),
        v=torch.full_like(net.scale_v, float(v_scale)) if v_scale else net.scale_v.clone(),
        f=torch.as_tensor(float(np.std(record.f)), dtype=dt),
    )


def _march(
    module: PIDynNetModule,
    blank: Record,
    spans: deque,
    accel,
    scales: _Scales,
    trainer_factory: Callable[..., L.Trainer],
    cfg: PredictSettings,
    x_pred: np.ndarray,
    pool_size: int,
    batch_size: int,
    data_seed: int,
) -> list[tuple[float, float, float]]:
    """Window after window from rest, each started from the state the last one ended in; a
    window left above ``split_tol`` is solved again as two halves. Writes ``x_pred``; returns
    (t0, t1, final physics loss) per solved window."""
    net = module.net
    dt = net.scale_x.dtype
    state = (
        torch.zeros(net.system.n_dof, dtype=dt),
        torch.zeros(net.system.n_dof, dtype=dt),
        torch.zeros(net.system.n_latent, dtype=dt) if net.system.n_latent else None,
    )
    done: list[tuple[float, float, float]] = []
    while spans:
        t0, t1 = spans.popleft()
        wdm = SubperiodDataModule(
            blank,
            window_length=t1 - t0,
            pool_size=pool_size,
            batch_size=batch_size,
            min_peak_fraction=0.0,
            t_start=t0,
            t_end=t1,
            data_seed=data_seed + len(done),
            accel_signal=accel,
        )
        w = wdm.windows[0]
        before = _nets_state(net)
        loss = _solve_window(module, wdm, w, state, scales, trainer_factory, cfg)
        if not (loss <= cfg.split_tol) and (t1 - t0) / 2 >= cfg.min_window - 1e-9:
            log.info(
                "%s: window %.2f-%.2f s ended at physics loss %.3g > %.3g: solving it as two halves",
                blank.name,
                t0,
                t1,
                loss,
                cfg.split_tol,
            )
            _load_nets(net, before)
            mid = 0.5 * (t0 + t1)
            spans.extendleft([(mid, t1), (t0, mid)])
            continue
        done.append((float(t0), float(t1), float(loss)))
        state = net.state_at_end(w)
        log.debug("window %.2f-%.2f s: physics loss %.3g", t0, t1, loss)
        _write_window(net, w, blank.t, x_pred)
    return done


def _reset_networks(net, seed: int) -> None:
    """A fresh (seeded) start of the RPN and LNN for a new excitation."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        for m in (net.rpn, net.lnn):
            if m is not None:
                for layer in m.layers:
                    layer.reset_parameters()


def _solve_window(
    module: PIDynNetModule,
    wdm: SubperiodDataModule,
    w,
    state,
    scales: _Scales,
    trainer_factory,
    cfg: PredictSettings,
) -> float:
    """Adam, then L-BFGS, on the physics of one window from the handed-over state; returns the
    window's final physics loss."""
    net = module.net
    net.enter_prediction_window(w, scales.x, scales.v, scales.f)
    net.anchor = (w.t0 * torch.ones((), dtype=net.scale_x.dtype), state[0], state[1], state[2])
    module.start(w, "finetune", cfg.iterations)
    wdm.activate(w.index, cfg.iterations, module.inner_steps, physics=True)
    trainer_factory(max_steps=-1, callbacks=[]).fit(module, datamodule=wdm)
    return _lbfgs_finish(module, wdm, w, trainer_factory, cfg.lbfgs_steps)


@torch.no_grad()
def _write_window(net, w, t: np.ndarray, x_pred: np.ndarray) -> None:
    m = (t >= w.t0 - 1e-9) & (t <= w.t1 + 1e-9)
    k = net.kinematics(w.t_data, w.f_data, w.q_data, w.qd_data, order=0, latent=False)
    x_pred[m] = k.x.numpy()


def _nets_state(net) -> dict:
    return copy.deepcopy(
        {"rpn": net.rpn.state_dict(), "lnn": net.lnn.state_dict() if net.lnn is not None else None}
    )


def _load_nets(net, state: dict) -> None:
    net.rpn.load_state_dict(state["rpn"])
    if net.lnn is not None:
        net.lnn.load_state_dict(state["lnn"])


def _lbfgs_finish(module: PIDynNetModule, dm: SubperiodDataModule, w, trainer_factory, steps: int) -> float:
    """L-BFGS after Adam; the Adam networks are kept if L-BFGS ends worse or non-finite.
    Returns the window's final physics loss on its whole pool."""
    net = module.net
    with torch.no_grad():
        adam_loss = float(module.total(net.physics_losses(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)))
    if steps <= 0 or adam_loss < module.lbfgs_tol:
        return adam_loss
    keep = _nets_state(net)
    module.start(w, "finetune_lbfgs", steps)
    module.last_losses = {"total": adam_loss}
    dm.activate(w.index, steps, 1, physics=False)
    trainer_factory(max_steps=-1, callbacks=[]).fit(module, datamodule=dm)
    final = module.last_losses.get("total", float("nan"))
    if not np.isfinite(final) or final > adam_loss:
        _load_nets(net, keep)
        log.debug(
            "window %d: L-BFGS ended at %.3g, worse than Adam's %.3g; Adam's networks kept",
            w.index,
            final,
            adam_loss,
        )
        return adam_loss
    log.debug("window %d: L-BFGS %.3g -> %.3g", w.index, adam_loss, final)
    return float(final)


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.ravel(a), np.ravel(b)
    if np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])
