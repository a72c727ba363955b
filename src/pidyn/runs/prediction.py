"""A record the model has not seen: an identification read back from its run folder, the record
checked against the channels it was identified on, the model simulated from rest under the
record's own input motions, every measured channel scored beside the prediction that knows
nothing (the structure moving with its support, or at rest) and the linear model of the same
layout where there is one. ``predict.py`` (``pidyn.tasks.predict``) and ``pidyn.predict`` use it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf, open_dict

from pidyn.adequacy import trivial_predictions
from pidyn.assessment import heldout_scores, measured_convention
from pidyn.config import choose_system
from pidyn.data.layout import sensor_view
from pidyn.data.sources import Record
from pidyn.params import fixed_values
from pidyn.reporting import nrmse, plottable, pyplot
from pidyn.runs.build import system_and_record
from pidyn.runs.folder import COMPLETE, is_complete
from pidyn.runs.linear_beside import linear_model
from pidyn.simulate import simulate_response
from pidyn.systems.base import StructuralSystem

#: the channels' units, for the figure's axes
UNITS = {"x": "m", "v": "m/s", "a": "m/s^2"}

#: the record's channel map must be the run's, key by key (a missing key is not compared)
CHANNEL_KEYS = ("station", "direction", "input_channels", "output_channels")


@dataclass
class Identified:
    """A finished identification read back from its run folder: its config, system and values."""

    run_dir: Path
    cfg: DictConfig
    metrics: dict[str, Any]
    values: dict[str, float] = field(default_factory=dict)

    @classmethod
    def load(cls, run_dir: str | Path) -> Identified:

        run_dir = Path(run_dir)
        config = run_dir / ".hydra" / "config.yaml"
        if not is_complete(run_dir) or not (run_dir / "metrics.json").is_file() or not config.is_file():
            raise FileNotFoundError(
                f"{run_dir}: not a finished identification (no {COMPLETE}, metrics.json and .hydra/config.yaml)"
            )
        cfg = choose_system(OmegaConf.load(config))  # the model the run's own records called for
        if str(cfg.get("task_name", "train")) in ("diagnose", "predict"):
            raise ValueError(f"{run_dir}: a {cfg.task_name} run, not an identification")
        return cls(run_dir, cfg, json.loads((run_dir / "metrics.json").read_text()))

    def for_record(
        self, data: DictConfig | None = None, record: Record | None = None
    ) -> tuple[StructuralSystem, Record, dict[str, float]]:
        """The run's system and values, and the record (``record``, or the one ``data`` describes,
        read as the run read its own); the system's inputs are the record's where the run took
        them so."""
        cfg = self.cfg.copy()
        with open_dict(cfg):
            if data is not None:
                cfg.data = data
            # the scale the run read from its own records, not from the record predicted
            cfg.system.update(self.metrics.get("scale") or {})
        system, record = system_and_record(cfg, record)
        values = {**fixed_values(system), **{k: float(v) for k, v in self.metrics["params"].items()}}
        missing = sorted(s.name for s in system.param_specs() if s.name not in values)
        if missing:
            check_channels(self, record)  # another channel set: say so, not which values are missing
            raise ValueError(f"{self.run_dir}: the run's metrics.json gives no value of {', '.join(missing)}")
        return system, record, values

    def linear_beside(self) -> Identified | None:
        """The linear model of the same layout that the run fitted beside its own on the same
        records (``metrics.json``'s ``linear_model``), as a run of its own; None where it has none."""
        found = linear_model(self.cfg, self.metrics)
        if found is None:
            return None
        cfg, values = found
        system = (self.metrics.get("linear_model") or {}).get("system")
        return Identified(
            self.run_dir,
            cfg,
            # the run's adequacy test judged its own model, not this one
            {**self.metrics, "params": values, "scale": {}, "system": system, "adequacy": None},
        )

    def chosen(self) -> Identified:
        """The model the run stands behind: its own, or the linear model beside it where its own
        records, each left out and predicted, said its nonlinear terms did not earn their place
        (``metrics.json``'s ``model_choice``, ``pidyn.runs.model_choice``)."""
        if (self.metrics.get("model_choice") or {}).get("chosen") == "linear":
            linear = self.linear_beside()
            if linear is not None:
                return linear
        return self

    @property
    def record_meta(self) -> dict[str, Any]:
        return dict(self.metrics.get("record_meta") or {})


def check_channels(run: Identified, record: Record) -> None:
    """The new record measures the structure as the run's record did: the same station, direction,
    input and output channels (a model of supports ch3, ch17, ch20 cannot read another set)."""
    own = run.record_meta
    new = {**record.meta.to_dict(CHANNEL_KEYS), "sensors": record.sensors(), "inputs": record.inputs}
    wrong = [
        f"{key} {new.get(key)!r} (the run: {own.get(key)!r})"
        for key in (*CHANNEL_KEYS, "sensors", "inputs")
        if key in own and own.get(key) is not None and _plain(new.get(key)) != _plain(own.get(key))
    ]
    if wrong:
        raise ValueError(
            f"record '{record.name}' does not match run {run.run_dir}: {'; '.join(wrong)}; "
            "a model predicts the channels it was identified on"
        )


def _plain(value: Any) -> Any:
    """JSON's view of a value (dict keys as strings, tuples as lists), to compare with metrics.json."""
    return json.loads(json.dumps(value))


def channel_names(record: Record, keys: list[str]) -> dict[str, str]:
    """Score keys (``a1``: the first output) -> the record's own channel names (``a7``: the station's
    channel 7; a building's floors keep their numbers)."""
    outs = record.meta.output_channels
    out = {}
    for key in keys:
        kind, num = key[0], key[1:]
        if outs and kind == "a" and num.isdigit() and int(num) <= len(outs):
            out[key] = f"a{outs[int(num) - 1]}"
        else:
            out[key] = key if num else f"{key}1"
    return out


def score(system: StructuralSystem, values: dict[str, float], record: Record) -> dict[str, Any]:
    """The model simulated from rest over the record: NRMSE per measured channel and their mean."""
    sim = simulate_response(system, values, record)
    span = (float(record.t[0]), float(record.t[-1]))
    record, channels = sensor_view(record, sim)  # a deck's own channels (pidyn.data.layout)
    scores = heldout_scores(channels, record, span)
    names = channel_names(record, list(scores["nrmse"]))
    nrmse_by = {names[k]: float(v) for k, v in scores["nrmse"].items()}
    acc = [v for k, v in nrmse_by.items() if k.startswith("a")]
    return {"sim": sim, "nrmse": nrmse_by, "mean_nrmse_a": float(np.mean(acc)) if acc else None}


def trivial(record: Record) -> dict[str, Any]:
    """The prediction that knows nothing, chosen on the predicted record itself (so it is at least
    as good as any such choice made beforehand)."""
    record, _ = sensor_view(record, {})  # a deck's own channels (pidyn.data.layout)
    span = (float(record.t[0]), float(record.t[-1]))
    preds = trivial_predictions(record, span)
    out, labels = {}, set()
    multi = record.n_dof > 1
    for kind, floors in record.sensors().items():
        meas = measured_convention({kind: getattr(record, kind)}, record, kind)
        for fl in floors:
            label, series = preds[f"{kind}{fl}" if multi else kind]
            out[f"{kind}{fl}"] = nrmse(series, meas[:, fl - 1])
            labels.add(label)
    names = channel_names(record, list(out))
    by = {names[k]: float(v) for k, v in out.items()}
    acc = [v for k, v in by.items() if k.startswith("a")]
    return {
        "label": ", ".join(sorted(labels)),
        "nrmse": by,
        "mean_nrmse_a": float(np.mean(acc)) if acc else None,
    }


def predict_record(
    run: Identified,
    record: Record,
    system: StructuralSystem | None = None,
    values: dict[str, float] | None = None,
    linear_run: Identified | None = None,
    data: DictConfig | None = None,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """prediction.json's content and the simulated response for ``record`` (checked against the run's channels)."""
    if system is None or values is None:
        system, record, values = run.for_record(record=record)
    check_channels(run, record)
    ours = score(system, values, record)
    linear = _linear(linear_run or run.linear_beside(), data, system, record, ours)
    knows_nothing = trivial(record)
    offset = float(record.meta.t_offset or 0.0)
    out = {
        "mean_nrmse_a": ours["mean_nrmse_a"],
        "nrmse": ours["nrmse"],
        "span": [offset + float(record.t[0]), offset + float(record.t[-1])],
        "linear_mean_nrmse_a": linear,
        "trivial": knows_nothing["label"],
        "trivial_mean_nrmse_a": knows_nothing["mean_nrmse_a"],
        "trivial_nrmse": knows_nothing["nrmse"],
        "beats_trivial": _beats(ours["mean_nrmse_a"], knows_nothing["mean_nrmse_a"]),
        "run": str(run.run_dir),
        "system": run.metrics.get("system"),
        "model_choice": (run.metrics.get("model_choice") or {}).get("chosen"),
        # False: the run's own records could not tell its two models apart (model_choice.decisive)
        "model_choice_decisive": (run.metrics.get("model_choice") or {}).get("decisive"),
        **run_verdict(run),
        "identified_on": run.metrics.get("record"),
        "record": record.name,
        "seen_by_run": record.name in str(run.metrics.get("record") or "").split("+"),
        "pga": record.meta.pga,
        "pga_unit": "m/s^2",  # the record's largest input acceleration, as every record's meta keeps it
        **training_range(run, record.meta.pga),
        "simulated": "from rest, the record's own input motions, fixed-step RK4",
    }
    return out, ours["sim"]


def run_verdict(run: Identified) -> dict[str, Any]:
    """The run's own verdict on the model that predicts (``metrics.json``'s ``adequacy``):
    ``model_adequate`` (None where the run gives none, as for the linear model beside it) and
    ``model_rejected_because``. A model its own records reject (one that cannot be simulated
    stably, or misses them worse than knowing nothing) can still score on another record by
    chance; its prediction is not a property of the structure."""
    adequacy = run.metrics.get("adequacy") or {}
    verdict = adequacy.get("adequate")
    return {
        "model_adequate": None if verdict is None else bool(verdict),
        "model_rejected_because": list(adequacy.get("reasons") or []) if verdict is False else [],
    }


def training_range(run: Identified, pga: float | None) -> dict[str, Any]:
    """The peak input accelerations of the records the run was identified on (``training_pga``:
    [smallest, largest]) and, where the predicted record's lies outside them, by what factor
    (``beyond_training``: above 1 stronger than any, below 1 weaker): a model whose stiffness
    follows the amplitude is extrapolated there, and a linear one was never shown that shaking."""
    meta = run.record_meta
    pgas = [float(r["pga"]) for r in meta.get("records") or [] if r.get("pga")]
    if not pgas and meta.get("pga"):
        pgas = [float(meta["pga"])]
    if not pgas or not pga:
        return {"training_pga": None, "beyond_training": None}
    lo, hi = min(pgas), max(pgas)
    factor = pga / hi if pga > hi else (pga / lo if pga < lo else None)
    return {"training_pga": [lo, hi], "beyond_training": factor}


def _beats(ours: float | None, theirs: float | None) -> bool | None:
    if ours is None or theirs is None:
        return None
    return bool(ours < theirs)


def _linear(other: Identified | None, data, system, record, ours) -> float | None:
    """The linear model of the same layout: ``linear_run=`` (identified on the same records), or
    the run's own model when it is linear; None otherwise."""
    if other is not None:
        sys_l, rec_l, val_l = other.for_record(data, None if data is not None else record)
        check_channels(other, rec_l)
        return score(sys_l, val_l, rec_l)["mean_nrmse_a"]
    if getattr(system, "linear_time_invariant", False):
        return ours["mean_nrmse_a"]
    return None


def figure(path: Path, record: Record, sim: dict[str, np.ndarray], run: Identified, out: dict) -> None:
    """Predicted against measured motion, one panel per measured channel."""
    plt = pyplot()

    path.parent.mkdir(parents=True, exist_ok=True)
    record, sim = sensor_view(record, sim)
    panels = [(kind, fl) for kind, floors in record.sensors().items() for fl in floors]
    names = channel_names(record, [f"{k}{fl}" for k, fl in panels])
    fig, axes = plt.subplots(
        len(panels), 1, figsize=(10, 2.2 * len(panels) + 0.6), sharex=True, squeeze=False
    )
    t = record.t + float(record.meta.t_offset or 0.0)
    for ax, (kind, fl) in zip(axes[:, 0], panels):
        meas = measured_convention({kind: getattr(record, kind)}, record, kind)[:, fl - 1]
        pred = measured_convention(sim, record, kind)[:, fl - 1]
        name = names[f"{kind}{fl}"]
        ax.plot(t, meas, color="0.3", lw=0.9, label=f"measured {name}")
        ax.plot(t, plottable(pred), lw=0.8, ls="--", label=f"predicted (NRMSE {out['nrmse'][name]:.3g})")
        ax.set_ylabel(f"{name} ({UNITS.get(kind, '')})")
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("t (s)")
    seen = str(out.get("identified_on") or "").split("+")
    on = f"{len(seen)} records" if len(seen) > 1 else (seen[0] or Path(str(out["run"])).name)
    on += " including this one" if out.get("seen_by_run") else ""
    fig.suptitle(f"{record.name}: predicted by the {out.get('system')} model identified on {on}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
