"""The progress line of a log: the window as k of n, the iteration as k of n, the time left."""

from __future__ import annotations

from types import SimpleNamespace

from pidyn.callbacks.progress import LineProgress


def _module(done: int, budget: int = 1500, n: int | None = 5):
    params = SimpleNamespace(as_floats=lambda: {"c": 0.5, "k1": 15.0})
    return SimpleNamespace(
        window=SimpleNamespace(index=1),
        n_windows=n,
        phase="identify",
        window_iteration=done,
        budget=budget,
        last_losses={"physics/motion": 0.012},
        net=SimpleNamespace(params=params),
    )


def test_the_line_says_where_the_run_is_and_how_long_the_fit_has_left():
    cb = LineProgress(every_s=1.0)
    cb._start, cb._first = 100.0, 0
    line = cb.line(_module(400), now=140.0)  # 400 iterations in 40 s: 1100 more take 110 s
    assert line.startswith(
        "window 2/5 identify: iteration 400/1500 (~1 min 50 s left), loss physics/motion 0.012"
    )
    assert line.endswith("c=0.5, k1=15")
    assert "s left" not in cb.line(_module(0), now=140.0)  # no pace before the first iteration
    assert cb.line(_module(400, n=None), now=140.0).startswith("window 1 identify")
    assert "(~4 s left)" in cb.line(_module(1400), now=150.0)  # 1400 in 50 s: 100 more in 3.6 s
