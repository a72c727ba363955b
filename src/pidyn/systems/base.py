"""The contract every structural system fulfils (pure PyTorch/NumPy, no training framework).

A system knows its parameters (``ParamSpec``), its named physics residuals for the loss
(torch) and its right-hand side for simulation (NumPy/SciPy). The excitation is either a
ground acceleration (``-M 1 ag``) or a force applied to the structure (``u``).

Several ground inputs (a bridge on three supports that move differently): the excitation
``f`` then has a last axis of ``2 n_inputs`` columns, the supports' accelerations and then
their velocities (``excitation_width``). Each degree of freedom feels the ground acceleration
``sum_j r_j ag_j`` with influence coefficients ``r_j``, and an accelerometer's absolute reading
is x'' + sum_j r_j ag_j. With one input the record keeps accelerations relative to the ground
(the measured ag is subtracted); with several there is no single ground to subtract, so the
record keeps them absolute and ``acceleration_output`` gives the model's reading alike.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any, Literal

import numpy as np
import torch

from pidyn.params import ParamSpec

ExcitationKind = Literal["ground", "force"]


@dataclass
class Kinematics:
    """Response and its time derivatives at a set of time points.

    Shapes: ``x, v, a``: (N, n_dof); ``z, zd``: (N, n_latent) or None.
    """

    t: torch.Tensor
    x: torch.Tensor
    v: torch.Tensor
    a: torch.Tensor
    z: torch.Tensor | None = None
    zd: torch.Tensor | None = None


class StructuralSystem(ABC):
    """Base class: parameter specs, named residuals, simulation right-hand side."""

    name: str = "system"
    n_dof: int = 1
    n_latent: int = 0
    latent_names: tuple[str, ...] = ()
    #: names of several ground inputs (supports); empty: one input (``ag`` or ``u``)
    inputs: tuple[str, ...] = ()

    #: linear in its state and excitation, with no time-dependent term: its RK4 scheme is a
    #: one-sample affine map (``pidyn.integrate_linear``)
    linear_time_invariant: bool = False

    def period_scaling(self) -> dict[str, float]:
        """Powers p of a frequency factor lam: every parameter named here times lam ** p puts
        every natural frequency times lam and keeps the damping ratios (stiffnesses 2, dashpots 1).
        Empty where no such family is known (a nonlinear model): no period scan
        (``pidyn.refine.period_scan``)."""
        return {}

    @property
    def n_inputs(self) -> int:
        return max(1, len(self.inputs))

    @property
    def excitation_width(self) -> int:
        """Columns of the excitation: 1, or the supports' accelerations and velocities (2 n_inputs)."""
        return 1 if self.n_inputs == 1 else 2 * self.n_inputs

    def __init__(self, excitation: ExcitationKind = "ground") -> None:
        if excitation not in ("ground", "force"):
            raise ValueError(f"{self.name}: excitation must be 'ground' or 'force', got '{excitation}'")
        self.excitation = excitation

    @abstractmethod
    def param_specs(self) -> list[ParamSpec]:
        """All parameters, known ones (trainable=False) included."""

    @abstractmethod
    def residual(self, k: Kinematics, f: torch.Tensor, p: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Named residuals, each (N, ·), zero when the response obeys the model.

        ``f`` is the excitation at the same points: ground acceleration (m/s^2) or force (N),
        shape (N,). ``motion`` is in force units; latent rates in their own units.
        """

    @abstractmethod
    def rhs(self, t: float, y: np.ndarray, p: dict[str, float], f: Callable[[float], float]) -> np.ndarray:
        """dy/dt for the state y = [x (n_dof), v (n_dof), z (n_latent)]."""

    @property
    def n_state(self) -> int:
        """Length of the state y = [x (n_dof), v (n_dof), z (n_latent)]."""
        return 2 * self.n_dof + self.n_latent

    def state_rate(self, t, y, p: dict, f):
        """dy/dt for a batch of states ``y`` (..., n_state) at times ``t`` and excitation ``f``
        (both broadcast against y[..., 0]). Written on array operations only, so NumPy
        arrays and ``pidyn.autodiff.Dual`` arrays (exact sensitivities) go through the same
        code; ``rhs`` is its one-state special case."""
        raise NotImplementedError(f"{self.name}: no batched state rate")

    def nominal_mass(self) -> float:
        """The mass as given (its spec's init): known, or the starting guess when identified."""
        spec = next((s for s in self.param_specs() if s.name in ("m", "m1")), None)
        return float(spec.init) if spec is not None else 1.0

    def ground_motion(self, f, p):
        """The ground acceleration every degree of freedom feels, shaped like ``f[..., 0]`` per
        degree of freedom on a last axis (..., n_dof): ``f`` itself for one input, the inputs
        weighted by their influence coefficients for several."""
        raise NotImplementedError(f"{self.name}: several ground inputs are not supported")

    def acceleration_output(self, a_rel, f, p):
        """What an accelerometer on each degree of freedom reads, in the record's convention:
        ``a_rel`` itself (relative to the one ground) for one input, a_rel + sum_j r_j ag_j
        (absolute) for several. Works on NumPy, dual and torch arrays (..., n_dof)."""
        if self.n_inputs == 1:
            return a_rel
        return a_rel + self.ground_motion(f, p)

    def excitation_as_acceleration(self, f):
        """The excitation as an acceleration q'' for the excitation transform, or None.

        Ground excitation: ag itself (several inputs: weighted by the influence coefficients'
        starting values, a fixed signal, so the change of variable stays exact). A force on a
        single mass: -u/m (nominal m). A force on one storey of a multi-storey model has no
        common acceleration: None (no transform).
        """
        if self.excitation == "ground":
            if self.n_inputs > 1:
                start = {s.name: s.init for s in self.param_specs()}
                return self.ground_motion(f, start)[..., 0]
            return f
        if self.n_dof > 1:
            return None
        return -f / self.nominal_mass()

    def linear_params(self) -> list[str]:
        """Parameters in which the ``motion`` residual is linear (for least-squares init)."""
        return []

    def true_values(self) -> dict[str, float]:
        out = {}
        for s in self.param_specs():
            if s.true is None:
                raise ValueError(f"{self.name}: parameter '{s.name}' has no true value to simulate with")
            out[s.name] = s.true
        return out

    def describe(self, p: dict[str, float]) -> str:
        """Human-readable equation with the given parameter values."""
        return f"{self.name}(" + ", ".join(f"{k}={v:.5g}" for k, v in p.items()) + ")"


def merge_specs(defaults: list[ParamSpec], overrides: dict | None) -> list[ParamSpec]:
    """Apply config overrides (``{name: {field: value}}``) to default specs; typos fail."""
    overrides = dict(overrides or {})
    by_name = {s.name: s for s in defaults}
    unknown = set(overrides) - set(by_name)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; this system has {list(by_name)}")
    allowed = {f.name for f in fields(ParamSpec)} - {"name"}
    out = []
    for s in defaults:
        o = dict(overrides.get(s.name) or {})
        bad = set(o) - allowed
        if bad:
            raise ValueError(
                f"parameter '{s.name}': unknown field(s) {sorted(bad)}; allowed {sorted(allowed)}"
            )
        if "init" in o and "scale" not in o and s.transform != "box":
            o["scale"] = abs(float(o["init"])) or s.scale  # never scale by the (unknown) truth
        out.append(replace(s, **o))
    return out


def stack_last(parts: list, like) -> Any:
    """``parts`` stacked on a new last axis: torch when ``like`` is a tensor (the physics loss, a
    learned force trained by output error), NumPy otherwise (plain or dual arrays)."""
    return torch.stack(parts, dim=-1) if isinstance(like, torch.Tensor) else np.stack(parts, axis=-1)
