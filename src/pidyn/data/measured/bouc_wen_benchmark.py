"""The Bouc-Wen hysteretic benchmark (Noel and Schoukens 2016): force in (N), displacement out (m).

Simulated by the benchmark's authors, not measured (see ``bouc_wen_benchmark/PROVENANCE.md``);
fs = 750 Hz. The training record is five periods of one multisine from rest, so the first
period holds the start-up transient and the structure starts at rest. The diagnosis fits on
the first ``fit_periods`` and holds out the rest; the benchmark's own test signals
(``val_multisine``, ``val_sinesweep``) are other inputs, for the benchmark's figure of merit.
Only ratios of the model's coefficients are identifiable from u -> x, so the mass is
identified with the others (``data.mass: null``).
"""

from __future__ import annotations

from importlib import resources

import numpy as np
import pandas as pd

from pidyn.data.meta import RecordMeta, Split
from pidyn.data.sources import DataError, Record

FS = 750.0
PERIOD = 8192  # samples per multisine period
FILES = {
    "train": "train_multisine_5periods.csv.gz",
    "val_multisine": "val_multisine.csv.gz",
    "val_sinesweep": "val_sinesweep.csv.gz",
}
SOURCE = "Bouc-Wen hysteretic benchmark (Noel & Schoukens 2016)"


def _read(name: str) -> tuple[np.ndarray, np.ndarray]:
    if name not in FILES:
        raise DataError(f"bouc_wen_benchmark: unknown signal '{name}'; choose one of {', '.join(FILES)}")
    ref = resources.files("pidyn.data.measured").joinpath(f"bouc_wen_benchmark/{FILES[name]}")
    with resources.as_file(ref) as path:
        try:
            df = pd.read_csv(path)
        except Exception as exc:  # pandas raises several types for damaged files
            raise DataError(f"{path}: cannot be read as CSV ({exc})") from None
        missing = {"u_N", "y_m"} - set(df.columns)
        if missing:
            raise DataError(f"{path}: missing column(s) {sorted(missing)}; found {list(df.columns)}")
        u, y = df["u_N"].to_numpy(float), df["y_m"].to_numpy(float)
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise DataError(f"{path}: non-finite values in u_N or y_m")
    return u, y


def _record(name: str, u: np.ndarray, y: np.ndarray, split: Split | None) -> Record:
    t = np.arange(len(u)) / FS
    return Record(
        name=name,
        t=t,
        f=u,
        x=y,
        excitation="force",
        meta=RecordMeta(
            dt=1 / FS,
            fs=FS,
            units={"x": "m", "u": "N"},
            source=SOURCE,
            # the benchmark's own equations simulated from its sampled input follow its output
            # 7x closer on val_multisine with the input read band-limited between samples than
            # linearly (9.8e-7 m against 7.3e-6 m): its data come from a band-limited input
            input_hold="bandlimited",
            split=split,
        ),
    )


def load_bouc_wen_benchmark(fit_periods: int = 3, periods: int = 5) -> Record:
    """The training multisine from rest: ``periods`` periods (1-5), of which the first
    ``fit_periods`` are fitted and the rest held out (``meta.split``)."""
    if not 1 <= fit_periods < periods <= 5:
        raise DataError(
            f"bouc_wen_benchmark: need 1 <= fit_periods < periods <= 5, got {fit_periods}, {periods}"
        )
    u, y = _read("train")
    n = periods * PERIOD
    fit_end = (fit_periods * PERIOD - 1) / FS
    return _record(
        "bouc_wen_benchmark",
        u[:n],
        y[:n],
        Split((0.0, fit_end), (fit_periods * PERIOD / FS, (n - 1) / FS)),
    )


def load_bouc_wen_validation(name: str) -> Record:
    """One of the benchmark's test signals, ``val_multisine`` or ``val_sinesweep``, from rest."""
    if name == "train":
        raise DataError("bouc_wen_benchmark: 'train' is not a test signal; use load_bouc_wen_benchmark()")
    u, y = _read(name)
    return _record(f"bouc_wen_benchmark_{name}", u, y, None)
