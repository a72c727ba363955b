"""Which start a run takes (``model.start``): the data's, the config's or an earlier run's, and
the values a user gave kept in any case."""

from __future__ import annotations

import glob
import json
import logging
import re
from pathlib import Path

from pidyn.starts.data import DataStart, start_from_data
from pidyn.systems.base import merge_specs
from pidyn.systems.modal import first_mode

log = logging.getLogger(__name__)


def with_start(system, values: dict[str, float], keep: set[str] | frozenset = frozenset()):
    """``system`` with its trainable parameters started at ``values`` (their scales with them),
    except those in ``keep`` (a start the user gave)."""
    trainable = {s.name for s in system.param_specs() if s.trainable}
    chosen = {n: {"init": float(v)} for n, v in values.items() if n in trainable and n not in keep}
    if chosen:
        system._specs = merge_specs(system.param_specs(), chosen)
    return system


def user_started(system, settings: list[str]) -> set[str]:
    """The parameters whose start the user set (``system.params.<name>...``, ``system.guess``)."""
    names = [s.name for s in system.param_specs()]
    out: set[str] = set()
    for key in settings:
        m = re.fullmatch(r"system\.params\.([^.]+)(\..*)?", key)
        if m:
            out.add(m.group(1))
        elif key == "system.params":
            out.update(names)
        elif key == "system.guess":
            out.update(names)
        elif key.startswith("system.guess."):
            base = key.split(".", 2)[2]
            out.update(n for n in names if re.fullmatch(rf"{re.escape(base)}_?\d+", n) or n == base)
    return out


def start_from_run(folder: str, system, own: set[str] | frozenset = frozenset()) -> DataStart:
    """The estimate of an earlier run (its folder's ``metrics.json``) as the start: another record of
    the same structure whose input does not show its resonance (a sine below it) starts from a
    broadband record's estimate; the record at hand then decides. A pattern (``*``) must match one
    folder. A single mode's run starts a modes model (``from_single_mode``). Parameters the run
    has no estimate of may start where the user set them (``own``: ``system.params.<name>.init``):
    a model extended by a term starts from the nominal run, its new term from the user's values."""
    if any(ch in folder for ch in "*?["):  # a pattern (a sweep names each job's earlier run by its options)
        found = sorted(glob.glob(folder))
        if len(found) != 1:
            raise ValueError(f"model.start: the pattern '{folder}' matches {len(found)} run folders, not one")
        folder = found[0]
    path = Path(folder) / "metrics.json"
    if not path.is_file():
        raise ValueError(
            f"model.start: '{folder}' is none of {', '.join(START_METHODS)} and not a run folder "
            f"(no metrics.json in it)"
        )
    params = json.loads(path.read_text()).get("params") or {}
    trainable = {s.name for s in system.param_specs() if s.trainable}
    values = {n: float(v) for n, v in params.items() if n in trainable}
    inits = {s.name: float(s.init) for s in system.param_specs()}
    values.update({n: inits[n] for n in sorted(trainable & set(own)) if n not in values})  # the user's
    missing = sorted(trainable - set(values))
    nested = getattr(system, "from_single_mode", lambda _: None)(params) if missing else None
    if nested is not None:  # a single mode's run starts a modes model (pidyn.systems.modes)
        values, missing = {n: v for n, v in nested.items() if n in trainable}, []
    if missing:
        raise ValueError(f"model.start: the run in '{folder}' has no estimate of {missing} (another model?)")
    freq, zeta = first_mode(system, {**{s.name: float(s.init) for s in system.param_specs()}, **values})
    return DataStart(values, "run", freq, zeta, note=f"the estimate of the run in {folder}")


#: where PIDynNet's parameters start (``model.start``; or an earlier run's folder)
START_METHODS = ("auto", "data", "config")


def start_policy(method: str, system, record, user_keys: list[str]):
    """(system, start, used): ``data``: read from the record; ``config``: the system config's
    values; ``auto``: the data's on a measured record (no truth), the config's on a simulated one;
    a run folder: that run's estimate (``start_from_run``).
    A start the user gave (``system.params.<name>.init=...``, in ``user_keys``) is always kept.
    Unless ``config``, the start is returned to be offered to the refinement as well."""
    if method not in START_METHODS:
        kept = user_started(system, user_keys)
        start = start_from_run(method, system, kept)
        return with_start(system, start.values, kept), start, True
    if method == "config":
        return system, None, False
    start = start_from_data(record, system)
    if start is None:
        log.info("start from the data: the record shows no resonance; the config's values are used")
        return system, None, False
    used = method == "data" or not record.truth
    if used:
        kept = user_started(system, user_keys)
        system = with_start(system, start.values, kept)
        if kept:
            log.info("start from the data, except %s (set by the user)", sorted(kept))
    return system, start, used
