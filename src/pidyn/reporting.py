"""What a run leaves behind: identified parameters with errors, metrics, figures."""

from __future__ import annotations

import io
import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pidyn.errors import error_pct


def param_table(
    values: dict[str, float],
    truths: dict[str, float | None],
    units: dict[str, str],
    intervals: dict[str, dict] | None = None,
) -> dict:
    """Per parameter: value, unit, 95 % interval and std (when estimated), truth and error %."""
    out = {}
    for n, v in values.items():
        row: dict[str, Any] = {"value": float(v), "unit": units.get(n, "")}
        if intervals and n in intervals:
            row["ci95"] = [float(x) for x in intervals[n]["ci95"]]
            row["std"] = float(intervals[n]["std"])
        t = truths.get(n)
        if t is not None:
            row["truth"] = float(t)
            row["error_pct"] = error_pct(v, t) if t != 0 else None
            if "ci95" in row:
                row["covered"] = bool(row["ci95"][0] <= t <= row["ci95"][1])
        out[n] = row
    return out


def write_text_atomic(path: Path, text: str) -> None:
    """``text`` to ``path`` through a temporary name and a rename: a reader sees the old file or
    the whole new one, never half of it (a full disk or a kill leaves the old one)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_yaml(path: Path, data: dict) -> None:
    write_text_atomic(path, yaml.safe_dump(data, sort_keys=False))


def _jsonable(value: Any) -> Any:
    """A typed result writes itself (``to_dict``); a NumPy scalar is a number."""
    to_dict = getattr(value, "to_dict", None)
    return to_dict() if callable(to_dict) else float(value)


def write_json(path: Path, data: dict) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, default=_jsonable))


def nrmse(pred: np.ndarray, true: np.ndarray) -> float:
    return float(np.sqrt(np.mean((pred - true) ** 2)) / max(np.std(true), 1e-300))


#: beyond this a value is a blown-up simulation, not a response (the refinement treats it so,
#: and matplotlib's tick arithmetic overflows on values near the float64 limit)
BLOWN_UP = 1e100


def plottable(a: Any) -> np.ndarray:
    """``a`` as floats with non-finite and blown-up values blanked (NaN): a plot leaves them out
    instead of failing, so a run whose identified model diverges still gets its figures."""
    a = np.array(a, dtype=float)
    with np.errstate(invalid="ignore"):
        a[~(np.abs(a) < BLOWN_UP)] = np.nan
    return a


def diverged(a: Any) -> bool:
    """Does a simulated response blow up (non-finite or beyond ``BLOWN_UP``) anywhere?"""
    a = np.asarray(a, dtype=float)
    with np.errstate(invalid="ignore"):
        return bool(a.size and not np.all(np.abs(a) < BLOWN_UP))


def pyplot():
    """matplotlib's pyplot, on the Agg backend unless pyplot is loaded already (a notebook has chosen
    its backend). Imported on the first figure, not with the package: it costs about half a second
    at start-up, and the tasks draw only at their end."""
    import matplotlib  # lazy: see the docstring

    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: see the docstring

    return plt


def _param_grid(n_params: int, errors: bool = True):
    """One row per parameter: estimate (left), relative error (right; ``errors=False``, as for a
    measured record, where there is no truth to err from: the estimate alone), shared record-time
    axis. Without the error column, each row's second entry is its first axis again."""
    plt = pyplot()
    if errors:
        return plt.subplots(n_params, 2, figsize=(10, 2.2 * n_params), squeeze=False, sharex=True)
    fig, axes = plt.subplots(n_params, 1, figsize=(7, 1.8 * n_params), squeeze=False, sharex=True)
    return fig, [(row[0], row[0]) for row in axes]


def _finish_grid(fig, axes, title: str, path: Path | None, dpi: int, palette: bool = False) -> None:
    """Label and save the grid; ``path=None`` leaves the figure open for the caller."""
    plt = pyplot()

    for ax in set(axes[-1]):
        ax.set_xlabel("record time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    if path is None:
        return
    if palette:
        _save_small(fig, path, dpi)
    else:
        fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_convergence(
    path: Path | None,
    trajectory: list[dict],
    truths: dict[str, float | None],
    windows: list[dict],
    title: str = "",
    other: tuple[str, list[dict]] | None = None,
    final: dict[str, dict] | None = None,
):
    """Parameter estimates over record time with window boundaries (cf. paper Figure 3);
    ``final``: the refined estimate with its 95 % interval, drawn at the record's end.
    ``path=None`` returns the open figure (notebooks) instead of writing a file."""
    names = [k for k in trajectory[0] if k not in ("iteration", "t")] if trajectory else []
    if not names:
        return None
    fig, axes = _param_grid(len(names), errors=any(truths.get(n) is not None for n in names))
    t = np.array([p["t"] for p in trajectory])
    for i, n in enumerate(names):
        v = plottable([p[n] for p in trajectory])
        ax, axe = axes[i]
        ax.plot(t, v, lw=1, label="PIDynNet")
        if other is not None and other[1] and n in other[1][0]:
            to = np.array([p["t"] for p in other[1]])
            vo = plottable([p[n] for p in other[1]])
            ax.plot(to, vo, lw=0.8, color="tab:orange", label=other[0])
            if truths.get(n) is not None:
                axe.semilogy(to, error_pct(vo, truths[n]) + 1e-6, lw=0.8, color="tab:orange")
        if truths.get(n) is not None:
            ax.axhline(truths[n], color="k", ls="--", lw=0.8, label="truth")
            axe.semilogy(t, error_pct(v, truths[n]) + 1e-6, lw=1, color="tab:blue")
            axe.set_ylabel(f"|err| {n} (%)")
        if final and n in final:
            val, lo, hi = plottable([final[n]["value"], *final[n]["ci95"]])
            te = t[-1] if len(t) else 0.0
            if np.isfinite(val):  # an interval without bounds is drawn as the point alone
                err = [[val - lo], [hi - val]] if np.isfinite(lo) and np.isfinite(hi) else None
                ax.errorbar(
                    [te], [val], yerr=err, fmt="o", color="tab:green", ms=4, capsize=3, label="refined, 95 %"
                )
        ax.set_ylabel(n)
        for w in windows:
            for a in {ax, axe}:
                a.axvline(w["t1"], color="0.85", lw=0.6)
        if i == 0:
            ax.legend(fontsize=8)
    _finish_grid(fig, axes, title, path, dpi=110)
    return fig if path is None else None


def plot_convergence_seeds(
    path: Path,
    runs: dict[str, list[list[dict]]],
    truths: dict[str, float | None],
    bound_pct: dict[str, float] | None = None,
    title: str = "",
) -> bool:
    """Figure 3 for a table cell: every seed's estimate over record time, per method.

    One seed's curve says little when the error is partly luck; the spread of all seeds beside
    the truth (left) and their relative errors beside the Cramer-Rao std (right, dotted) show
    whether a method converges, and to what. Returns False (no file) when no run has a trajectory.
    """
    first = next((tr for trs in runs.values() for tr in trs if tr), None)
    if first is None:
        return False
    names = [k for k in first[0] if k not in ("iteration", "t")]
    colors = dict(zip(runs, ["tab:blue", "tab:orange", "tab:green", "tab:red"]))
    fig, axes = _param_grid(len(names))
    for i, n in enumerate(names):
        ax, axe = axes[i]
        for method, trs in runs.items():
            for s_i, tr in enumerate(t for t in trs if t and n in t[0]):
                t = np.array([p["t"] for p in tr])
                v = plottable([p[n] for p in tr])
                ax.plot(t, v, lw=0.7, alpha=0.6, color=colors[method], label=method if s_i == 0 else None)
                if truths.get(n):
                    axe.semilogy(t, error_pct(v, truths[n]) + 1e-6, lw=0.7, alpha=0.6, color=colors[method])
        if truths.get(n) is not None:
            ax.axhline(truths[n], color="k", ls="--", lw=0.8, label="truth")
            axe.set_ylabel(f"|err| {n} (%)")
        if bound_pct and bound_pct.get(n):
            axe.axhline(bound_pct[n], color="k", ls=":", lw=0.9, label="Cramer-Rao std")
            if i == 0:
                axe.legend(fontsize=8)
        ax.set_ylabel(n)
        if i == 0:
            ax.legend(fontsize=8)
    _finish_grid(fig, axes, title, path, dpi=90, palette=True)
    return True


def _save_small(fig, path: Path, dpi: int) -> None:
    """PNG with a 64-colour palette: many thin overlapping curves are several times smaller so."""
    from PIL import Image  # lazy: with matplotlib, on the first figure (see pyplot)

    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    buf.seek(0)
    Image.open(buf).convert("RGB").quantize(colors=64).save(path, optimize=True)


def plot_response(
    path: Path, t: np.ndarray, series: dict[str, np.ndarray], title: str = "", ylabel: str = "x (m)"
) -> None:
    """Measured vs predicted time histories on one axis."""
    plt = pyplot()

    fig, ax = plt.subplots(figsize=(10, 3.2))
    for i, (name, y) in enumerate(series.items()):
        ax.plot(
            t,
            plottable(y),
            lw=0.9 if i == 0 else 0.8,
            ls="-" if i == 0 else "--",
            label=name,
            color="0.3" if i == 0 else None,
        )
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
