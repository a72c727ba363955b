"""What every restoring-force term is (``ForceTerm``), the array helpers its formulas share
(the same code on torch tensors and NumPy arrays), and the integration of a latent state along
a given motion."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import torch

from pidyn.compiled import kernel
from pidyn.params import ParamSpec

Array = Any  # torch.Tensor or np.ndarray: the formulas below work on both


def signed_sum(parts: list[str]) -> str:
    """Written terms joined into one sum that reads as written by hand: a term that carries its
    own sign ("- 0.5 k e x", "-2.4 vg") is joined by that sign, not by "+ -"."""
    out = ""
    for part in parts:
        part = part.strip()
        sign, body = "+", part
        if part[:2] in ("- ", "+ "):
            sign, body = part[0], part[2:]
        elif part[:1] == "-" and part[1:2].isdigit():
            sign, body = "-", part[1:]
        if not out:
            out = body if sign == "+" else f"-{body}"
        else:
            out += f" {sign} {body}"
    return out


def _abs(x: Array) -> Array:
    return x.abs() if isinstance(x, torch.Tensor) else np.abs(x)


def _tanh(x: Array) -> Array:
    return torch.tanh(x) if isinstance(x, torch.Tensor) else np.tanh(x)


def _exp(x: Array) -> Array:
    return torch.exp(x) if isinstance(x, torch.Tensor) else np.exp(x)


def _relu(x: Array) -> Array:
    return torch.relu(x) if isinstance(x, torch.Tensor) else np.maximum(x, 0.0)


def _clamp_min(x: Array, lo: float) -> Array:
    return x.clamp_min(lo) if isinstance(x, torch.Tensor) else np.maximum(x, lo)


def _sigmoid(x: Array) -> Array:
    return torch.sigmoid(x) if isinstance(x, torch.Tensor) else 0.5 * (1 + np.tanh(0.5 * x))


def _spow(z: Array, n: Array) -> Array:
    """|z|^n, with a floor so that the gradient stays finite at z = 0 for any n > 0."""
    return _clamp_min(_abs(z), 1e-12) ** n


class ForceTerm(ABC):
    """One additive restoring-force term f(t, x, v, z; p).

    A subclass defines ``specs`` (its parameters), ``force`` and ``formula``; a term with a
    latent state (``n_latent`` > 0) defines ``latent_rate`` too, checked when the class is made.
    ``linear`` names the parameters the force is linear in: ``columns`` then gives a regression
    its columns without another formula."""

    name: str = "term"
    n_latent: int = 0
    linear: tuple[str, ...] = ()  # parameters the force is linear in
    #: the force is proportional to its one linear parameter at fixed other parameters (a
    #: screening refits that coefficient with the nominal ones, the others held)
    proportional: bool = False
    #: the term's column as a regression library names it (``x^3``); empty for a term that has none
    symbol: str = ""
    #: in a storey or at a support, the term is the spring itself (its stiffness the place's k,
    #: in place of the linear spring) rather than a force beside it
    is_the_spring: bool = False

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if cls.__dict__.get("n_latent", 0) and "latent_rate" not in cls.__dict__:
            raise TypeError(f"{cls.__name__} has a latent state (n_latent > 0) but no latent_rate")

    @abstractmethod
    def specs(self) -> list[ParamSpec]:
        """The term's parameters, with their starts, scales, transforms and units."""

    @abstractmethod
    def force(self, t: Array, x: Array, v: Array, z: Array | None, p: dict) -> Array:
        """The restoring force at time ``t``, displacement ``x``, velocity ``v``, latent ``z``."""

    @abstractmethod
    def formula(self, p: dict[str, float]) -> str:
        """The term as it is printed in an identified equation, at the values ``p``."""

    def measured_force(
        self, t: Array, x: Array, v: Array, z: Array | None, p: dict, v_noise: float = 0.0
    ) -> Array:
        """The force along a measured velocity that still holds noise of std ``v_noise``: what a
        regression on measured signals must use. The same as ``force`` unless the force turns
        sharply with the velocity (dry friction), where noise flips its sign near rest."""
        return self.force(t, x, v, z, p)

    def columns(
        self, t: Array, x: Array, v: Array, z: Array | None, p: dict, v_noise: float | None = None
    ) -> dict[str, Array]:
        """The force per unit of each ``linear`` parameter (the other parameters at ``p``): the
        term's columns in a regression. ``v_noise``: along a measured velocity (``measured_force``)."""
        zero = {n: 0.0 for n in self.linear}
        if v_noise is None:
            return {n: self.force(t, x, v, z, {**p, **zero, n: 1.0}) for n in self.linear}
        return {n: self.measured_force(t, x, v, z, {**p, **zero, n: 1.0}, v_noise) for n in self.linear}

    def latent_rate(self, t: Array, x: Array, v: Array, z: Array, p: dict) -> Array:
        """dz/dt of the latent state (terms with ``n_latent`` > 0 only)."""
        raise NotImplementedError(f"{type(self).__name__} has no latent state")


def heun_along(
    rate, t: np.ndarray, x: np.ndarray, v: np.ndarray | None, z0: np.ndarray, substeps: int = 4
) -> np.ndarray:
    """A latent state integrated along a given motion (Heun's rule, x and x' interpolated
    linearly between samples): the one z integrator of the package. ``rate(t, x, v, z)`` gives
    dz/dt in ``z0``'s shape; returns (N, *z0.shape). A path that blows up is NaN from there on.

    ``v=None``: along the displacement path alone, the velocity on each interval its chord's
    (x[i+1] - x[i]) / dt. For a rate-independent law (Bouc-Wen) z then depends on the increments
    of x only, whatever a smoothed or noisy velocity says."""
    along_x = v is None
    if along_x:
        v = np.diff(x, axis=0) / np.reshape(np.diff(t), (-1,) + (1,) * (np.ndim(x) - 1))
    z = np.zeros((len(t), *np.shape(z0)))
    zi = np.array(z0, dtype=float)
    z[0] = zi
    for i in range(len(t) - 1):
        h = (t[i + 1] - t[i]) / substeps
        for j in range(substeps):
            a, b = j / substeps, (j + 1) / substeps
            x0, x1 = x[i] + a * (x[i + 1] - x[i]), x[i] + b * (x[i + 1] - x[i])
            if along_x:  # the chord's velocity holds on the whole interval
                v0 = v1 = v[i]
            else:
                v0, v1 = v[i] + a * (v[i + 1] - v[i]), v[i] + b * (v[i + 1] - v[i])
            k1 = rate(t[i], x0, v0, zi)
            zi = zi + 0.5 * h * (k1 + rate(t[i], x1, v1, zi + h * k1))
        z[i + 1] = zi
    return z


def latent_path(
    term: ForceTerm,
    t: np.ndarray,
    x: np.ndarray,
    v: np.ndarray | None,
    values: dict[str, Any],
    substeps: int = 4,
) -> np.ndarray:
    """A term's latent state along a given motion from zero (``heun_along``; ``v=None``: along
    the displacement path alone): what the term's z was, given the motion the structure made.
    ``values`` may hold (P,) arrays (P parameter sets at once): z is then (N, P, n_latent), else
    (N, n_latent)."""
    fast = kernel.latent_path(term, t, x, v, values, substeps)  # the same operations, in C
    if fast is not None:
        return fast
    shape = (*np.broadcast_shapes(*(np.shape(val) for val in values.values())), term.n_latent)

    def rate(ti, xi, vi, zi):
        return np.asarray(term.latent_rate(ti, xi, vi, zi, values), float).reshape(shape)

    return heun_along(rate, t, x, v, np.zeros(shape), substeps)
