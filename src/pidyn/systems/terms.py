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


def _sigmoid(x: Array) -> Array:
    return torch.sigmoid(x) if isinstance(x, torch.Tensor) else 0.5 * (1 + np.tanh(0.5 * x))


def _spow(z: Array, n: Array) -> Array:
    """|z|^n, with a floor so that the gradient stays finite at z = 0 for any n > 0."""
    if isinstance(z, torch.Tensor):
        return z.abs().clamp_min(1e-12) ** n
    return np.maximum(np.abs(z), 1e-12) ** n


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

    def __init__(self, k3: float = 120.0) -> None:
        self.k3 = k3

    def specs(self):
        return [ParamSpec("k3", init=self.k3, scale=abs(self.k3), true=self.k3, unit="N/m^3")]

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
        self, k: float = 12.0, beta: float = 1.0, gamma: float = 2.0, n: float = 2.0, param: str = "k"
    ) -> None:
        self.k, self.beta, self.gamma, self.n, self.param = k, beta, gamma, n, param
        self.linear = (param,)

    def specs(self):
        return [
            ParamSpec(self.param, init=self.k, scale=self.k, true=self.k, unit="N/m"),
            ParamSpec("beta", init=self.beta, scale=1.0, true=self.beta, lower=0.0, upper=10.0),
            ParamSpec("gamma", init=self.gamma, scale=1.0, true=self.gamma, lower=-10.0, upper=10.0,
                      transform="box"),
            ParamSpec("n", init=self.n, scale=1.0, true=self.n, lower=0.5, upper=6.0, transform="box"),
        ]

    def force(self, t, x, v, z, p):
        return p[self.param] * z[..., 0]

    def latent_rate(self, t, x, v, z, p):
        z0 = z[..., 0]
        zn = _spow(z0, p["n"])
        sgn_z = z0 / _abs(z0).clip(1e-12) if isinstance(z0, np.ndarray) else z0 / z0.abs().clamp_min(1e-12)
        rate = v - p["gamma"] * _abs(v) * zn * sgn_z - p["beta"] * v * zn
        return rate[..., None]

    def formula(self, p):
        return f"{p[self.param]:.5g} z"


TERMS: dict[str, type[ForceTerm]] = {
    cls.name: cls for cls in (ViscousDamping, LinearStiffness, CubicStiffness, BoucWenHysteresis)
}
