"""Every classical estimator by name, with one signature.

An estimator registers itself where it is written, with ``@estimator`` on its adapter
``(record, system, settings, noise) -> row``; the registry finds every module of
``pidyn.baselines`` on first use. ``baselines.run`` and ``model.refine.starts`` name the
estimators, the train task runs them, the tables and the settings test list them from here:
adding an estimator is one module (with its adapter registered), its settings in
``conf/baselines/default.yaml`` and its test.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pidyn.baselines.common import BaselineResult

#: (record, system, its settings from ``baselines.<name>``, the record's noise level) -> a row
Estimator = Callable[[Any, Any, dict, float], dict]


@dataclass(frozen=True)
class Entry:
    """One estimator: its adapter, the function whose keyword arguments are its settings, the
    label the tables print, whether it estimates the model's parameters (fitted on the fitting
    part only) or modes only, whether its row may carry the model's parameters as a refinement
    start (every parametric one; a modal peer whose realization maps onto the model), and its
    place in the tables."""

    name: str
    run: Estimator
    function: Callable
    label: str
    parametric: bool
    order: int
    starts: bool = False


_ENTRIES: dict[str, Entry] = {}
_FOUND = False


def estimator(
    name: str,
    function: Callable,
    label: str,
    parametric: bool = False,
    order: int = 100,
    starts: bool = False,
) -> Callable[[Estimator], Estimator]:
    """Register the decorated adapter as estimator ``name``."""

    def register(run: Estimator) -> Estimator:
        if name in _ENTRIES and _ENTRIES[name].run is not run:
            raise ValueError(f"estimator '{name}' is registered twice")
        _ENTRIES[name] = Entry(name, run, function, label, parametric, order, starts or parametric)
        return run

    return register


def row(r: BaselineResult) -> dict:
    """A parametric estimator's result as the row the run folder keeps."""
    return {
        "method": r.method,
        "params": r.params,
        "seconds": r.seconds,
        "note": r.note,
        "trajectory": r.trajectory,
    }


def entries() -> dict[str, Entry]:
    """Every registered estimator, in the tables' order (the modules found on first use)."""
    global _FOUND
    if not _FOUND:
        here = Path(__file__).parent  # the package's folder, without importing the package here
        for info in pkgutil.iter_modules([str(here)]):
            if info.name not in ("registry", "worker"):
                importlib.import_module(f"{__package__}.{info.name}")
        _FOUND = True
    return dict(sorted(_ENTRIES.items(), key=lambda kv: (kv[1].order, kv[0])))


def __getattr__(name: str) -> Any:
    """``ESTIMATORS`` (name -> adapter), ``PARAMETRIC`` (the names that estimate the model's
    parameters) and ``STARTS`` (the names a refinement may start from), derived from the entries."""
    if name == "ESTIMATORS":
        return {k: e.run for k, e in entries().items()}
    if name == "PARAMETRIC":
        return tuple(k for k, e in entries().items() if e.parametric)
    if name == "STARTS":
        return tuple(k for k, e in entries().items() if e.starts)
    raise AttributeError(name)


def check_names(key: str, names, extra: tuple[str, ...] = ()) -> None:
    """Misspelled estimator names fail with the list of the known ones."""
    known = set(entries()) | set(extra)
    unknown = sorted(set(names) - known)
    if unknown:
        raise ValueError(f"{key}: unknown method(s) {unknown}; choose from {', '.join(sorted(known))}")
