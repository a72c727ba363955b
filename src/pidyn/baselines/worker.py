"""The classical estimators of one run, in a worker process beside PIDynNet.

The worker is a fresh interpreter running this module (``python -m pidyn.baselines.worker``),
fed its arguments by pickle through a file. It never imports the caller's ``__main__``:
multiprocessing's ``spawn`` (and ``forkserver``) re-run the main script in the child, so a
user's plain script that calls ``pidyn.identify(...)`` at top level, without a
``__main__`` guard, identified its record a second time in the worker and printed its result
twice. ``fork`` is no answer either: it copies torch's thread pools mid-flight.
"""

from __future__ import annotations

import logging
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from pidyn.baselines.registry import ESTIMATORS, PARAMETRIC, check_names
from pidyn.cores import cores
from pidyn.errors import errors_pct
from pidyn.parallel import set_workers


def baseline_rows(
    bcfg: dict, noise: float, system: Any, record: Any, fit: tuple[float, float] | None = None
) -> list[dict]:
    """The configured classical methods on one record (``bcfg``: the ``baselines`` config as a
    plain dict); a method that fails gives a row saying so. Pure, so it runs in a worker.
    ``fit``: the span the parametric methods see (a held-out part stays unseen; the modal peers
    fit the record's own fitting part and predict the rest)."""
    out: list[dict] = []
    truth = record.truth or {}
    names = list(bcfg.get("run") or [])
    check_names("baselines.run", names)
    fitted = record if fit is None else record.segment(*fit)
    for name in names:
        try:
            row = ESTIMATORS[name](
                fitted if name in PARAMETRIC else record, system, dict(bcfg.get(name) or {}), noise
            )
        except Exception as exc:  # a failed baseline must not spoil the run
            row = {"method": name, "params": {}, "seconds": 0.0, "note": f"failed: {exc}"}
        if truth and row["params"]:
            row["error_pct"] = errors_pct(row["params"], {n: truth.get(n) for n in row["params"]})
        out.append(row)
    return out


class BaselineJob:
    """The baselines of one run, started before PIDynNet.

    With ``parallel`` (and a second core) they run in a worker process while PIDynNet trains:
    on two cores the default run's wall time is PIDynNet's, not PIDynNet's plus the
    baselines'. Otherwise, or when the worker cannot start or dies, they run in this process
    when asked for."""

    def __init__(
        self,
        bcfg: dict,
        noise: float,
        system: Any,
        record: Any,
        fit: tuple[float, float] | None = None,
        parallel: bool = False,
        workers: int = 1,
    ) -> None:
        self._args = (bcfg, noise, system, record, fit)
        self._workers = int(workers)
        self._proc: subprocess.Popen | None = None
        self._rows: list[dict] | None = None
        self._dir: tempfile.TemporaryDirectory | None = None
        names = list(bcfg.get("run") or [])
        check_names("baselines.run", names)  # a typo fails now, not after PIDynNet's minutes
        if names and parallel and cores() > 1:
            try:
                self._start()
            except Exception as exc:  # no worker here: run them in this process afterwards
                import logging

                logging.getLogger(__name__).info("baselines run after PIDynNet (no worker process: %s)", exc)
                self._close()

    def _start(self) -> None:
        self._dir = tempfile.TemporaryDirectory(prefix="pidyn-baselines-")
        folder = Path(self._dir.name)
        with open(folder / "args.pkl", "wb") as f:
            pickle.dump(self._args, f, protocol=pickle.HIGHEST_PROTOCOL)
        self._stderr = open(folder / "stderr.txt", "wb")
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "pidyn.baselines.worker", str(folder)],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=self._stderr,
            # PIDynNet has the other core; where the run waits for these rows, the worker may fork
            env={**os.environ, "PIDYN_THREADS": "1", "PIDYN_WORKERS": str(self._workers)},
        )

    def result(self) -> list[dict]:
        """The baselines' rows (the worker's, or run here); asked again, the same rows."""
        if self._rows is None:
            self._rows = self._result()
        return self._rows

    def _result(self) -> list[dict]:
        if self._proc is not None:
            try:
                self._proc.wait()
                folder = Path(self._dir.name)
                if not (folder / "result.pkl").exists():
                    tail = (folder / "stderr.txt").read_text(errors="replace")[-400:]
                    raise RuntimeError(f"worker exited with code {self._proc.returncode}: {tail.strip()}")
                with open(folder / "result.pkl", "rb") as f:
                    ok, value = pickle.load(f)
                if ok:
                    return value
                raise RuntimeError(value)
            except Exception as exc:
                logging.getLogger(__name__).warning(
                    "baseline worker failed (%s); running the baselines in this process", exc
                )
            finally:
                self.cancel()
        return baseline_rows(*self._args)

    def cancel(self) -> None:
        """Stop the worker (PIDynNet failed or the run was interrupted)."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(5)
            except subprocess.TimeoutExpired:
                self._proc.kill()
        self._close()

    def _close(self) -> None:
        self._proc = None
        if getattr(self, "_stderr", None) is not None:
            self._stderr.close()
            self._stderr = None
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None

    def __del__(self) -> None:
        try:
            self.cancel()
        except Exception:
            pass


def main(folder: str) -> None:
    """Worker entry: read the arguments, run the estimators, write (ok, rows or message)."""
    path = Path(folder)
    set_workers(int(os.environ.get("PIDYN_WORKERS", "1")))
    with open(path / "args.pkl", "rb") as f:
        args = pickle.load(f)
    try:
        out: tuple[bool, Any] = (True, baseline_rows(*args))
    except Exception as exc:
        out = (False, f"{type(exc).__name__}: {exc}")
    tmp = path / "result.pkl.part"
    with open(tmp, "wb") as f:
        pickle.dump(out, f, protocol=pickle.HIGHEST_PROTOCOL)
    tmp.replace(path / "result.pkl")  # whole or absent: a killed worker leaves no half result


if __name__ == "__main__":
    main(sys.argv[1])
