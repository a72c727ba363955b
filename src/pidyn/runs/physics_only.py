"""The paper's prediction of a new record (Eq. 14) from a finished run folder: fresh response
networks trained window by window on the physics residual alone, the run's parameters held,
beside the plain simulation that ``predict.py`` reports first.

It applies where the networks' physics takes one ground acceleration (a building on a shake
table, a single-support record). A model driven by several supports' own motions has no single
ground acceleration for the networks' excitation transform, and is said so instead.
"""

from __future__ import annotations

import logging
from typing import Any

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from pidyn.assessment import heldout_scores
from pidyn.data.sources import Record
from pidyn.models.pidynnet import PIDynNet
from pidyn.models.predict import predict_response
from pidyn.models.predict_settings import PredictSettings
from pidyn.reporting import nrmse
from pidyn.systems.base import StructuralSystem

log = logging.getLogger(__name__)


def applies(system: StructuralSystem, record: Record) -> str | None:
    """Why the physics-only prediction does not apply to this model and record, or None."""
    if system.excitation != "ground" or record.excitation != "ground":
        return "the networks' physics is written for a ground acceleration"
    if system.n_inputs > 1:
        return (
            f"the model is driven by {system.n_inputs} supports' own motions; the networks take one ground "
            "acceleration"
        )
    return None


def physics_only(
    cfg: DictConfig,
    system: StructuralSystem,
    values: dict[str, float],
    record: Record,
    sim: dict,
    settings: Any,
) -> dict[str, Any]:
    """prediction.json's ``physics_only`` entry: every measured channel's NRMSE of the networks'
    prediction (``_response``: its accelerations from the model at its motion), its time,
    and the worst window's physics loss; or why it does not apply."""
    why = applies(system, record)
    if why is not None:
        return {"applies": False, "why": why}
    module, factory = _networks(cfg, system, values)
    x_scale = float(np.nanstd(sim["x"])) or 1.0
    v_scale = float(np.nanstd(sim["v"])) or None
    pred = predict_response(
        module,
        record,
        factory,
        PredictSettings(**OmegaConf.to_container(settings, resolve=True)),  # type: ignore[arg-type]
        x_scale=x_scale,
        v_scale=v_scale,
        seed=int(cfg.get("seed", 0)),
    )
    x = pred.x if pred.x.ndim == 2 else pred.x[:, None]
    response = _response(system, values, record, x)
    scores = heldout_scores(response, record, (float(record.t[0]), float(record.t[-1])))
    acc = [float(s) for k, s in scores["nrmse"].items() if k.startswith("a")]

    follows = [nrmse(x[:, j], np.asarray(sim["x"])[:, j]) for j in range(x.shape[1])]
    return {
        "applies": True,
        "nrmse": {k: float(s) for k, s in scores["nrmse"].items()},
        "mean_nrmse_a": float(np.mean(acc)) if acc else None,
        "nrmse_x_against_simulation": float(np.mean(follows)),  # how closely it follows the model's physics
        "seconds": pred.seconds,
        "max_window_loss": pred.max_window_loss,
        "response": response,
    }


def _response(system: StructuralSystem, values: dict[str, float], record: Record, x: np.ndarray) -> dict:
    """x, v, a of the networks' prediction: v by differentiating x once, a from the model's own
    equation of motion at (x, v) (differentiating twice would amplify the networks' small ripples
    by the frequency squared); a model with latent states, whose states the displacement alone does
    not give, by differentiating twice."""
    v = np.gradient(x, record.dt, axis=0)
    n = system.n_dof
    if system.n_latent:
        return {"x": x, "v": v, "a": np.gradient(v, record.dt, axis=0)}
    rate = system.state_rate(record.t, np.concatenate([x, v], axis=1), values, np.asarray(record.f, float))
    return {"x": x, "v": v, "a": np.asarray(rate)[:, n : 2 * n]}


def _networks(cfg: DictConfig, system: StructuralSystem, values: dict[str, float]) -> tuple[Any, Any]:
    """A PIDynNet of the run's architecture on ``system`` with the run's values held, and a
    factory of quiet trainers."""
    import lightning as L  # lazy: the prediction's trainer only

    rpn = hydra.utils.instantiate(cfg.model.rpn, out_features=system.n_dof)
    lnn = hydra.utils.instantiate(cfg.model.lnn, out_features=system.n_latent) if system.n_latent else None
    core = PIDynNet(system, rpn, lnn, normalize_losses=cfg.model.normalize_losses)
    core.params.set_values({k: v for k, v in values.items() if k in core.params.raw})
    module = hydra.utils.instantiate(cfg.model.module, net=core)

    def factory(**kw: Any) -> L.Trainer:
        kw.setdefault("enable_progress_bar", False)
        return hydra.utils.instantiate(cfg.trainer, logger=False, **kw)

    return module, factory
