"""Restoring-force terms: the building blocks of single-degree-of-freedom models.

A model is mass x acceleration + the sum of its terms = excitation force. Every term is one
small class: its parameters, its force (torch and NumPy through the same array code) and,
for hysteresis, the rate of its latent state. New physical effects (the discrepancy
library) are added here and nowhere else.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from pidyn.params import ParamSpec

Array = Any  # torch.Tensor or np.ndarray: the formulas below work on both


def _abs(x: Array) -> Array:
    return x.abs() if isinstance(x, torch.Tensor) else np.abs(x)


def _tanh(x: Array) -> Array:
    return torch.tanh(x) if isinstance(x, torch.Tensor) else np.tanh(x)


def _relu(x: Array) -> Array:
    return torch.relu(x) if isinstance(x, torch.Tensor) else np.maximum(x, 0.0)


def _clamp_min(x: Array, lo: float) -> Array:
    return x.clamp_min(lo) if isinstance(x, torch.Tensor) else np.maximum(x, lo)


def _sigmoid(x: Array) -> Array:
    return torch.sigmoid(x) if isinstance(x, torch.Tensor) else 0.5 * (1 + np.tanh(0.5 * x))


def _spow(z: Array, n: Array) -> Array:
    """|z|^n, with a floor so that the gradient stays finite at z = 0 for any n > 0."""
    return _clamp_min(_abs(z), 1e-12) ** n


class ForceTerm:
    """One additive restoring-force term f(t, x, v, z; p)."""

    name: str = "term"
    n_latent: int = 0
    linear: tuple[str, ...] = ()  # parameters the force is linear in

    def specs(self) -> list[ParamSpec]:
        raise NotImplementedError

    def force(self, t: Array, x: Array, v: Array, z: Array | None, p: dict) -> Array:
        raise NotImplementedError

    def latent_rate(self, t: Array, x: Array, v: Array, z: Array, p: dict) -> Array:
        raise NotImplementedError

    def formula(self, p: dict[str, float]) -> str:
        raise NotImplementedError


class ViscousDamping(ForceTerm):
    name = "viscous_damping"
    linear = ("c",)

    def __init__(self, c: float = 0.5) -> None:
        self.c = c

    def specs(self) -> list[ParamSpec]:
        return [ParamSpec("c", init=self.c, scale=self.c, true=self.c, unit="N s/m")]

    def force(self, t, x, v, z, p):
        return p["c"] * v

    def formula(self, p):
        return f"{p['c']:.5g} x'"


class LinearStiffness(ForceTerm):
    name = "linear_stiffness"

    def __init__(self, k: float = 15.0, param: str = "k") -> None:
        self.k, self.param = k, param
        self.linear = (param,)

    def specs(self):
        return [ParamSpec(self.param, init=self.k, scale=self.k, true=self.k, unit="N/m")]

    def force(self, t, x, v, z, p):
        return p[self.param] * x

    def formula(self, p):
        return f"{p[self.param]:.5g} x"


class CubicStiffness(ForceTerm):
    name = "cubic_stiffness"
    linear = ("k3",)

    def __init__(self, k3: float = 120.0, signed: bool = False) -> None:
        """``signed``: k3 may take either sign (hardening or softening is a finding, as when a
        diagnosis discovers the term); otherwise it is positive (a hardening Duffing spring)."""
        if not signed and k3 <= 0:
            raise ValueError(f"cubic_stiffness: k3={k3} is softening; use signed=True to allow k3 <= 0")
        self.k3, self.signed = k3, signed

    def specs(self):
        return [ParamSpec("k3", init=self.k3, scale=abs(self.k3) or 1.0, true=self.k3, unit="N/m^3",
                          transform="identity" if self.signed else "log")]

    def force(self, t, x, v, z, p):
        return p["k3"] * x**3

    def formula(self, p):
        return f"{p['k3']:.5g} x^3"


class BoucWenHysteresis(ForceTerm):
    """k z with z' = x' - gamma |x'| |z|^(n-1) z - beta x' |z|^n (Bouc 1967, Wen 1976).

    The paper's Eq. 16 uses this term alone as the restoring force (no elastic part).
    """

    name = "hysteresis"
    n_latent = 1

    def __init__(
        self, k: float = 12.0, beta: float = 1.0, gamma: float = 2.0, n: float = 2.0, param: str = "k",
        shape_scale: float = 1.0, gamma_lower: float | None = None,
    ) -> None:
        """``shape_scale`` sizes beta's and gamma's bounds (+-10 x it): they scale with
        displacement^-n, so a response in centimetres needs a larger range than one in metres.
        ``gamma_lower`` (default -10 x shape_scale) can keep beta + gamma > 0 (bounded z)."""
        self.k, self.beta, self.gamma, self.n, self.param = k, beta, gamma, n, param
        self.shape_scale = shape_scale
        self.gamma_lower = -10.0 * shape_scale if gamma_lower is None else gamma_lower
        self.linear = (param,)

    def specs(self):
        S = self.shape_scale
        return [
            ParamSpec(self.param, init=self.k, scale=self.k, true=self.k, unit="N/m"),
            ParamSpec("beta", init=self.beta, scale=S, true=self.beta, lower=0.0, upper=10.0 * S),
            ParamSpec("gamma", init=self.gamma, scale=S, true=self.gamma, lower=self.gamma_lower, upper=10.0 * S,
                      transform="box"),
            ParamSpec("n", init=self.n, scale=1.0, true=self.n, lower=0.5, upper=6.0, transform="box"),
        ]

    def force(self, t, x, v, z, p):
        return p[self.param] * z[..., 0]

    def latent_rate(self, t, x, v, z, p):
        z0 = z[..., 0]
        zn = _spow(z0, p["n"])
        sgn_z = z0 / _clamp_min(_abs(z0), 1e-12)
        rate = v - p["gamma"] * _abs(v) * zn * sgn_z - p["beta"] * v * zn
        return rate[..., None]

    def formula(self, p):
        return f"{p[self.param]:.5g} z"


class QuadraticStiffness(ForceTerm):
    """k2 x^2: a stiffness that differs in tension and compression (asymmetric)."""

    name = "quadratic_stiffness"
    linear = ("k2",)

    def __init__(self, k2: float = 10.0, scale: float | None = None) -> None:
        self.k2, self.scale = k2, scale

    def specs(self):
        s = self.scale or (abs(self.k2) or 1.0)
        return [ParamSpec("k2", init=self.k2, scale=s, true=self.k2, transform="identity", unit="N/m^2")]

    def force(self, t, x, v, z, p):
        return p["k2"] * x**2

    def formula(self, p):
        return f"{p['k2']:.5g} x^2"


class CoulombFriction(ForceTerm):
    """Fc sign(x'), smoothed as Fc tanh(x'/eps) so that integrators and gradients stay finite.

    ``eps`` (m/s) is fixed, not identified: a small fraction of the velocity scale.
    """

    name = "coulomb_friction"
    linear = ("Fc",)

    def __init__(self, Fc: float = 0.1, eps: float = 1e-3) -> None:
        if eps <= 0:
            raise ValueError(f"coulomb_friction: eps must be > 0, got {eps}")
        self.Fc, self.eps = Fc, eps

    def specs(self):
        return [ParamSpec("Fc", init=self.Fc, scale=self.Fc, true=self.Fc, unit="N")]

    def force(self, t, x, v, z, p):
        return p["Fc"] * _tanh(v / self.eps)

    def formula(self, p):
        return f"{p['Fc']:.5g} sign(x')"


class QuadraticDamping(ForceTerm):
    """c2 x'|x'|: drag-type damping that grows with the square of the velocity."""

    name = "quadratic_damping"
    linear = ("c2",)

    def __init__(self, c2: float = 0.5) -> None:
        self.c2 = c2

    def specs(self):
        return [ParamSpec("c2", init=self.c2, scale=self.c2, true=self.c2, unit="N s^2/m^2")]

    def force(self, t, x, v, z, p):
        return p["c2"] * v * _abs(v)

    def formula(self, p):
        return f"{p['c2']:.5g} x'|x'|"


class StiffnessLoss(ForceTerm):
    """-drop k x H(t - t_d): the stiffness ``k`` falls by the fraction ``drop`` at time t_d.

    Damage during the earthquake. The step is smoothed over ``tau`` seconds (a sigmoid) so
    that t_d has a gradient; ``stiffness`` names the nominal stiffness parameter it scales.
    """

    name = "stiffness_loss"

    def __init__(self, drop: float = 0.2, t_d: float = 10.0, t_min: float = 0.0, t_max: float = 40.0,
                 stiffness: str = "k", tau: float = 0.05) -> None:
        if not t_min < t_d < t_max:
            raise ValueError(f"stiffness_loss: t_d={t_d} outside ({t_min}, {t_max})")
        self.drop, self.t_d, self.t_min, self.t_max, self.stiffness, self.tau = drop, t_d, t_min, t_max, stiffness, tau

    def specs(self):
        return [
            ParamSpec("drop", init=self.drop, true=self.drop, transform="box", lower=0.0, upper=0.95),
            ParamSpec("t_d", init=self.t_d, true=self.t_d, transform="box", lower=self.t_min, upper=self.t_max,
                      unit="s"),
        ]

    def force(self, t, x, v, z, p):
        return -p["drop"] * p[self.stiffness] * x * _sigmoid((t - p["t_d"]) / self.tau)

    def formula(self, p):
        return f"- {p['drop']:.4g} {p[self.stiffness]:.5g} x H(t - {p['t_d']:.4g})"


class DampingChange(ForceTerm):
    """change c x' H(t - t_d): the damping ``c`` changes by the fraction ``change`` at t_d.

    Damage that opens cracks or loosens joints raises the dissipation (change > 0); a lost
    damper lowers it (change < 0). The step is smoothed over ``tau`` seconds as in
    :class:`StiffnessLoss`; ``damping`` names the nominal damping parameter it scales.
    """

    name = "damping_change"

    def __init__(self, change: float = 0.5, t_d: float = 10.0, t_min: float = 0.0, t_max: float = 40.0,
                 damping: str = "c", tau: float = 0.05) -> None:
        if not t_min < t_d < t_max:
            raise ValueError(f"damping_change: t_d={t_d} outside ({t_min}, {t_max})")
        if not -0.95 < change < 10.0:
            raise ValueError(f"damping_change: change={change} outside (-0.95, 10)")
        self.change, self.t_d, self.t_min, self.t_max, self.damping, self.tau = change, t_d, t_min, t_max, damping, tau

    def specs(self):
        return [
            ParamSpec("change", init=self.change, true=self.change, transform="box", lower=-0.95, upper=10.0),
            ParamSpec("t_d", init=self.t_d, true=self.t_d, transform="box", lower=self.t_min, upper=self.t_max,
                      unit="s"),
        ]

    def force(self, t, x, v, z, p):
        return p["change"] * p[self.damping] * v * _sigmoid((t - p["t_d"]) / self.tau)

    def formula(self, p):
        return f"+ {p['change']:.4g} {p[self.damping]:.5g} x' H(t - {p['t_d']:.4g})"


class GapContact(ForceTerm):
    """kg (|x| - gap)_+ sign(x): a symmetric stop that engages beyond a gap."""

    name = "gap_contact"
    linear = ("kg",)

    def __init__(self, kg: float = 50.0, gap: float = 0.05) -> None:
        self.kg, self.gap = kg, gap

    def specs(self):
        return [
            ParamSpec("kg", init=self.kg, scale=self.kg, true=self.kg, unit="N/m"),
            ParamSpec("gap", init=self.gap, scale=self.gap, true=self.gap, unit="m"),
        ]

    def force(self, t, x, v, z, p):
        return p["kg"] * (_relu(x - p["gap"]) - _relu(-x - p["gap"]))

    def formula(self, p):
        return f"{p['kg']:.5g} (|x| - {p['gap']:.4g})+ sign(x)"


TERMS: dict[str, type[ForceTerm]] = {
    cls.name: cls
    for cls in (ViscousDamping, LinearStiffness, CubicStiffness, BoucWenHysteresis, QuadraticStiffness,
                CoulombFriction, QuadraticDamping, StiffnessLoss, DampingChange, GapContact)
}
