"""Every classical estimator by name, with one signature: ``baselines.run`` and
``model.refine.starts`` name them, the train task runs them, the tables list them from here."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pidyn.baselines.common import BaselineResult

#: (record, system, its settings from ``baselines.<name>``, the record's noise level) -> a row
Estimator = Callable[[Any, Any, dict, float], dict]


def _row(r: BaselineResult) -> dict:
    return {
        "method": r.method,
        "params": r.params,
        "seconds": r.seconds,
        "note": r.note,
        "trajectory": r.trajectory,
    }


def _equation_error(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.least_squares import equation_error

    return _row(equation_error(record, system))


def _output_error(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.least_squares import output_error

    return _row(output_error(record, system, **settings))


def _sindy(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.sindy import weak_sindy

    return _row(weak_sindy(record, system, **settings))


def _ukf(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.ukf import unscented_kalman_filter

    return _row(unscented_kalman_filter(record, system, noise_level=noise, **settings))


def _transfer_function(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.peers import transfer_function_estimate

    return transfer_function_estimate(record, **settings).to_row()


def _srim(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.peers import srim

    return srim(record, **settings).to_row()


def _okid_era(record, system, settings: dict, noise: float) -> dict:
    from pidyn.baselines.peers import okid_era

    return okid_era(record, **settings).to_row()


ESTIMATORS: dict[str, Estimator] = {
    "equation_error": _equation_error,
    "output_error": _output_error,
    "sindy": _sindy,
    "ukf": _ukf,
    "transfer_function": _transfer_function,
    "srim": _srim,
    "okid_era": _okid_era,
}

#: estimators that give the model's parameters (the others give modes only): refinement starts
PARAMETRIC = ("equation_error", "output_error", "sindy", "ukf")
#: estimators of modes that run on an optional extra (``pip install 'pidyn[peer]'``)
PEERS = ("srim", "okid_era")


def check_names(key: str, names, extra: tuple[str, ...] = ()) -> None:
    """Misspelled estimator names fail with the list of the known ones."""
    known = set(ESTIMATORS) | set(extra)
    unknown = sorted(set(names) - known)
    if unknown:
        raise ValueError(f"{key}: unknown method(s) {unknown}; choose from {', '.join(sorted(known))}")
