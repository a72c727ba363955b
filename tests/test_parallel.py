"""Independent points shared among forked processes: the same results, in order, as one process
computes them; a worker that fails costs time, not results."""

import os

import numpy as np
import pytest

from pidyn import parallel
from pidyn.refine.period_profile import profile_period
from pidyn.refine.period_scan import scan_period
from pidyn.systems import LinearSDOF
from tests.test_period_scan import _two_modes

fork = pytest.mark.skipif(not parallel._can_fork(), reason="workers are forked on Linux only")


@fork
def test_the_points_come_back_in_order_from_every_worker():
    parent = os.getpid()
    out = parallel.map_ordered(lambda i: (i * i, os.getpid() == parent), list(range(11)), n=3)
    assert [v for v, _ in out] == [i * i for i in range(11)]
    assert [here for _, here in out] == [i % 3 == 0 for i in range(11)]  # the parent took every third
    assert parallel.map_ordered(lambda i: i, [], n=2) == []


@fork
def test_a_worker_that_fails_has_its_points_computed_here():
    parent = os.getpid()

    def fn(i):
        if os.getpid() != parent:
            raise RuntimeError("a worker's fault")
        return i + 1

    assert parallel.map_ordered(fn, list(range(5)), n=2) == [1, 2, 3, 4, 5]
    with pytest.raises(ZeroDivisionError):  # an error of the points themselves is the caller's
        parallel.map_ordered(lambda i: 1 / (i - 2), list(range(5)), n=2)


def test_the_setting():
    before = parallel.workers()
    try:
        assert parallel.set_workers(3) == 3 and parallel.workers() == 3
        assert parallel.set_workers(None) >= 1
    finally:
        parallel.set_workers(before)


@fork
def test_the_period_scan_and_profile_are_the_same_bits_with_two_workers():
    record = _two_modes(0.7)
    system = LinearSDOF()
    k = (2 * np.pi / 0.30) ** 2
    values = {"m": 1.0, "k": k, "c": 0.1 * np.sqrt(k)}
    before = parallel.workers()
    try:
        runs = []
        for n in (1, 2):
            parallel.set_workers(n)
            scan = scan_period(system, record, values)
            prof = profile_period(system, record, values)
            runs.append((scan.costs, scan.values, prof.statistic, prof.ci95))
    finally:
        parallel.set_workers(before)
    assert runs[0] == runs[1]
