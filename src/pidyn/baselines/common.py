"""What every baseline returns, and the parameter coordinates they share."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pidyn.params import ParamSpec, clip_to_bounds, to_raw


@dataclass
class BaselineResult:
    method: str
    params: dict[str, float]
    seconds: float
    trajectory: list[dict] = field(default_factory=list)  # {"t": ..., name: value}
    note: str = ""


def trainable_specs(system) -> list[ParamSpec]:
    return [s for s in system.param_specs() if s.trainable]


def to_theta(specs: list[ParamSpec], values: dict[str, float]) -> np.ndarray:
    """Unconstrained coordinates (log for positive, logit for boxed), as PIDynNet uses."""
    return np.array([to_raw(s, clip_to_bounds(s, values[s.name])) for s in specs])


def from_theta(specs: list[ParamSpec], theta: np.ndarray) -> dict[str, np.ndarray]:
    """Vectorised inverse of ``to_theta``; ``theta`` has shape (n,) or (n, P)."""
    out = {}
    for i, s in enumerate(specs):
        th = theta[i]
        if s.transform == "log":
            out[s.name] = s.scale * np.exp(th)
        elif s.transform == "box":
            assert s.lower is not None and s.upper is not None
            out[s.name] = s.lower + (s.upper - s.lower) / (1 + np.exp(-th))
        else:
            out[s.name] = s.scale * th
    return out


def fixed_values(system) -> dict[str, float]:
    return {s.name: s.init for s in system.param_specs() if not s.trainable}


def starting_point(system, init: dict[str, float] | None) -> tuple[list[ParamSpec], dict[str, float], np.ndarray]:
    """Trainable specs, fixed values and the unconstrained start (the specs' init, overridden by ``init``)."""
    specs = trainable_specs(system)
    start = {s.name: s.init for s in specs}
    start.update(init or {})
    return specs, fixed_values(system), to_theta(specs, start)
