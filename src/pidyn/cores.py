"""How many threads one pidyn process may use for work that splits (a compiled integration's
trajectories), and how many cores it may run on."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

#: how many processes share this one's threads now (``shared_by``)
_SHARE = 1


def threads() -> int:
    """``PIDYN_THREADS`` where it is set, else the cores this process may run on, at most
    ``OMP_NUM_THREADS`` where that is set (a test worker, or one of several jobs sharing the
    cores, says so by it); divided among the processes it forked to share them (``shared_by``)."""
    return max(1, _threads() // _SHARE)


def _threads() -> int:
    for name in ("PIDYN_THREADS", "OMP_NUM_THREADS"):
        value = os.environ.get(name, "").strip()
        if value.isdigit() and int(value) > 0:
            return min(int(value), cores()) if name == "OMP_NUM_THREADS" else int(value)
    return cores()


@contextlib.contextmanager
def shared_by(n: int) -> Iterator[None]:
    """Within the block this process and the ``n - 1`` it forks (which inherit the setting) share
    its threads: each splits its own work over its part of them, not over all (two processes of two
    threads each on two cores would spend their time waiting for one another)."""
    global _SHARE
    before = _SHARE
    _SHARE = before * max(1, int(n))
    try:
        yield
    finally:
        _SHARE = before


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity call on this platform
        return os.cpu_count() or 1


def share_cores(jobs: int) -> None:
    """``jobs`` processes about to run side by side (a study's jobs, started from here): each may
    split its work over its share of the cores, not over all of them (``PIDYN_THREADS``, which
    they inherit; a value the user set is kept)."""
    if jobs > 1:
        os.environ.setdefault("PIDYN_THREADS", str(max(1, cores() // jobs)))
