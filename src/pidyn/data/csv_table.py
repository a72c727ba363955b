"""A CSV record's table checked column by column: the columns it may hold, numbers only and
finite, a uniform increasing time, one excitation, the floors' arrays (``sources.from_csv`` reads
a record with these); every problem named with the file, the column and the row."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from pidyn.data.errors import DataError
from pidyn.excitation.ground_motion import load_record


def read_table(path: Path, units: dict[str, float] | None) -> pd.DataFrame:
    """The CSV with stripped column names, index columns dropped, ``units`` applied."""
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        df = pd.read_csv(path)
    except Exception as exc:  # pandas raises many types for malformed CSVs
        raise DataError(f"{path}: cannot be read as CSV ({exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    df = df.loc[:, [c for c in df.columns if c and not c.startswith("Unnamed")]]
    check_numeric(path, df)
    for col, factor in (units or {}).items():
        if col not in df.columns:
            raise DataError(f"{path}: units given for '{col}', which is not a column ({list(df.columns)})")
        df[col] = df[col] * factor
    return df


def ground_from_at2(path: Path, df: pd.DataFrame, time_col: str, at2: str | Path) -> None:
    """Add column ``ag`` from a PEER AT2 record, interpolated at the CSV's times."""
    if "ag" in df.columns or "u" in df.columns:
        raise DataError(f"{path}: has an excitation column and an AT2 record ({at2}) was given too; use one")
    if time_col not in df.columns:
        raise DataError(f"{path}: missing column '{time_col}' (columns: {list(df.columns)})")
    gm = load_record(at2)
    t_csv = df[time_col].to_numpy(float)
    if t_csv[-1] - t_csv[0] > gm.duration + 1e-9:
        raise DataError(
            f"{path}: spans {t_csv[-1] - t_csv[0]:.4g} s, longer than the AT2 record {at2} "
            f"({gm.duration:.4g} s)"
        )
    df["ag"] = gm(t_csv - t_csv[0])


def excitation_column(path: Path, df: pd.DataFrame, excitation: str | None) -> str:
    has = [c for c in ("ag", "u") if c in df.columns]
    if excitation is None:
        if len(has) != 1:
            raise DataError(
                f"{path}: need exactly one excitation column 'ag' (ground) or 'u' (force); found {has}"
            )
        return has[0]
    col = {"ground": "ag", "force": "u"}[excitation]
    if col not in df.columns:
        raise DataError(f"{path}: excitation '{excitation}' needs a column '{col}'")
    return col


def check_numeric(path: Path, df: pd.DataFrame) -> None:
    """Every column numeric; a text cell is named with its column and row (before any unit is applied)."""
    for c in df.columns:
        if not pd.api.types.is_numeric_dtype(df[c]) or pd.api.types.is_bool_dtype(df[c]):
            as_num = pd.to_numeric(df[c], errors="coerce")
            text = as_num.isna() & df[c].notna()
            row = int(np.flatnonzero(text.to_numpy())[0]) if text.any() else 0
            raise DataError(
                f"{path}: column '{c}' is not numeric: row {row + 2} holds {str(df[c].iloc[row])!r}"
            )


def check_values(path: Path, df: pd.DataFrame) -> None:
    """Every column numeric and finite; the first bad row is named."""
    check_numeric(path, df)
    for c in df.columns:
        bad = ~np.isfinite(df[c].to_numpy(float))
        if bad.any():
            raise DataError(
                f"{path}: column '{c}' has {int(bad.sum())} NaN/infinite value(s), first at row "
                f"{int(np.flatnonzero(bad)[0]) + 2}"
            )


def uniform_time(path: Path, t: np.ndarray, time_col: str) -> np.ndarray:
    if t.size < 10:
        raise DataError(f"{path}: only {t.size} rows")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise DataError(
            f"{path}: time column '{time_col}' is not strictly increasing (row {int(np.flatnonzero(dt <= 0)[0]) + 3})"
        )
    if np.max(np.abs(dt - dt.mean())) > 1e-6 * max(dt.mean(), 1e-12) + 1e-9:
        raise DataError(
            f"{path}: non-uniform time step (from {dt.min():.6g} to {dt.max():.6g} s); resample to a uniform grid first"
        )
    return t


def floor_arrays(
    df: pd.DataFrame, layout: dict[str, dict[int, str]], n_rows: int, ground: np.ndarray | None
) -> dict[str, np.ndarray]:
    """(N, n_floors) arrays per kind, NaN for floors without the sensor; ``ground`` (ag) is
    subtracted from absolute accelerations so that ``a`` is relative like x and v."""
    n = max(j for cols in layout.values() for j in cols)
    out: dict[str, np.ndarray] = {}
    for kind, cols in layout.items():
        arr = np.full((n_rows, n), np.nan)
        for j, name in cols.items():
            arr[:, j - 1] = df[name].to_numpy(float)
        if kind == "a" and ground is not None:
            arr = arr - ground[:, None]
        out[kind] = arr
    return out


def channel_columns(path: Path, columns) -> dict[str, dict[int, str]]:
    """Response columns by kind and floor: ``x`` alone is floor 1, ``x3`` floor 3. A file may
    not mix the two spellings of a kind, and needs at least one response column."""
    out: dict[str, dict[int, str]] = {}
    unknown = [c for c in columns if c not in ("t", "ag", "u") and not re.fullmatch(r"[xva]\d*", c)]
    if unknown:
        raise DataError(
            f"{path}: unknown column(s) {unknown}; a record holds t, ag or u, and x, v, a (one degree "
            f"of freedom) or x1.., v1.., a1.. per floor"
        )
    for c in columns:
        m = re.fullmatch(r"([xva])(\d*)", c)
        if not m:
            continue
        kind, num = m.group(1), m.group(2)
        floor = int(num) if num else 1
        if num and floor < 1:
            raise DataError(f"{path}: column '{c}': floors are numbered from 1")
        if floor in out.setdefault(kind, {}):
            raise DataError(
                f"{path}: columns '{out[kind][floor]}' and '{c}' both give {kind} of floor {floor}"
            )
        out[kind][floor] = c
    if not out:
        raise DataError(
            f"{path}: no response column; give x, v or a (one degree of freedom) or x1.., v1.., a1.. "
            f"per floor (columns: {list(columns)})"
        )
    return out
