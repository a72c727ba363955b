"""Console entry points ``pidyn-train``, ``pidyn-diagnose``, ``pidyn-generalize``, ``pidyn-predict``.

The configs ship inside the package (``pidyn/conf``, Hydra's ``pkg://pidyn.conf``), so the
commands work from any directory and from an installed wheel; ``train.py``, ``diagnose.py``,
``generalize.py`` and ``predict.py`` at the repository root are shims to these functions.
"""

from __future__ import annotations

import atexit
import logging
import os
import sys
import threading
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.types import RunMode
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from pidyn import blas_threads  # noqa: F401  (before NumPy loads its BLAS: see the module)
from pidyn.config import CONF_DIR as _CONF_PATH
from pidyn.config import check_settings
from pidyn.cores import cores, share_cores
from pidyn.reporting import write_json
from pidyn.runs.folder import FAILED, RunFolderBusy

#: the package's config directory, for ``hydra.initialize_config_dir``
CONF_DIR = str(_CONF_PATH)
log = logging.getLogger("pidyn")


#: set once a task starts: a Hydra exit before it is a configuration error (a misspelled key or option)
_STARTED = False


def _user_error(exc: BaseException) -> BaseException | None:
    """The user's error behind ``exc`` (a bad file, a bad value, a misspelled setting), or None for
    a fault of the program. Hydra and OmegaConf wrap such errors in their own types."""
    if isinstance(exc, (ValueError, FileNotFoundError, RuntimeError)):
        return exc
    if isinstance(exc, (HydraException, OmegaConfBaseException)):
        cause = exc.__cause__ or exc.__context__
        return _user_error(cause) if isinstance(cause, BaseException) and _user_error(cause) else exc
    return None


def _guarded(task, cfg: DictConfig) -> dict:
    """Run a task; user errors (bad files, bad values, settings Hydra or OmegaConf refuse) end with
    one clear line and exit 2. In a multirun the job's run folder keeps the reason in
    ``failed.json`` (``pidyn.runs.folder``) and the sweep goes on with the other jobs (a missing
    channel in one event must not stop the rest). An interruption is logged as such."""
    global _STARTED
    _STARTED = True
    try:
        _share_cores_with_sweep()
        return task(cfg)
    except KeyboardInterrupt:
        log.error("interrupted; run the same command again to resume")
        sys.exit(130)
    except Exception as exc:
        err = _user_error(exc)
        if err is None:
            raise
        log.error("%s: %s", type(err).__name__, str(err).splitlines()[0] if str(err) else "")
        if cfg.get("raise_errors", False):
            raise
        if _in_multirun():
            _write_failure(cfg, err)
            return {}
        sys.exit(2)


def _config_errors_exit_2(main, leave: bool = True) -> None:
    """Hydra ends a run whose settings it cannot compose with exit status 1, as for a crash; such a
    run never reached its task, so it is the user's error: exit status 2, as every other.
    ``leave``: a run that ended well ends the process at once (``_leave``)."""
    try:
        main()
    except SystemExit as exc:
        if exc.code == 1 and not _STARTED:
            raise SystemExit(2) from None
        raise
    if leave:
        _leave()


def _leave() -> None:
    """End the process now that everything is written: threads joined, exit handlers run (logging's
    flush among them), the streams flushed, and then no interpreter teardown. Tearing down torch,
    Lightning, Hydra and matplotlib module by module took 1.2 s of a 20 s identification and
    writes nothing. Under a profiler or a debugger (``python -m cProfile train.py``, which writes
    its statistics once main returns), the usual exit."""
    shutdown = getattr(threading, "_shutdown", None)  # what the interpreter runs first at exit
    run_exitfuncs = getattr(atexit, "_run_exitfuncs", None)
    if shutdown is None or run_exitfuncs is None:  # another Python: the usual exit
        return
    if sys.getprofile() is not None or sys.gettrace() is not None:  # a profiler writes after main
        return
    shutdown()
    run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken stream has nothing left to write
            pass
    os._exit(0)


def _in_multirun() -> bool:

    try:
        return HydraConfig.get().mode == RunMode.MULTIRUN
    except ValueError:
        return False


def _share_cores_with_sweep() -> None:
    """A job of a multirun whose launcher runs several at once (joblib's ``n_jobs``) splits its work
    over its share of the cores only: its compiled integrations' threads and its workers
    (``pidyn.cores.share_cores``; a ``PIDYN_THREADS`` the user set is kept)."""
    if not _in_multirun():
        return
    n_jobs = HydraConfig.get().launcher.get("n_jobs")
    if isinstance(n_jobs, int) and n_jobs != 1:
        share_cores(cores() if n_jobs < 0 else n_jobs)  # joblib's -1: every core


def _write_failure(cfg: DictConfig, exc: BaseException) -> None:
    """The reason, where the run folder's own record (``pidyn.runs.folder``) did not write one: a
    folder another run holds is not touched."""
    folder = Path(cfg.paths.output_dir)
    if isinstance(exc, RunFolderBusy) or (folder / FAILED).exists():
        return
    folder.mkdir(parents=True, exist_ok=True)
    write_json(folder / FAILED, {"error": type(exc).__name__, "message": str(exc)})


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def _train(cfg: DictConfig) -> float | None:
    metrics = _guarded(_checked_train, cfg) or {}
    value = metrics.get(cfg.get("optimized_metric", "max_error_pct"))
    return float(value) if value is not None else None


def _checked_train(cfg: DictConfig) -> dict:
    """The settings refused before the task is imported: a bad value is named in a second or
    two, not after the seconds Lightning and its kin take to import."""
    check_settings(cfg)
    from pidyn.tasks.train import train  # imported once the settings hold (see above)

    return train(cfg)


@hydra.main(version_base="1.3", config_path="conf", config_name="generalize")
def _generalize(cfg: DictConfig) -> float | None:
    from pidyn.tasks.generalize import generalize  # imported once the settings hold

    summary = _guarded(generalize, cfg)
    return summary.get("share_gamma_ge_0.95_pidynnet")


@hydra.main(version_base="1.3", config_path="conf", config_name="diagnose")
def _diagnose(cfg: DictConfig) -> float | None:
    from pidyn.tasks.diagnose import diagnose  # imported once the settings hold

    result = _guarded(diagnose, cfg)
    if not result:
        return None
    return result["gain"]["extended"] if result["gain"]["extended"] is not None else result["gain"]["nominal"]


@hydra.main(version_base="1.3", config_path="conf", config_name="predict")
def _predict(cfg: DictConfig) -> float | None:
    from pidyn.tasks.predict import predict  # imported once the settings hold

    out = _guarded(predict, cfg) or {}
    return out.get("mean_nrmse_a")


def train_main(leave: bool = True) -> None:
    """``pidyn-train`` / ``python train.py``; ``leave=False`` for a caller that goes on after it."""
    _config_errors_exit_2(_train, leave)


def diagnose_main(leave: bool = True) -> None:
    """``pidyn-diagnose`` / ``python diagnose.py``; ``leave=False`` for a caller that goes on after it."""
    _config_errors_exit_2(_diagnose, leave)


def generalize_main(leave: bool = True) -> None:
    """``pidyn-generalize`` / ``python generalize.py``; ``leave=False`` for a caller that goes on after it."""
    _config_errors_exit_2(_generalize, leave)


def predict_main(leave: bool = True) -> None:
    """``pidyn-predict`` / ``python predict.py``; ``leave=False`` for a caller that goes on after it."""
    _config_errors_exit_2(_predict, leave)
