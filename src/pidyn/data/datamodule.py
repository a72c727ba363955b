"""DataModule: serves the current subperiod's collocation batches.

The record (measured channels and excitation) comes from a data source (synthetic
simulation or a measured file); this module cuts it into windows and, for the window in
training, yields batches of ``inner_steps`` collocation draws of ``batch_size`` points
from the window's pool. Draws come from a generator seeded by ``data_seed`` and the
window index, so a resumed run sees the same points.
"""

from __future__ import annotations

from collections.abc import Iterator

import lightning as L
import torch
from torch.utils.data import DataLoader, IterableDataset

from pidyn.data.sources import Record
from pidyn.data.windows import Window, make_windows


class _CollocationStream(IterableDataset):
    def __init__(
        self, window: Window, batch_size: int, inner_steps: int, n_batches: int, seed: int, physics: bool
    ) -> None:
        self.window, self.batch_size, self.inner_steps = window, batch_size, inner_steps
        self.n_batches, self.seed, self.physics = n_batches, seed, physics

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        g = torch.Generator().manual_seed(self.seed)
        pool = self.window.t_pool.numel()
        b = min(self.batch_size, pool)
        for _ in range(self.n_batches):
            if not self.physics:
                yield {}
                continue
            idx = torch.stack([torch.randperm(pool, generator=g)[:b] for _ in range(self.inner_steps)])
            batch = {"t": self.window.t_pool[idx], "f": self.window.f_pool[idx]}
            if self.window.q_pool is not None:
                batch["q"], batch["qd"] = self.window.q_pool[idx], self.window.qd_pool[idx]
            yield batch

    def __len__(self) -> int:
        return self.n_batches


class SubperiodDataModule(L.LightningDataModule):
    """Windows of a record plus the collocation stream of the active window.

    ``accel_signal`` (the excitation as an acceleration, see
    ``StructuralSystem.excitation_as_acceleration``) switches on the excitation transform;
    None leaves the networks representing x itself.
    """

    def __init__(
        self,
        record: Record,
        window_length: float = 3.0,
        pool_size: int = 1000,
        batch_size: int = 500,
        min_peak_fraction: float = 0.2,
        t_start: float | None = None,
        t_end: float | None = None,
        data_seed: int = 0,
        accel_signal=None,
        cover_tail: bool = False,
    ) -> None:
        super().__init__()
        if batch_size > pool_size:
            raise ValueError(f"batch_size={batch_size} exceeds the collocation pool_size={pool_size}")
        self.record = record
        self.window_length, self.pool_size, self.batch_size = window_length, pool_size, batch_size
        self.data_seed = data_seed
        self.windows = make_windows(
            record.t,
            record.f,
            record.x,
            record.v,
            record.a,
            window_length,
            pool_size,
            min_peak_fraction,
            t_start,
            t_end,
            accel_signal=accel_signal,
            cover_tail=cover_tail,
            pieces=_piece_spans(record),
        )
        self.active: Window = self.windows[0]
        self.inner_steps, self.n_batches, self.physics = 10, 1, True

    def activate(self, index: int, n_iterations: int, inner_steps: int, physics: bool) -> None:
        self.active = self.windows[index]
        self.inner_steps = inner_steps
        self.n_batches = max(1, -(-n_iterations // inner_steps))
        self.physics = physics

    def train_dataloader(self) -> DataLoader:
        seed = 1_000_003 * self.data_seed + 7919 * self.active.index + int(self.physics)
        ds = _CollocationStream(
            self.active, self.batch_size, self.inner_steps, self.n_batches, seed, self.physics
        )
        return DataLoader(ds, batch_size=None, num_workers=0)


def _piece_spans(record: Record) -> list[tuple[float, float]] | None:
    """The time spans of the records a record is made of (``pidyn.data.multi``); None for one."""
    parts = record.meta.pieces
    if not parts:
        return None
    return [(float(record.t[p.i0]), float(record.t[p.i1 - 1])) for p in parts]
