"""Trainable physical parameters with positivity / bound transforms and O(1) scaling.

Each parameter is stored as an unconstrained ``nn.Parameter`` (``raw``) and mapped to its
physical value by a transform, so the optimiser works on O(1) numbers whatever the unit
(a damping of 0.3 N s/m and a cubic stiffness of 120 N/m^3 move at the same relative pace),
and a positive quantity can never turn negative. Being ``nn.Parameter``s they live in
every checkpoint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
from torch import nn

Transform = Literal["log", "box", "identity"]

#: a positive (log-transformed) estimate that ran to zero, its exp underflowing, restarts here when
#: a model is built from it: a friction damper can take a storey's whole viscous damping
POSITIVE_FLOOR = 1e-12


def positive(value: float) -> float:
    """``value`` as the start of a log-transformed parameter: at least ``POSITIVE_FLOOR``."""
    return max(float(value), POSITIVE_FLOOR)


@dataclass(frozen=True)
class ParamSpec:
    """What is known about one physical parameter before identification.

    Attributes:
        name: identifier used in configs, logs and reports (``params/<name>``).
        init: starting value when no better initialisation is available.
        scale: typical magnitude; ``identity`` uses ``value = scale * raw``.
        transform: ``log`` (positive, value = scale * exp(raw)), ``box`` (within
            [lower, upper] through a sigmoid) or ``identity``.
        lower, upper: physical bounds (required for ``box``; used as a guard otherwise).
        true: the ground truth when it is known (synthetic data), else None.
        trainable: False for known quantities (e.g. a measured mass).
        unit: for reports.
    """

    name: str
    init: float
    scale: float = 1.0
    transform: Transform = "log"
    lower: float | None = None
    upper: float | None = None
    true: float | None = None
    trainable: bool = True
    unit: str = ""

    def __post_init__(self) -> None:
        if self.transform == "log" and self.init <= 0:
            raise ValueError(f"parameter '{self.name}': log transform needs init > 0, got {self.init}")
        if self.transform == "box":
            if self.lower is None or self.upper is None or not self.lower < self.upper:
                raise ValueError(f"parameter '{self.name}': box transform needs lower < upper")
            if not self.lower < self.init < self.upper:
                raise ValueError(
                    f"parameter '{self.name}': init {self.init} outside ({self.lower}, {self.upper})"
                )
        if self.scale <= 0:
            raise ValueError(f"parameter '{self.name}': scale must be positive")


def to_raw(spec: ParamSpec, value: float) -> float:
    """Inverse transform: the unconstrained number that maps to ``value``."""
    if spec.transform == "log":
        return math.log(max(value, 1e-300) / spec.scale)
    if spec.transform == "box":
        lo, hi = spec.lower, spec.upper
        assert lo is not None and hi is not None
        u = min(max((value - lo) / (hi - lo), 1e-9), 1 - 1e-9)
        return math.log(u / (1 - u))
    return value / spec.scale


def from_raw(spec: ParamSpec, raw: torch.Tensor) -> torch.Tensor:
    """Forward transform, differentiable."""
    if spec.transform == "log":
        return spec.scale * torch.exp(raw)
    if spec.transform == "box":
        assert spec.lower is not None and spec.upper is not None
        return spec.lower + (spec.upper - spec.lower) * torch.sigmoid(raw)
    return spec.scale * raw


class PhysicalParameters(nn.Module):
    """A named set of physical parameters; ``values()`` gives the physical numbers."""

    def __init__(self, specs: list[ParamSpec]) -> None:
        super().__init__()
        names = [s.name for s in specs]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate parameter names in {names}")
        self.specs = list(specs)
        self.raw = nn.ParameterDict(
            {
                s.name: nn.Parameter(
                    torch.tensor(to_raw(s, s.init), dtype=torch.get_default_dtype()),
                    requires_grad=s.trainable,
                )
                for s in self.specs
            }
        )

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.specs]

    @property
    def trainable_names(self) -> list[str]:
        return [s.name for s in self.specs if s.trainable]

    def spec(self, name: str) -> ParamSpec:
        return next(s for s in self.specs if s.name == name)

    def values(self) -> dict[str, torch.Tensor]:
        return {s.name: from_raw(s, self.raw[s.name]) for s in self.specs}

    def as_floats(self) -> dict[str, float]:
        with torch.no_grad():
            return {k: float(v) for k, v in self.values().items()}

    def truths(self) -> dict[str, float | None]:
        return {s.name: s.true for s in self.specs}

    @torch.no_grad()
    def set_values(self, values: dict[str, float]) -> None:
        """Set physical values (clipped into the spec's bounds)."""
        for name, value in values.items():
            s = self.spec(name)
            value = clip_to_bounds(s, float(value))
            self.raw[name].fill_(to_raw(s, value))

    def raw_vector(self, names: list[str] | None = None) -> torch.Tensor:
        names = names or self.trainable_names
        return torch.stack([self.raw[n] for n in names])


def dvalue_draw(spec: ParamSpec, raw: float) -> float:
    """d value / d raw at ``raw``: maps a standard error between the two coordinates."""
    r = torch.tensor(raw, dtype=torch.float64, requires_grad=True)
    (g,) = torch.autograd.grad(from_raw(spec, r), r)
    return float(g)


def in_range(spec: ParamSpec, value: float) -> bool:
    """Whether ``value`` is a value the parameter's transform can represent (inside its bounds)."""
    if spec.transform == "log" and value <= 0:
        return False
    lo = spec.lower if spec.lower is not None else -float("inf")
    hi = spec.upper if spec.upper is not None else float("inf")
    return lo < value < hi


def clip_to_bounds(spec: ParamSpec, value: float) -> float:
    lo = spec.lower if spec.lower is not None else -math.inf
    hi = spec.upper if spec.upper is not None else math.inf
    if spec.transform == "log":
        lo = max(lo, 1e-12 * spec.scale)
    if spec.transform == "box":
        eps = 1e-6 * (hi - lo)
        lo, hi = lo + eps, hi - eps
    return min(max(value, lo), hi)


# ---------------------------------------------------------------- vectorised coordinates
def trainable_specs(system) -> list[ParamSpec]:
    return [s for s in system.param_specs() if s.trainable]


def to_theta(specs: list[ParamSpec], values: dict[str, float]) -> np.ndarray:
    """Unconstrained coordinates (log for positive, logit for boxed), as PIDynNet trains them."""
    return np.array([to_raw(s, clip_to_bounds(s, values[s.name])) for s in specs])


def from_theta(specs: list[ParamSpec], theta: np.ndarray) -> dict[str, np.ndarray]:
    """Vectorised inverse of ``to_theta``; ``theta`` has shape (n,) or (n, P), plain or dual
    (``pidyn.autodiff``: the same formulas give exact derivatives)."""
    out = {}
    for i, s in enumerate(specs):
        th = theta[i]
        if s.transform == "log":
            with np.errstate(over="ignore"):  # a parameter run to infinity is inf, named by the caller
                out[s.name] = s.scale * np.exp(th)
        elif s.transform == "box":
            assert s.lower is not None and s.upper is not None
            with np.errstate(over="ignore"):  # far below the box: exp overflows, the value is its lower bound
                out[s.name] = s.lower + (s.upper - s.lower) / (1 + np.exp(-th))
        else:
            out[s.name] = s.scale * th
    return out


def fixed_values(system) -> dict[str, float]:
    return {s.name: s.init for s in system.param_specs() if not s.trainable}
