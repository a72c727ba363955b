"""What every baseline returns, and the parameter coordinates they share."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pidyn.params import ParamSpec, fixed_values, from_theta, to_theta, trainable_specs

__all__ = ["BaselineResult", "fixed_values", "from_theta", "to_theta", "trainable_specs", "starting_point"]


@dataclass
class BaselineResult:
    method: str
    params: dict[str, float]
    seconds: float
    trajectory: list[dict] = field(default_factory=list)  # {"t": ..., name: value}
    note: str = ""
    loglik: float = float("nan")  # innovation log-likelihood (filters)


def starting_point(
    system, init: dict[str, float] | None
) -> tuple[list[ParamSpec], dict[str, float], np.ndarray]:
    """Trainable specs, fixed values and the unconstrained start (the specs' init, overridden by ``init``)."""
    specs = trainable_specs(system)
    start = {s.name: s.init for s in specs}
    start.update(init or {})
    return specs, fixed_values(system), to_theta(specs, start)
