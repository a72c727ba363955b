"""The budget of a subperiod identification (iterations, windows, pretraining) and what each
window leaves behind (its estimates, losses, clamp box and notes)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

#: the iteration counts a schedule sets
ITERATIONS = ("pretrain_iters", "pretrain_iters_window", "max_iters")


@dataclass
class Schedule:
    """How much work each window gets and how windows hand over to each other."""

    pretrain_iters: int = 1000  # supervised-only iterations before the first window
    pretrain_iters_window: int = 1000  # the same before every later window (its local time is new)
    max_iters: int = 1500  # physics + data iterations per window
    ls_init: str = "first"  # least-squares init of linear parameters: none | first | every
    skip_uninformative: bool = True  # skip windows below data.min_peak_fraction of the peak response
    fusion: str = "information"  # information | last (paper: carry the last window's values)
    max_windows: int | None = None
    # at most this many windows per record of the run as well (several records: their number
    # times it), so that one record's budget can be small while several records' windows still
    # come from every record
    windows_per_record: int | None = None
    transfer_lnn: bool = True  # LNN <- RPN after pretraining (paper's transfer-learning init)
    latent_init: bool = (
        False  # with ls_init: start latent shape parameters (beta, gamma, n) by variable projection
    )
    # the iterations of a run from several records where they differ from one record's
    # (pretrain_iters, pretrain_iters_window, max_iters); None: the same
    several_records: dict[str, int] | None = None
    # stop PIDynNet after a window where a peer's estimate (the data's start, a classical method's)
    # simulates the fitting part from rest with a cost this many times lower than PIDynNet's estimate
    # so far: the refinement starts from the estimate that simulates best, which PIDynNet's later
    # windows would have to lower their cost that many times to be. None: every window is trained
    stop_behind: float | None = None

    def __post_init__(self) -> None:
        """A misspelled option fails here, naming the valid ones, instead of silently changing behaviour."""
        for name, allowed in (("ls_init", ("none", "first", "every")), ("fusion", ("information", "last"))):
            value = getattr(self, name)
            if value not in allowed:
                raise ValueError(f"model.schedule.{name}: '{value}' is not one of {', '.join(allowed)}")
        for name in ITERATIONS:
            if int(getattr(self, name)) < 0:
                raise ValueError(f"model.schedule.{name} must be >= 0, got {getattr(self, name)}")
        unknown = set(self.several_records or {}) - set(ITERATIONS)
        if unknown:
            raise ValueError(
                f"model.schedule.several_records: {sorted(unknown)} not among {', '.join(ITERATIONS)}"
            )
        if self.stop_behind is not None and not float(self.stop_behind) >= 1.0:
            raise ValueError(f"model.schedule.stop_behind must be >= 1 or null, got {self.stop_behind}")
        for name in ("max_windows", "windows_per_record"):
            value = getattr(self, name)
            if value is not None and int(value) < 1:
                raise ValueError(f"model.schedule.{name} must be >= 1 or null, got {value}")

    def for_records(self, n_records: int) -> Schedule:
        """The schedule of a run from ``n_records`` records: ``several_records``'s iterations where
        there are several."""
        if n_records <= 1 or not self.several_records:
            return self
        return replace(self, **{k: int(v) for k, v in self.several_records.items()})

    def window_limit(self, n_records: int) -> int | None:
        """How many windows a run of ``n_records`` records may train (None: every one)."""
        per = None if self.windows_per_record is None else int(self.windows_per_record) * max(n_records, 1)
        limits = [int(v) for v in (self.max_windows, per) if v is not None]
        return min(limits) if limits else None


@dataclass
class WindowResult:
    index: int
    t0: float
    t1: float
    iterations: int
    seconds: float
    estimate: dict[str, float]
    fused: dict[str, float]
    losses: dict[str, float]
    stopped_early: bool
    clamp_bounds: dict[str, list[float]] = field(default_factory=dict)
    z_end: list[float] | None = None  # latent state at the window's end (the next window starts from it)
    states: list[list[float]] | None = (
        None  # [t, x, x', z] from the networks every 10th sample (refinement starts)
    )
    notes: list[str] = field(default_factory=list)  # what the data decided that a user should know


def network_states(results: list[WindowResult]) -> np.ndarray | None:
    """All windows' network states, (K, 1 + n_state) rows [t, x, x', z], in time order; a
    later window's value wins where two windows share a time (its networks start there)."""
    rows: dict[float, list[float]] = {}
    for r in results:
        for row in r.states or []:
            rows[round(row[0], 9)] = row
    return np.array([rows[k] for k in sorted(rows)]) if rows else None
