"""Restoring-force terms: the building blocks of single-degree-of-freedom models.

A model is mass x acceleration + the sum of its terms = excitation force. Every term is one
small class: its parameters, its force (torch and NumPy through the same array code), its
regression columns (derived from the force) and, for hysteresis, the rate of its latent state.
Every force is written here once: the systems, the screening effects of the diagnosis
(``pidyn.discrepancy.effects``), the SINDy library and the hidden effects of the tests take their
forces and columns from these classes. A new force is one subclass here.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import torch

from pidyn.params import ParamSpec

Array = Any  # torch.Tensor or np.ndarray: the formulas below work on both


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
    shape = (*np.broadcast_shapes(*(np.shape(val) for val in values.values())), term.n_latent)

    def rate(ti, xi, vi, zi):
        return np.asarray(term.latent_rate(ti, xi, vi, zi, values), float).reshape(shape)

    return heun_along(rate, t, x, v, np.zeros(shape), substeps)


class ViscousDamping(ForceTerm):
    name = "viscous_damping"
    symbol = "x'"
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
    symbol = "x"

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
    symbol = "x^3"
    linear = ("k3",)

    def __init__(self, k3: float = 120.0, signed: bool = False) -> None:
        """``signed``: k3 may take either sign (hardening or softening is a finding, as when a
        diagnosis discovers the term); otherwise it is positive (a hardening Duffing spring)."""
        if not signed and k3 <= 0:
            raise ValueError(f"cubic_stiffness: k3={k3} is softening; use signed=True to allow k3 <= 0")
        self.k3, self.signed = k3, signed

    def specs(self):
        return [
            ParamSpec(
                "k3",
                init=self.k3,
                scale=abs(self.k3) or 1.0,
                true=self.k3,
                unit="N/m^3",
                transform="identity" if self.signed else "log",
            )
        ]

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
        self,
        k: float = 12.0,
        beta: float = 1.0,
        gamma: float = 2.0,
        n: float = 2.0,
        param: str = "k",
        shape_scale: float = 1.0,
        gamma_lower: float | None = None,
        beta_lower: float = 0.0,
    ) -> None:
        """``shape_scale`` sizes beta's and gamma's bounds (+-10 x it): they scale with
        displacement^-n, so a response in centimetres needs a larger range than one in metres.
        ``gamma_lower`` (default -10 x shape_scale) can keep beta + gamma > 0 (bounded z).
        ``beta_lower`` < 0 lets beta take either sign (a box transform): the Bouc-Wen
        benchmark's own x'|z|^n coefficient is negative, a hardening loop."""
        self.k, self.beta, self.gamma, self.n, self.param = k, beta, gamma, n, param
        self.shape_scale = shape_scale
        self.gamma_lower = -10.0 * shape_scale if gamma_lower is None else gamma_lower
        self.beta_lower = beta_lower
        self.linear = (param,)

    def specs(self):
        S = self.shape_scale
        signed = self.beta_lower < 0
        return [
            ParamSpec(self.param, init=self.k, scale=self.k, true=self.k, unit="N/m"),
            ParamSpec(
                "beta",
                init=self.beta,
                scale=S,
                true=self.beta,
                lower=self.beta_lower,
                upper=10.0 * S,
                transform="box" if signed else "log",
            ),
            ParamSpec(
                "gamma",
                init=self.gamma,
                scale=S,
                true=self.gamma,
                lower=self.gamma_lower,
                upper=10.0 * S,
                transform="box",
            ),
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
    symbol = "x^2"
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

    ``eps`` (m/s) is a small fraction of the velocity scale, fixed; with ``eps_range`` it is a
    parameter too, identified within that range: a width read from filtered, integrated drifts
    is off by a third, and a friction refined at such a width settled 23 % below its size.
    """

    name = "coulomb_friction"
    symbol = "sign x'"
    linear = ("Fc",)

    def __init__(
        self, Fc: float = 0.1, eps: float = 1e-3, eps_range: tuple[float, float] | None = None
    ) -> None:
        if eps <= 0:
            raise ValueError(f"coulomb_friction: eps must be > 0, got {eps}")
        if eps_range is not None and not 0 < eps_range[0] < eps < eps_range[1]:
            raise ValueError(f"coulomb_friction: eps {eps} must lie inside eps_range {eps_range}")
        self.Fc, self.eps, self.eps_range = Fc, eps, eps_range

    def specs(self):
        out = [ParamSpec("Fc", init=self.Fc, scale=self.Fc, true=self.Fc, unit="N")]
        if self.eps_range is not None:
            lo, hi = self.eps_range
            out.append(
                ParamSpec(
                    "eps", init=self.eps, scale=self.eps, transform="box", lower=lo, upper=hi, unit="m/s"
                )
            )
        return out

    def _eps(self, p) -> Any:
        return p["eps"] if "eps" in p else self.eps

    def force(self, t, x, v, z, p):
        return p["Fc"] * _tanh(v / self._eps(p))

    def measured_force(self, t, x, v, z, p, v_noise=0.0):
        # the expected sign of a noisy velocity is a smooth step about as wide as the noise
        return p["Fc"] * _tanh(v / _clamp_min(self._eps(p), 2.0 * v_noise))

    def formula(self, p):
        return f"{p['Fc']:.5g} sign(x')"


class QuadraticDamping(ForceTerm):
    """c2 x'|x'|: drag-type damping that grows with the square of the velocity."""

    name = "quadratic_damping"
    symbol = "x'|x'|"
    linear = ("c2",)

    def __init__(self, c2: float = 0.5) -> None:
        self.c2 = c2

    def specs(self):
        return [ParamSpec("c2", init=self.c2, scale=self.c2, true=self.c2, unit="N s^2/m^2")]

    def force(self, t, x, v, z, p):
        return p["c2"] * v * _abs(v)

    def formula(self, p):
        return f"{p['c2']:.5g} x'|x'|"


class Monomial(ForceTerm):
    """p x^i x'^j: a column of a polynomial library (SINDy's cross terms), no physical law of its
    own; the physical monomials (x, x', x^2, x^3) are their own terms."""

    def __init__(
        self, i: int, j: int, value: float = 0.0, param: str | None = None, scale: float = 1.0
    ) -> None:
        """``scale``: the coefficient's typical size, f / (x^i x'^j) in the record's units, so
        that a search over it is well conditioned."""
        if i < 0 or j < 0 or i + j == 0:
            raise ValueError(f"monomial: need powers i, j >= 0 and not both 0, got {i}, {j}")
        if not scale > 0:
            raise ValueError(f"monomial: scale must be > 0, got {scale}")
        self.i, self.j, self.value, self.scale = i, j, value, float(scale)
        self.param = param or f"p{i}{j}"
        self.name, self.linear = f"monomial_{i}_{j}", (self.param,)
        parts = [f"x^{i}" if i > 1 else "x"] * bool(i) + [f"x'^{j}" if j > 1 else "x'"] * bool(j)
        self.symbol = " ".join(parts)

    def specs(self):
        return [
            ParamSpec(self.param, init=self.value, scale=self.scale, true=self.value, transform="identity")
        ]

    def force(self, t, x, v, z, p):
        out = p[self.param]
        if self.i:
            out = out * x**self.i
        if self.j:
            out = out * v**self.j
        return out

    def formula(self, p):
        return f"{p[self.param]:.5g} {self.symbol}"


class StepInTime(ForceTerm):
    """A force that switches on at an unknown time t_d, smoothed over ``tau`` seconds (a sigmoid)
    so that t_d has a gradient, and kept inside (t_min, t_max): what every change in time
    shares."""

    def __init__(self, t_d: float, t_min: float, t_max: float, tau: float) -> None:
        if not t_min < t_d < t_max:
            raise ValueError(f"{self.name}: t_d={t_d} outside ({t_min}, {t_max})")
        self.t_d, self.t_min, self.t_max, self.tau = t_d, t_min, t_max, tau

    def _t_d_spec(self) -> ParamSpec:
        return ParamSpec(
            "t_d", init=self.t_d, true=self.t_d, transform="box", lower=self.t_min, upper=self.t_max, unit="s"
        )

    def _step(self, t: Array, p: dict) -> Array:
        return _sigmoid((t - p["t_d"]) / self.tau)


class StiffnessLoss(StepInTime):
    """-drop k x H(t - t_d): the stiffness ``k`` falls by the fraction ``drop`` at time t_d.

    Damage during the earthquake; ``stiffness`` names the nominal stiffness parameter it scales.
    """

    name = "stiffness_loss"

    def __init__(
        self,
        drop: float = 0.2,
        t_d: float = 10.0,
        t_min: float = 0.0,
        t_max: float = 40.0,
        stiffness: str = "k",
        tau: float = 0.05,
    ) -> None:
        super().__init__(t_d, t_min, t_max, tau)
        self.drop, self.stiffness = drop, stiffness

    def specs(self):
        return [
            ParamSpec("drop", init=self.drop, true=self.drop, transform="box", lower=0.0, upper=0.95),
            self._t_d_spec(),
        ]

    def force(self, t, x, v, z, p):
        return -p["drop"] * p[self.stiffness] * x * self._step(t, p)

    def formula(self, p):
        return f"- {p['drop']:.4g} {p[self.stiffness]:.5g} x H(t - {p['t_d']:.4g})"


class DampingChange(StepInTime):
    """change c x' H(t - t_d): the damping ``c`` changes by the fraction ``change`` at t_d.

    Damage that opens cracks or loosens joints raises the dissipation (change > 0); a lost
    damper lowers it (change < 0). ``damping`` names the nominal damping parameter it scales.
    """

    name = "damping_change"

    def __init__(
        self,
        change: float = 0.5,
        t_d: float = 10.0,
        t_min: float = 0.0,
        t_max: float = 40.0,
        damping: str = "c",
        tau: float = 0.05,
    ) -> None:
        super().__init__(t_d, t_min, t_max, tau)
        if not -0.95 < change < 10.0:
            raise ValueError(f"damping_change: change={change} outside (-0.95, 10)")
        self.change, self.damping = change, damping

    def specs(self):
        return [
            ParamSpec("change", init=self.change, true=self.change, transform="box", lower=-0.95, upper=10.0),
            self._t_d_spec(),
        ]

    def force(self, t, x, v, z, p):
        return p["change"] * p[self.damping] * v * self._step(t, p)

    def formula(self, p):
        return f"+ {p['change']:.4g} {p[self.damping]:.5g} x' H(t - {p['t_d']:.4g})"


def _inside(value: float, lo: float, hi: float) -> float:
    """``value`` moved just inside (lo, hi): a box parameter's start must lie strictly within."""
    margin = 1e-6 * (hi - lo)
    return float(min(max(float(value), lo + margin), hi - margin))


class AmplitudeSoftening(ForceTerm):
    """- soft k e x + gain c e x': a stiffness that falls and a damping that rises with the
    response's recent amplitude e, and recover as it decays (soil at a bridge's abutments that
    softens in strong shaking and stiffens again in the coda; an equivalent-linear structure
    whose amplitude is a state, not a choice made per record).

    e' = (A / a_ref - e) / tau, with A = sqrt(x^2 + (x' / w0)^2) the oscillation's amplitude at
    the nominal circular frequency w0 (smooth; |x| ripples at twice the frequency) and ``a_ref``
    a typical amplitude of the record, so that e is about 1 in the strongest shaking and ``soft``
    and ``gain`` are the shares by which k and c have changed there."""

    name = "amplitude_softening"
    n_latent = 1
    linear = ("soft", "gain")

    def __init__(
        self,
        soft: float = 0.1,
        gain: float = 0.1,
        tau: float = 2.0,
        a_ref: float = 1.0,
        w0: float = 1.0,
        stiffness: str = "k",
        damping: str = "c",
        tau_range: tuple[float, float] = (0.05, 60.0),
    ) -> None:
        if not (a_ref > 0 and w0 > 0):
            raise ValueError(f"{self.name}: a_ref and w0 must be > 0, got {a_ref}, {w0}")
        self.tau_range = (float(tau_range[0]), float(tau_range[1]))
        # a fit that ended on a bound starts the next one just inside it (a box needs init inside)
        self.soft = _inside(soft, -0.5, 0.95)
        self.gain = _inside(gain, -0.9, 10.0)
        self.tau = _inside(tau, *self.tau_range)
        self.a_ref, self.w0 = float(a_ref), float(w0)
        self.stiffness, self.damping = stiffness, damping

    def specs(self):
        lo, hi = self.tau_range
        return [  # the bounds here are _inside's in __init__
            ParamSpec("soft", init=self.soft, true=self.soft, transform="box", lower=-0.5, upper=0.95),
            ParamSpec("gain", init=self.gain, true=self.gain, transform="box", lower=-0.9, upper=10.0),
            ParamSpec("tau", init=self.tau, true=self.tau, transform="box", lower=lo, upper=hi, unit="s"),
        ]

    def force(self, t, x, v, z, p):
        e = z[..., 0]
        return -p["soft"] * p[self.stiffness] * e * x + p["gain"] * p[self.damping] * e * v

    def at_envelope(self, p: dict, e: Array) -> tuple[Array, Array]:
        """The structure's stiffness and damping where the envelope is ``e``: k (1 - soft e) and
        c (1 + gain e), what an equivalent-linear model at that amplitude would have."""
        return p[self.stiffness] * (1 - p["soft"] * e), p[self.damping] * (1 + p["gain"] * e)

    def latent_rate(self, t, x, v, z, p):
        amp = (x * x + (v / self.w0) ** 2 + (1e-9 * self.a_ref) ** 2) ** 0.5
        return ((amp / self.a_ref - z[..., 0]) / p["tau"])[..., None]

    def formula(self, p):
        return (
            f"- {p['soft']:.4g} {p[self.stiffness]:.5g} e x + {p['gain']:.4g} {p[self.damping]:.5g} e x'"
            f" (e' = (A/{self.a_ref:.3g} - e)/{p['tau']:.3g})"
        )


class GapContact(ForceTerm):
    """kg (|x| - gap)_+ sign(x): a symmetric stop that engages beyond a gap."""

    name = "gap_contact"
    linear = ("kg",)
    proportional = True

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


class TrilinearSpring(ForceTerm):
    """dk1 (|x| - x1)+ sign(x) + dk2 (|x| - x2)+ sign(x): the stiffness changes at |x| = x1 and
    again at x2 (softening at first yield, hardening at a stop). Not in the discrepancy library:
    it hides an effect the library cannot name."""

    name = "trilinear_spring"
    linear = ("dk1", "dk2")

    def __init__(self, dk1: float = -5.0, x1: float = 0.03, dk2: float = 10.0, x2: float = 0.06) -> None:
        if not 0 < x1 < x2:
            raise ValueError(f"trilinear_spring: need 0 < x1 < x2, got x1={x1}, x2={x2}")
        self.dk1, self.x1, self.dk2, self.x2 = dk1, x1, dk2, x2

    def specs(self):
        return [
            ParamSpec("dk1", init=self.dk1, scale=abs(self.dk1) or 1.0, true=self.dk1, transform="identity"),
            ParamSpec("dk2", init=self.dk2, scale=abs(self.dk2) or 1.0, true=self.dk2, transform="identity"),
            ParamSpec("x1", init=self.x1, scale=self.x1, true=self.x1, trainable=False, unit="m"),
            ParamSpec("x2", init=self.x2, scale=self.x2, true=self.x2, trainable=False, unit="m"),
        ]

    def force(self, t, x, v, z, p):
        return p["dk1"] * (_relu(x - p["x1"]) - _relu(-x - p["x1"])) + p["dk2"] * (
            _relu(x - p["x2"]) - _relu(-x - p["x2"])
        )

    def formula(self, p):
        return (
            f"{p['dk1']:.5g} (|x| - {p['x1']:.4g})+ sign(x) + {p['dk2']:.5g} (|x| - {p['x2']:.4g})+ sign(x)"
        )


class StribeckFriction(ForceTerm):
    """(Fc + (Fs - Fc) exp(-(x'/vs)^2)) sign(x'): dry friction whose static level Fs exceeds the
    sliding level Fc (the Stribeck drop at low speed). Not in the discrepancy library."""

    name = "stribeck_friction"

    def __init__(self, Fc: float = 0.1, Fs: float = 0.25, vs: float = 0.02, eps: float = 1e-3) -> None:
        self.Fc, self.Fs, self.vs, self.eps = Fc, Fs, vs, eps

    def specs(self):
        return [
            ParamSpec("Fc", init=self.Fc, scale=self.Fc, true=self.Fc, unit="N"),
            ParamSpec("Fs", init=self.Fs, scale=self.Fs, true=self.Fs, unit="N"),
            ParamSpec("vs", init=self.vs, scale=self.vs, true=self.vs, trainable=False, unit="m/s"),
        ]

    def force(self, t, x, v, z, p):
        level = p["Fc"] + (p["Fs"] - p["Fc"]) * _exp(-((v / p["vs"]) ** 2))
        return level * _tanh(v / self.eps)

    def formula(self, p):
        return f"({p['Fc']:.4g} + ({p['Fs']:.4g} - {p['Fc']:.4g}) exp(-(x'/{p['vs']:.3g})^2)) sign(x')"


class LearnedForce(ForceTerm):
    """f(x, x') by a small network inside the equation of motion: a universal differential
    equation. What the diagnosis adds when the residual force is clearly structured but no
    library effect explains it. Its weights are trained in PIDynNet's physics loss (they sit
    with the networks' parameters); the last layer starts at zero, so the extension starts
    as the nominal model. Inputs and output are scaled by the record's x, x' and force scales."""

    name = "learned_force"

    def __init__(
        self,
        x_scale: float = 1.0,
        v_scale: float = 1.0,
        f_scale: float = 1.0,
        hidden: int = 24,
        depth: int = 2,
        seed: int = 0,
    ) -> None:
        from torch import nn

        self.x_scale, self.v_scale, self.f_scale = float(x_scale), float(v_scale), float(f_scale)
        gen = torch.random.fork_rng()
        with gen:
            torch.manual_seed(seed)
            layers: list[nn.Module] = []
            d = 2
            for _ in range(depth):
                layers += [nn.Linear(d, hidden), nn.Tanh()]
                d = hidden
            layers.append(nn.Linear(d, 1))
            self.net = nn.Sequential(*layers)
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def specs(self):
        return []

    def fit_to(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, iters: int = 300) -> float:
        """Start the network at a force measured pointwise (the force the model could not
        explain), by L-BFGS on all samples; returns the relative RMS misfit."""
        dtype = self.net[0].weight.dtype
        u = torch.as_tensor(np.stack([x / self.x_scale, v / self.v_scale], -1), dtype=dtype)
        target = torch.as_tensor(f / self.f_scale, dtype=dtype)
        opt = torch.optim.LBFGS(
            self.net.parameters(),
            lr=1.0,
            max_iter=iters,
            line_search_fn="strong_wolfe",
            tolerance_grad=1e-12,
            tolerance_change=1e-14,
        )

        def closure():
            opt.zero_grad()
            loss = ((self.net(u)[..., 0] - target) ** 2).mean()
            loss.backward()
            return loss

        opt.step(closure)
        with torch.no_grad():
            return float(
                ((self.net(u)[..., 0] - target) ** 2).mean().sqrt()
                / target.pow(2).mean().sqrt().clamp_min(1e-300)
            )

    def force(self, t, x, v, z, p):
        if isinstance(x, torch.Tensor):
            u = torch.stack([x / self.x_scale, v / self.v_scale], dim=-1)
            dtype = self.net[0].weight.dtype
            # a float64 solve (the drift of an accelerometer record) through a float32 network: evaluated in the
            # network's precision, returned in the caller's
            return self.net(u.to(dtype))[..., 0].to(u.dtype) * self.f_scale
        u = np.stack([x / self.x_scale, v / self.v_scale], axis=-1)
        layers = self._numpy_layers()  # the same weights, evaluated in NumPy for simulations
        for i, (w, b) in enumerate(layers):
            u = u @ w + b
            if i < len(layers) - 1:  # Linear, Tanh, ..., Linear
                u = np.tanh(u)
        return u[..., 0] * self.f_scale

    def _numpy_layers(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The linear layers' (W^T, b) in float64, converted again only when training has changed
        them (an integrator asks at every step)."""
        linear = [m for m in self.net if isinstance(m, torch.nn.Linear)]
        key = tuple((id(q), q._version) for m in linear for q in (m.weight, m.bias))
        cached = getattr(self, "_numpy_cache", None)
        if cached is None or cached[0] != key:
            self._numpy_cache = (
                key,
                [
                    (
                        m.weight.detach().cpu().double().numpy().copy().T,
                        m.bias.detach().cpu().double().numpy().copy(),
                    )
                    for m in linear
                ],
            )
        return self._numpy_cache[1]

    def formula(self, p):
        return "f_NN(x, x')"


TERMS: dict[str, type[ForceTerm]] = {
    cls.name: cls
    for cls in (
        ViscousDamping,
        LinearStiffness,
        CubicStiffness,
        BoucWenHysteresis,
        QuadraticStiffness,
        CoulombFriction,
        QuadraticDamping,
        StiffnessLoss,
        DampingChange,
        GapContact,
        TrilinearSpring,
        StribeckFriction,
        AmplitudeSoftening,
        LearnedForce,
    )
}
