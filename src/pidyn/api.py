"""The Python API: identify, diagnose and predict from a notebook or a script.

    import pidyn
    rec = pidyn.Record.simulate("duffing", excitation="kobe", noise=0.025)
    res = pidyn.identify(rec, "duffing")
    res.to_frame()                       # value, 95 % interval, std, truth, error per parameter
    res.plot()                           # PIDynNet's estimate over the record, the final interval
    pred = pidyn.predict(res, "el_centro", scale=0.5)
    diag = pidyn.diagnose(rec, nominal="linear")

Each call composes the same configs as the command line (``pidyn-train``), with the
keyword values checked against them, and runs the same task code; every run still writes
its run folder (``Result.run_dir``), so a notebook run can be reopened with
``Result.load(run_dir)`` and compared with command-line runs.
"""

from __future__ import annotations

import contextlib
import json
import logging
import shutil
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from hydra.errors import HydraException
from omegaconf.errors import OmegaConfBaseException

from pidyn.assessment import measured_convention
from pidyn.config import compose, group_options
from pidyn.data.multi import concatenate
from pidyn.data.sources import Record
from pidyn.excitation.ground_motion import prepare
from pidyn.reporting import plot_convergence
from pidyn.runs.folder import COMPLETE, is_complete
from pidyn.simulate import simulate

#: short names for settings a notebook user sets often (any other key: ``model__schedule__max_windows=4``)
ALIASES = {
    "refine": "model/refine",
    "baselines": "baselines",
    "logger": "logger",
    "debug": "debug",
    "trainer": "trainer",
    "excitation": "excitation",
    "data": "data",  # data="csmip", data__station="CE89324": a record's reader and its settings
}


def _split_options(options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Keyword options -> (group choices, dotted settings); ``a__b`` is the key ``a.b``."""
    groups, values = {}, {}
    for key, value in options.items():
        if key in ALIASES:
            groups[ALIASES[key]] = value
        else:
            values[key.replace("__", ".")] = value
    return groups, values


def _run_dir(out_dir: str | Path | None, task: str, name: str) -> Path:
    if out_dir is not None:
        return Path(out_dir)
    return Path("outputs") / task / "api" / f"{time.strftime('%Y-%m-%d_%H-%M-%S')}_{name}"


@dataclass
class Result:
    """An identification: the final estimate with its intervals, PIDynNet's own estimate, the
    identified equation, the estimate's history over the record, and the run folder."""

    system: str
    params: dict[str, float]
    ci95: dict[str, list[float]]
    std: dict[str, float]
    truth: dict[str, float | None]
    error_pct: dict[str, float]
    pidynnet: dict[str, float]
    equation: str
    notes: list[str]
    metrics: dict[str, Any]
    run_dir: Path
    history: pd.DataFrame
    windows: list[dict] = field(default_factory=list)
    _objects: dict[str, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def load(cls, run_dir: str | Path, objects: dict[str, Any] | None = None) -> Result:
        """A run folder written by ``identify`` or ``pidyn-train``, read back."""
        run_dir = Path(run_dir)

        if not (run_dir / "metrics.json").exists() or not is_complete(run_dir):
            failed = run_dir / "failed.json"
            why = f" ({json.loads(failed.read_text()).get('message')})" if failed.is_file() else ""
            raise FileNotFoundError(
                f"{run_dir}: no metrics.json and {COMPLETE}; not a finished identification run folder{why}"
            )
        m = json.loads((run_dir / "metrics.json").read_text())
        ident = yaml.safe_load((run_dir / "identified_params.yaml").read_text())
        state = run_dir / "subperiod_state.json"
        traj = json.loads(state.read_text()).get("trajectory", []) if state.exists() else []
        wins = run_dir / "windows.json"
        return cls(
            system=m["system"],
            params=m["params"],
            ci95=m.get("ci95", {}),
            std=m.get("std", {}),
            truth=m.get("truth", {}),
            error_pct=m.get("error_pct", {}),
            pidynnet=m["pidynnet"]["params"],
            equation=ident["equation"],
            notes=list(m.get("notes", [])),
            metrics=m,
            run_dir=run_dir,
            history=pd.DataFrame(traj),
            windows=json.loads(wins.read_text())["windows"] if wins.exists() else [],
            _objects=objects or {},
        )

    def to_frame(self) -> pd.DataFrame:
        """One row per parameter: value, ci95_lo, ci95_hi, std, truth, error_pct, pidynnet."""
        rows = []
        for n, v in self.params.items():
            lo, hi = self.ci95.get(n, (np.nan, np.nan))
            rows.append(
                {
                    "param": n,
                    "value": v,
                    "ci95_lo": lo,
                    "ci95_hi": hi,
                    "std": self.std.get(n, np.nan),
                    "truth": self.truth.get(n),
                    "error_pct": self.error_pct.get(n, np.nan),
                    "pidynnet": self.pidynnet.get(n, np.nan),
                }
            )
        return pd.DataFrame(rows).set_index("param")

    def plot(self, path: str | Path | None = None):
        """PIDynNet's estimate over record time with the window edges, the truth when known and
        the final estimate with its 95 % interval; returns the figure (or writes ``path``)."""
        final = {n: {"value": v, "ci95": self.ci95[n]} for n, v in self.params.items() if n in self.ci95}
        return plot_convergence(
            None if path is None else Path(path),
            self.history.to_dict("records"),
            self.truth,
            self.windows,
            title=f"{self.system}: {self.equation}",
            final=final or None,
        )

    def save(self, directory: str | Path) -> Path:
        """Copy the run folder to ``directory`` and add ``params.csv`` and ``history.csv``."""
        directory = Path(directory)
        if directory.resolve() != self.run_dir.resolve():
            shutil.copytree(self.run_dir, directory, dirs_exist_ok=True)
        self.to_frame().to_csv(directory / "params.csv")
        self.history.to_csv(directory / "history.csv", index=False)
        return directory


@contextlib.contextmanager
def _progress(show: bool = True):
    """A notebook or script whose logging nobody configured sees pidyn's progress lines (windows,
    refinement, diagnosis steps) on stderr for the call; a program that set up its own logging
    (a handler on ``pidyn`` or on the root logger) keeps it as it is, and ``show=False`` (the
    calls' ``progress=False``) keeps the call silent but for warnings."""
    logger = logging.getLogger("pidyn")
    if not show or logger.handlers or logging.getLogger().handlers:
        yield
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("[%(asctime)s] %(message)s", "%H:%M:%S"))
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


@contextlib.contextmanager
def _user_errors():
    """A setting Hydra or OmegaConf refuses (a wrong value in ``init``, a misspelled override)
    comes out as a ``ValueError`` with the cause's message: the API raises no framework's type."""
    try:
        yield
    except (HydraException, OmegaConfBaseException) as exc:
        cause = exc.__cause__ if isinstance(exc.__cause__, (ValueError, FileNotFoundError)) else None
        if cause is not None:
            raise cause from None
        raise ValueError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__) from exc


def identify(
    record: Record | Sequence[Record] | None = None,
    system: str = "duffing",
    *,
    init: dict[str, float] | None = None,
    out_dir: str | Path | None = None,
    overrides: Iterable[str] = (),
    progress: bool = True,
    **options: Any,
) -> Result:
    """Identify ``system`` (a name from ``conf/system``) from ``record`` (default: the
    configured simulated record; a list: several records of one structure, its parameters shared
    and each record's initial state its own) with PIDynNet and the refinement stage.

    ``init``: starting guesses (``{"k3": 50.0}``). ``options``: config settings by key, ``__``
    for a dot (``seed=1``, ``refine="none"``, ``baselines="none"``,
    ``model__schedule__max_windows=4``); ``overrides``: raw Hydra override strings;
    ``progress=False``: no progress lines in a notebook (warnings still show).
    """
    from pidyn.tasks.train import (
        identify_run as run_identification,  # lazy: torch and Lightning load (seconds) on the first call that needs them
    )

    if record is not None and not isinstance(record, Record):
        with _user_errors(), _progress(progress):
            record = concatenate(list(record))
    groups, values = _split_options(options)
    values.update({f"system.params.{k}.init": float(v) for k, v in (init or {}).items()})
    values.setdefault("trainer.enable_progress_bar", False)
    values.setdefault("raise_errors", True)
    run_dir = _run_dir(out_dir, "train", system)
    with _user_errors(), _progress(progress):
        cfg = compose(
            "train",
            groups={"system": system, **groups},
            values=values,
            overrides=overrides,
            output_dir=run_dir,
        )
        _, objects = run_identification(cfg, record=record)
    return Result.load(run_dir, objects)


@dataclass
class ResponsePrediction:
    """The response to an excitation the identification never saw: PIDynNet's networks
    fine-tuned on the physics alone, beside the identified model simulated."""

    name: str
    t: np.ndarray
    ag: np.ndarray
    x_pidynnet: np.ndarray
    x_simulated: np.ndarray
    seconds: float

    def to_frame(self) -> pd.DataFrame:
        cols = {"t": self.t, "ag": self.ag}
        for i in range(self.x_pidynnet.shape[1]):
            cols[f"x{i + 1}_pidynnet"] = self.x_pidynnet[:, i]
            cols[f"x{i + 1}_simulated"] = self.x_simulated[:, i]
        return pd.DataFrame(cols)


@dataclass
class RecordPrediction:
    """A measured record the identification never saw, predicted by the identified model simulated
    from rest under the record's own inputs: ``scores`` is what ``predict.py`` writes to
    prediction.json (NRMSE per channel, their mean, knowing nothing's beside it)."""

    name: str
    t: np.ndarray
    measured: dict[str, np.ndarray]
    predicted: dict[str, np.ndarray]
    scores: dict[str, Any]

    @property
    def mean_nrmse_a(self) -> float | None:
        return self.scores["mean_nrmse_a"]

    def to_frame(self) -> pd.DataFrame:
        cols: dict[str, np.ndarray] = {"t": self.t}
        for k in self.measured:
            cols[f"{k}_measured"] = self.measured[k]
            cols[f"{k}_predicted"] = self.predicted[k]
        return pd.DataFrame(cols)


def _predict_record(result: Result, record: Record) -> RecordPrediction:
    from pidyn.runs.prediction import (  # lazy: torch and Lightning load (seconds) on the first call that needs them
        Identified,
        channel_names,
        predict_record,
    )

    with _user_errors(), _progress():
        run = Identified.load(result.run_dir).chosen()  # as predict.py: the model the run's records chose
        system, rec, values = run.for_record(record=record)
        scores, sim = predict_record(run, rec, system, values)
    measured, predicted = {}, {}
    for kind, floors in rec.sensors().items():
        meas = measured_convention({kind: getattr(rec, kind)}, rec, kind)
        pred = measured_convention(sim, rec, kind)
        names = channel_names(rec, [f"{kind}{fl}" for fl in floors])
        for fl in floors:
            measured[names[f"{kind}{fl}"]] = meas[:, fl - 1]
            predicted[names[f"{kind}{fl}"]] = pred[:, fl - 1]
    return RecordPrediction(rec.name, rec.t, measured, predicted, scores)


def predict(
    result: Result,
    excitation: str | Path | Record,
    *,
    scale: float = 1.0,
    stretch: float = 1.0,
    duration: float | None = 20.0,
    dt: float | None = 0.01,
    start: float = 0.0,
    **settings: Any,
) -> ResponsePrediction:
    """Predict the response of the identified structure to ``excitation``.

    A measured ``Record`` (CSMIP, IMU, CSV, simulated): the model simulated from rest under the
    record's own inputs, every measured channel scored (a ``RecordPrediction``, as ``predict.py``).
    A shipped record's name or an AT2 path: as in the paper's Eq. 14, PIDynNet's networks
    fine-tuned on the physics alone beside the model simulated (a ``ResponsePrediction``; needs
    the networks of a run of this session). ``settings``: fields of ``PredictSettings``
    (``iterations``, ``lbfgs_steps``, ``split_tol``, ``min_window``, ``start_from``)."""
    if isinstance(excitation, Record):
        return _predict_record(result, excitation)
    from pidyn.models.predict import (  # lazy: torch and Lightning load (seconds) on the first call that needs them
        PredictSettings,
        predict_response,
    )

    obj = result._objects
    if not obj:
        raise ValueError(
            "predict needs the networks of an identification run in this session: "
            "a Result from pidyn.identify(), not one read back with Result.load()"
        )
    valid = set(PredictSettings.__dataclass_fields__)
    unknown = set(settings) - valid
    if unknown:
        raise ValueError(f"predict: unknown setting(s) {sorted(unknown)}; the settings are {sorted(valid)}")
    module, system, ident_record = obj["module"], obj["system"], obj["record"]
    gm = prepare(excitation, scale=scale, stretch=stretch, duration=duration, dt=dt, start=start)
    values = dict(result.params)
    sim = simulate(system, {**module.net.params.as_floats(), **values}, gm, gm.t)
    target = Record(name=gm.name, t=gm.t, f=gm.acc, x=np.zeros((len(gm.t), system.n_dof)))  # the shape only
    scale_x = float(np.nanstd(ident_record.x)) if ident_record.x is not None else float(np.nanstd(sim.x))
    scale_v = float(np.nanstd(ident_record.v)) if ident_record.v is not None else None
    pred = predict_response(
        module, target, obj["trainer_factory"], PredictSettings(**settings), x_scale=scale_x, v_scale=scale_v
    )
    x_pred = pred.x if pred.x.ndim == 2 else pred.x[:, None]
    x_sim = sim.x if sim.x.ndim == 2 else sim.x[:, None]
    return ResponsePrediction(
        name=gm.name, t=gm.t, ag=gm.acc, x_pidynnet=x_pred, x_simulated=x_sim, seconds=pred.seconds
    )


@dataclass
class Diagnosis:
    """What the nominal model gets wrong: the verdict (``discrepancy``, ``unexplained`` or
    ``none``), the named causes, the extended equation and its held-out gain."""

    verdict: str
    causes: list[str]
    nominal: str
    extended: str | None
    gain: dict[str, Any]
    change: dict | None
    report: Path
    details: dict[str, Any]

    def to_frame(self) -> pd.DataFrame:
        """The screening's ranking of the library's effects, best first."""
        return pd.DataFrame(self.details.get("ranking", []))


def diagnose(
    record: Record | None = None,
    nominal: str = "linear",
    *,
    mass: float | None = 1.0,
    out_dir: str | Path | None = None,
    overrides: Iterable[str] = (),
    progress: bool = True,
    **options: Any,
) -> Diagnosis:
    """Diagnose what ``nominal`` (a system name) misses on ``record`` (default: the configured
    record with a hidden effect). ``mass``: the known mass (None identifies it, force excitation
    only). ``options`` and ``progress`` as for ``identify`` (``diagnosis__fit_share=0.6``)."""
    from pidyn.tasks.diagnose import (
        diagnose as run_diagnosis,  # lazy: torch and Lightning load (seconds) on the first call that needs them
    )

    groups, values = _split_options(options)
    if record is not None:
        values["data.mass"] = mass
    values.setdefault("trainer.enable_progress_bar", False)
    values.setdefault("raise_errors", True)
    run_dir = _run_dir(out_dir, "diagnose", nominal)
    cfg = compose(
        "diagnose",
        groups={"system": nominal, **groups},
        values=values,
        overrides=overrides,
        output_dir=run_dir,
    )
    with _user_errors(), _progress(progress):
        d = run_diagnosis(cfg, record=record)
    return Diagnosis(
        verdict=d["verdict"],
        causes=list(d["causes"]),
        nominal=d["nominal"],
        extended=d["extended"],
        gain=d["gain"],
        change=d["change"],
        report=run_dir / "report.md",
        details=d,
    )


def system_names() -> list[str]:
    """The system names ``identify`` and ``diagnose`` accept."""
    return group_options("system")
