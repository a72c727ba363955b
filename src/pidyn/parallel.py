"""Independent pieces of one computation on the machine's other cores.

A period scan and a period profile fit a few dozen points that do not depend on one another, each
a few tens of milliseconds of simulation; a UKF tries a grid of process noises; a run draws half
a dozen figures. Meanwhile the second core of a two-core machine waits. ``map_ordered`` forks
children that inherit the whole process (the problem, its compiled kernels: nothing is pickled but
the results) and compute an interleaved share each, while the parent computes its own. Every point
is computed exactly as one process computes it, so the results are the same bits whatever the
number of workers. (Work that already splits over the cores, a long output-error fit whose
compiled integration runs in threads, gains nothing from it.)

The number of workers is a process-wide setting, like torch's threads (``set_workers``; the
config's ``workers``, by default this process's share of the cores). Forking is used on Linux
only; elsewhere, and where a child fails, the points are computed here, one after the other.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pickle
import signal
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import TypeVar

from pidyn.cores import shared_by, threads

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")

_WORKERS = 1


def set_workers(n: int | None) -> int:
    """Processes that independent points may use (None or 0: this process's share of the cores,
    ``pidyn.cores.threads``, which a study running several jobs lowers); returns the number set."""
    global _WORKERS
    _WORKERS = max(1, int(n) if n else threads())
    return _WORKERS


def workers() -> int:
    return _WORKERS


def _can_fork() -> bool:
    return sys.platform.startswith("linux") and hasattr(os, "fork")


def map_ordered(fn: Callable[[T], R], items: Sequence[T], n: int | None = None) -> list[R]:
    """``[fn(x) for x in items]``, shared among ``n`` processes (default ``workers()``): item i
    goes to process i mod n, the parent taking its share. ``fn`` must not change state that the
    rest of the computation reads (a child's changes are lost), and its results must pickle."""
    n = min(n or _WORKERS, len(items))
    if n <= 1 or not _can_fork():
        return [fn(x) for x in items]
    out: list = [None] * len(items)
    children: list[tuple[int, int]] = []
    try:
        with shared_by(n):  # each process's compiled integrations split over its part of the threads
            children = [_fork_share(fn, items, w, n) for w in range(1, n)]
            for i in range(0, len(items), n):
                out[i] = fn(items[i])
        while children:
            w = n - len(children)  # the first child left took items w, w + n, ...
            share = _collect(*children[0])
            children.pop(0)
            if share is None:  # the child failed: its points are computed here
                log.debug("a worker failed: its points are computed in this process")
                share = [(i, fn(items[i])) for i in range(w, len(items), n)]
            for i, value in share:
                out[i] = value
    except BaseException:  # an error of the points, or an interruption: no child left behind
        for pid, fd in children:
            _stop(pid, fd)
        raise
    return out


def _fork_share(fn: Callable, items: Sequence, w: int, n: int) -> tuple[int, int]:
    """A child computing items w, w + n, ...; returns its pid and the pipe's read end."""
    r, wfd = os.pipe()
    sys.stdout.flush()
    sys.stderr.flush()
    with warnings.catch_warnings():  # Python >= 3.12 warns on fork with threads; the child starts none
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # the child: compute, send, leave without running the parent's exit handlers
        global _WORKERS
        _WORKERS, code = 1, 0  # a point that shares its own work does so in this process
        try:
            os.close(r)
            data = pickle.dumps(("ok", [(i, fn(items[i])) for i in range(w, len(items), n)]))
        except BaseException as exc:  # noqa: BLE001  (reported to the parent, which recomputes)
            data, code = pickle.dumps(("error", repr(exc))), 1
        try:
            with os.fdopen(wfd, "wb") as fh:
                fh.write(data)
        finally:
            os._exit(code)
    os.close(wfd)
    return pid, r


def _stop(pid: int, fd: int) -> None:
    """A child whose results are no longer wanted: ended and reaped."""
    with contextlib.suppress(OSError):
        os.kill(pid, signal.SIGTERM)
    with contextlib.suppress(OSError):
        os.close(fd)
    with contextlib.suppress(OSError):
        os.waitpid(pid, 0)


def _collect(pid: int, fd: int) -> list | None:
    """The child's results (None where it failed)."""
    with os.fdopen(fd, "rb") as fh:
        data = fh.read()
    os.waitpid(pid, 0)
    try:
        status, payload = pickle.loads(data)
    except Exception:  # noqa: BLE001  (an empty or cut pipe: the child died)
        return None
    if status != "ok":
        log.debug("a worker raised %s", payload)
        return None
    return payload
