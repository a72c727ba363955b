"""A run folder that tells the truth: one run at a time holds it (a lock), a resumed run must be the
same run (its whole configuration), a finished run says so last (``complete.json``), and a run that
fails or is interrupted leaves ``failed.json`` with the reason and no file that claims success.

Readers (``skip_done``, resume, the aggregators) trust ``complete.json`` alone: a ``metrics.json``
without it is a run that did not finish.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import logging
import os
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from pidyn.reporting import write_json, write_text_atomic

log = logging.getLogger(__name__)

COMPLETE = "complete.json"
FAILED = "failed.json"
LOCK = "run.lock"
CONFIG = "run_config.json"

#: settings that change how a run is watched or how far it goes, not what it computes so far: a
#: resumed run may differ in these (``max_windows`` continues a run with more windows)
VOLATILE = (
    "hydra",
    "paths",
    "resume",
    "skip_done",
    "raise_errors",
    "num_threads",
    "workers",
    "figures",
    "trainer.enable_progress_bar",
    "model.schedule.max_windows",
    "model.schedule.windows_per_record",
    "logger",
)


class RunFolderBusy(ValueError):
    """Another live run holds the folder."""


class RunInterrupted(KeyboardInterrupt):
    """SIGTERM (or SIGINT) ended the run; the folder can be resumed."""


def is_complete(folder: str | Path) -> bool:
    """Whether ``folder`` holds a run that finished (its last step wrote ``complete.json``)."""
    return (Path(folder) / COMPLETE).is_file()


def comparable_config(cfg: DictConfig) -> dict[str, Any]:
    """The configuration that decides what a run computes: everything but ``VOLATILE``; in JSON's
    terms, as the folder keeps it (a mapping's integer keys, a deck layout's channel positions,
    are strings there, and the same run must compare equal to itself)."""
    data = json.loads(json.dumps(OmegaConf.to_container(cfg, resolve=False), default=str))
    assert isinstance(data, dict)
    for key in VOLATILE:
        node: Any = data
        *parents, last = key.split(".")
        for p in parents:
            node = node.get(p) if isinstance(node, dict) else None
        if isinstance(node, dict):
            node.pop(last, None)
    return data


def config_differences(saved: Any, now: Any, prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two configurations, ``key: saved -> now``. An empty
    mapping and null say the same (no terms, no overrides): a default written either way is one run."""
    if saved in ({}, None) and now in ({}, None):
        return []
    if isinstance(saved, dict) and isinstance(now, dict):
        out: list[str] = []
        for k in sorted(set(saved) | set(now), key=str):
            key = f"{prefix}.{k}" if prefix else str(k)
            if k not in saved or k not in now:
                out.append(f"{key}: {saved.get(k, '(absent)')!r} -> {now.get(k, '(absent)')!r}")
            else:
                out += config_differences(saved[k], now[k], key)
        return out
    return [] if saved == now else [f"{prefix}: {saved!r} -> {now!r}"]


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _acquire(folder: Path) -> Path:
    """Create ``run.lock`` exclusively; a lock whose process on this host is gone is taken over."""
    lock = folder / LOCK
    me = {"pid": os.getpid(), "host": socket.gethostname(), "started": _now()}
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                held = json.loads(lock.read_text() or "{}")
            except (OSError, ValueError):
                held = {}
            same_host = held.get("host") == me["host"]
            if same_host and isinstance(held.get("pid"), int) and not _pid_alive(held["pid"]):
                log.warning("%s: taking over the lock of a run that is gone (pid %s)", folder, held["pid"])
                lock.unlink(missing_ok=True)
                continue
            raise RunFolderBusy(
                f"{folder}: another run (pid {held.get('pid', '?')} on {held.get('host', '?')}, started "
                f"{held.get('started', '?')}) holds this run folder ({LOCK}); wait for it to end, or use "
                "another hydra.run.dir"
            ) from None
        with os.fdopen(fd, "w") as fh:
            json.dump(me, fh)
        return lock
    raise RunFolderBusy(f"{folder}: cannot take the run lock ({LOCK})")


def _check_same_run(folder: Path, cfg: DictConfig, resume: bool) -> None:
    """A folder with another run's state or results is refused by name, unless ``resume=false``
    starts it afresh."""
    saved_path = folder / CONFIG
    worked = (
        (folder / COMPLETE).is_file()
        or (folder / "subperiod_state.json").is_file()
        or any(folder.glob("*/subperiod_state.json"))  # a diagnosis's identifications
    )
    if not saved_path.is_file() or not worked:  # a run refused before any work leaves nothing to resume
        return
    try:
        saved = json.loads(saved_path.read_text())
    except ValueError:
        return
    diff = config_differences(saved, comparable_config(cfg))
    if diff and resume:
        shown = "; ".join(diff[:6]) + (f"; and {len(diff) - 6} more" if len(diff) > 6 else "")
        raise ValueError(
            f"{folder} holds another run (its configuration differs: {shown}); use another "
            "hydra.run.dir, or resume=false to start this folder afresh"
        )


def _save_hydra_files(folder: Path, cfg: DictConfig) -> None:
    """``.hydra/config.yaml``, ``hydra.yaml`` and ``overrides.yaml``, as Hydra writes them, but only
    once this run holds the folder (``hydra.output_subdir: null``): a refused second run must not
    overwrite the first run's record of itself."""
    if not HydraConfig.initialized():
        return
    hydra_cfg = HydraConfig.get()
    out = folder / ".hydra"
    out.mkdir(exist_ok=True)
    task_cfg = OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"]) if "hydra" in cfg else cfg
    write_text_atomic(out / "config.yaml", OmegaConf.to_yaml(task_cfg))
    write_text_atomic(out / "hydra.yaml", OmegaConf.to_yaml({"hydra": hydra_cfg}))
    write_text_atomic(out / "overrides.yaml", OmegaConf.to_yaml(list(hydra_cfg.overrides.task)))


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


@contextlib.contextmanager
def _signals_interrupt(received: list[str]) -> Iterator[None]:
    """SIGTERM and SIGINT raise ``RunInterrupted`` in the main thread and are noted in ``received``:
    Lightning turns an interruption during training into ``SystemExit(1)``, and the note tells
    that exit from a failure."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):  # noqa: ARG001
        name = signal.Signals(signum).name
        received.append(name)
        raise RunInterrupted(name)

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


@contextlib.contextmanager
def run_folder(cfg: DictConfig, task: str, claims: tuple[str, ...]) -> Iterator[Path]:
    """Hold ``cfg.paths.output_dir`` for one run of ``task``.

    ``claims``: the files that say the run succeeded (``metrics.json``); they are removed when the
    run fails, so that nothing in the folder claims a result it does not have."""
    folder = Path(cfg.paths.output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    lock = _acquire(folder)
    try:
        _check_same_run(folder, cfg, bool(cfg.get("resume", True)))
        for name in (COMPLETE, FAILED):  # the folder is this run's now: no earlier verdict stands
            (folder / name).unlink(missing_ok=True)
        received: list[str] = []
        try:
            write_json(folder / CONFIG, comparable_config(cfg))
            _save_hydra_files(folder, cfg)
            with _signals_interrupt(received):
                yield folder
        except BaseException as exc:
            if received or isinstance(exc, KeyboardInterrupt):
                signame = received[0] if received else "SIGINT"
                _failed(folder, task, RunInterrupted(signame), claims)
                raise SystemExit(143 if signame == "SIGTERM" else 130) from None
            _failed(folder, task, exc, claims)
            raise
        write_json(folder / COMPLETE, {"task": task, "finished": _now(), "files": _listing(folder)})
    finally:
        lock.unlink(missing_ok=True)


def _failed(folder: Path, task: str, exc: BaseException, claims: tuple[str, ...]) -> None:
    interrupted = isinstance(exc, KeyboardInterrupt)
    reason = (
        f"interrupted at {_now()} ({exc or 'SIGINT'}); run the same command again to resume"
        if interrupted
        else str(exc)
    )
    if interrupted:
        log.error("%s %s", task, reason)
    for name in (*claims, COMPLETE):
        (folder / name).unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        write_json(
            folder / FAILED,
            {
                "task": task,
                "error": "Interrupted" if interrupted else type(exc).__name__,
                "message": reason,
                "when": _now(),
            },
        )


def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in (LOCK, COMPLETE))
