"""Single-degree-of-freedom systems assembled from restoring-force terms.

    m x'' + sum_i f_i(t, x, x', z) = -m ag(t)   (ground excitation)
                                   =  u(t)      (applied force)

Several ground inputs (a deck on supports that move differently), each support a spring k_j
and a dashpot c_j: m x_abs'' + sum_j c_j (x_abs' - u_j') + k_j (x_abs - u_j) = 0. In the motion
relative to the supports' weighted motion, x = x_abs - sum_j r_j u_j with r_j = k_j / k:

    m x'' + c x' + k x + (terms) = -m sum_j r_j ag_j + sum_j g_j u_j'

with one influence coefficient ``r_<input>`` per support (about 1 in all when they move
together) and ``g_<input>`` = c_j - c r_j, the support's damping beyond its share (zero when
every support damps in proportion to its stiffness). Support j's own spring and dashpot are
k_j = r_j k and c_j = g_j + r_j c (``support_params``). The accelerometer reads
x'' + sum_j (r_j + e_j) ag_j: ``e_<input>`` is what it takes from a support directly, the modes
above the model's that move with the supports (the residual of a truncated modal model).
With r, g and e a single degree of freedom spans every second-order response of one output
to the supports' accelerations, the class of a state-space realization of order 2.

The Bouc-Wen case of the paper (Eq. 16) prints ``-ag`` on the right-hand side without m.
That is the same equation only when m = 1; with a known m != 1 no parameter set would zero
the residual. We write ``-m ag`` (Newton's law for a base-excited mass), which reduces to
the paper's form for its m = 1 examples.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch

from pidyn.params import ParamSpec
from pidyn.systems.base import ExcitationKind, Kinematics, StructuralSystem, merge_specs, stack_last
from pidyn.systems.modal import damping_params, stiffness_params
from pidyn.systems.terms import (
    AmplitudeSoftening,
    BoucWenHysteresis,
    CubicStiffness,
    ForceTerm,
    LinearStiffness,
    ViscousDamping,
    signed_sum,
)


class SDOFSystem(StructuralSystem):
    """A mass with additive restoring-force terms; named residuals ``motion`` + one per latent term."""

    def __init__(
        self,
        terms: Sequence[ForceTerm],
        mass: float = 1.0,
        identify_mass: bool = False,
        excitation: ExcitationKind = "ground",
        params: dict | None = None,
        name: str = "sdof",
        inputs: Sequence[str] | None = None,
    ) -> None:
        super().__init__(excitation)
        self.name = name
        self.terms = list(terms)
        self.mass = mass
        self.identify_mass = identify_mass
        self.inputs = tuple(str(i) for i in (inputs or ()))
        if len(self.inputs) == 1:
            self.inputs = ()  # one input is the plain ag (no influence coefficient to identify)
        if self.inputs and excitation != "ground":
            raise ValueError(
                f"{name}: several inputs are ground motions (supports); got excitation '{excitation}'"
            )
        if len(set(self.inputs)) != len(self.inputs):
            raise ValueError(f"{name}: input names repeat: {list(self.inputs)}")
        if identify_mass and excitation == "ground":
            raise ValueError(
                f"{name}: the mass cannot be identified under ground excitation "
                "(m x'' + ... = -m ag is homogeneous in m); give it, or scale all parameters by it"
            )
        defaults = [ParamSpec("m", init=mass, scale=mass, true=mass, trainable=identify_mass, unit="kg")]
        for term in self.terms:
            defaults += term.specs()
        share = 1.0 / max(len(self.inputs), 1)
        defaults += [
            ParamSpec(influence_name(i), init=share, scale=share, transform="identity", unit="-")
            for i in self.inputs
        ]
        c0 = float(next((sp.init for sp in defaults if sp.name == "c"), 1.0))
        defaults += [
            ParamSpec(
                support_damping_name(i),
                init=0.0,
                scale=max(abs(c0), 1e-6) * share,
                transform="identity",
                true=0.0,
                unit="N s/m",
            )
            for i in self.inputs
        ]
        defaults += [
            ParamSpec(
                feedthrough_name(i), init=0.0, scale=0.1 * share, transform="identity", true=0.0, unit="-"
            )
            for i in self.inputs
        ]
        self._specs = merge_specs(defaults, params)
        self.n_latent = sum(t.n_latent for t in self.terms)
        self.latent_names = tuple(t.name for t in self.terms if t.n_latent)

    def param_specs(self) -> list[ParamSpec]:
        return list(self._specs)

    def with_term(self, term: ForceTerm, name: str | None = None, params: dict | None = None) -> SDOFSystem:
        """This model plus one more force term (a discovered effect); the existing parameter
        specs (their initial values included) are kept, ``params`` overrides any of them."""
        new = SDOFSystem(
            self.terms + [term],
            mass=self.mass,
            excitation=self.excitation,
            name=name or f"{self.name}+{term.name}",
            inputs=self.inputs,
        )
        new.identify_mass = self.identify_mass
        new._specs = merge_specs(list(self._specs) + merge_specs(term.specs(), None), params)
        return new

    @property
    def linear_time_invariant(self) -> bool:
        return not self.n_latent and all(type(t) in (ViscousDamping, LinearStiffness) for t in self.terms)

    def period_scaling(self) -> dict[str, float]:
        if not self.linear_time_invariant:
            return {}
        out = {s.name: (1.0 if isinstance(t, ViscousDamping) else 2.0) for t in self.terms for s in t.specs()}
        return out | {support_damping_name(i): 1.0 for i in self.inputs}

    def linear_params(self) -> list[str]:
        # the influence coefficients are linear in the residual too, but a start from a network that
        # fits absolute accelerations pins them poorly: the data start and the refinement estimate them
        names = [n for t in self.terms for n in t.linear]
        if self.identify_mass:
            names.insert(0, "m")
        return [n for n in names if any(s.name == n and s.trainable for s in self._specs)]

    def _latent_slices(self) -> list[slice | None]:
        key = tuple(map(id, self.terms))
        cached = getattr(self, "_slices", None)
        if cached is not None and cached[0] == key:  # an integrator asks at every step
            return cached[1]
        out, i = [], 0
        for t in self.terms:
            if t.n_latent:
                out.append(slice(i, i + t.n_latent))
                i += t.n_latent
            else:
                out.append(None)
        self._slices = (key, out)
        return out

    def restoring_force(self, t, x, v, z, p):
        return self._restoring(t, x, v, z, p, self._latent_slices())

    def _restoring(self, t, x, v, z, p, slices):
        total = None  # the first term's force, not 0.0 + it: one array operation fewer per term set
        for term, sl in zip(self.terms, slices):
            force = term.force(t, x, v, None if sl is None else z[..., sl], p)
            total = force if total is None else total + force
        return 0.0 if total is None else total

    def forcing(self, f, p):
        """Right-hand-side force from the excitation signal (several supports: their weighted
        accelerations, and the velocities of the supports that damp beyond their share)."""
        if self.excitation != "ground":
            return f
        if not self.inputs:
            return -p["m"] * f
        out = -p["m"] * self.ground_input(f, p)
        n = len(self.inputs)
        for j, name in enumerate(self.inputs):
            out = out + p[support_damping_name(name)] * f[..., n + j]
        return out

    @property
    def stiffness_name(self) -> str:
        """The parameter that is this model's stiffness about rest (a linear spring's k or k1, a
        Bouc-Wen spring's k): what a stiffness loss scales and a period is read from."""
        names = stiffness_params(self)
        if not names:
            raise ValueError(f"nominal system '{self.name}' has no linear stiffness to extend")
        return names[0]

    def ground_input(self, f, p):
        """The ground acceleration the mass feels: ag, or sum_j r_j ag_j (``f[..., j]``) for several inputs."""
        if not self.inputs:
            return f
        total = None
        for j, name in enumerate(self.inputs):
            part = p[influence_name(name)] * f[..., j]
            total = part if total is None else total + part
        return total

    def support_params(self, p: dict[str, float]) -> dict[str, dict[str, float]]:
        """Each support's own spring and dashpot per unit mass: k_j = r_j k, c_j = g_j + r_j c."""
        k = sum(float(p[n]) for n in stiffness_params(self))
        c = sum(float(p[n]) for n in damping_params(self))
        return {
            i: {
                "k": float(p[influence_name(i)]) * k,
                "c": float(p[support_damping_name(i)]) + float(p[influence_name(i)]) * c,
            }
            for i in self.inputs
        }

    def ground_motion(self, f, p):
        return self.ground_input(f, p)[..., None]

    def acceleration_output(self, a_rel, f, p):
        """The accelerometer's reading: x'' + sum_j (r_j + e_j) ag_j for several supports."""
        if not self.inputs:
            return a_rel
        out = a_rel + self.ground_motion(f, p)
        for j, name in enumerate(self.inputs):
            out = out + (p[feedthrough_name(name)] * f[..., j])[..., None]
        return out

    def residual(self, k: Kinematics, f: torch.Tensor, p: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        x, v, a = k.x[:, 0], k.v[:, 0], k.a[:, 0]
        if self.n_latent and k.z is None:
            raise ValueError(f"{self.name}: latent state z is required (n_latent={self.n_latent})")
        out = {"motion": (p["m"] * a + self.restoring_force(k.t, x, v, k.z, p) - self.forcing(f, p))[:, None]}
        for term, sl in zip(self.terms, self._latent_slices()):
            if sl is not None:
                assert k.z is not None and k.zd is not None
                out[term.name] = k.zd[:, sl] - term.latent_rate(k.t, x, v, k.z[:, sl], p)
        return out

    def state_rate(self, t, y, p, f):
        if not self.n_latent and type(y) is np.ndarray and y.ndim == 2:  # an integrator's batch of plain
            v = y[:, 1]  # states without latent ones (most of a diagnosis's time): no checks, no list
            a = (self.forcing(f, p) - self._restoring(t, y[:, 0], v, None, p, self._latent_slices())) / p["m"]
            if type(a) is np.ndarray:
                out = np.empty(y.shape)
                out[:, 0], out[:, 1] = v, a
                return out
        plain = isinstance(y, np.ndarray) and y.ndim == 1
        if plain:  # one plain state (an integrator's step): scalars, not 0-d arrays, so the rate is built
            x, v, z = y[0], y[1], y[2:]  # without np.stack
        else:  # a batch, or dual numbers (sensitivities): np.stack dispatches to them
            x, v, z = y[..., 0], y[..., 1], y[..., 2:]
        slices = self._latent_slices()
        a = (self.forcing(f, p) - self._restoring(t, x, v, z, p, slices)) / p["m"]
        parts = [v, a]
        if self.n_latent:
            for term, sl in zip(self.terms, slices):
                if sl is not None:
                    rate = term.latent_rate(t, x, v, z[..., sl], p)
                    parts += [rate[..., j] for j in range(term.n_latent)]
        if plain and all(
            isinstance(q, (float, np.floating)) or (isinstance(q, np.ndarray) and q.ndim == 0) for q in parts
        ):
            return np.array([float(q) for q in parts])
        if isinstance(y, np.ndarray) and all(type(q) is np.ndarray for q in parts):  # a plain batch: filled,
            out = np.empty(y.shape[:-1] + (len(parts),))  # not np.stack (a third of a batched step's cost)
            for j, q in enumerate(parts):
                out[..., j] = q
            return out
        return stack_last(parts, parts[0])

    def rhs(self, t: float, y: np.ndarray, p: dict[str, float], f: Callable[[float], float]) -> np.ndarray:
        return self.state_rate(t, np.asarray(y, dtype=float), p, f(t))

    def describe(self, p: dict[str, float]) -> str:
        lhs = signed_sum([f"{p['m']:.5g} x''", *(t.formula(p) for t in self.terms)])
        rhs = f"-{p['m']:.5g} ag(t)" if self.excitation == "ground" else "u(t)"
        if self.inputs:
            drive = signed_sum([f"{p[influence_name(i)]:.4g} ag_{i}(t)" for i in self.inputs])
            dashpots = [f"{p[support_damping_name(i)]:.4g} vg_{i}(t)" for i in self.inputs]
            sensor = [f"{p[influence_name(i)] + p[feedthrough_name(i)]:.4g} ag_{i}(t)" for i in self.inputs]
            rhs = (
                signed_sum([f"-{p['m']:.5g} ({drive})", *dashpots])
                + "; sensor: "
                + signed_sum(["x''", *sensor])
            )
        eqs = [f"{lhs} = {rhs}"]
        for t in self.terms:
            if isinstance(t, BoucWenHysteresis):
                g, b, n = p["gamma"], p["beta"], p["n"]
                eqs.append(
                    f"z' = x' {'-' if g >= 0 else '+'} {abs(g):.5g} |x'| |z|^({n:.5g}-1) z "
                    f"{'-' if b >= 0 else '+'} {abs(b):.5g} x' |z|^{n:.5g}"
                )
        return "; ".join(eqs)


def influence_name(input_name: str) -> str:
    """The parameter name of an input's influence coefficient (``r_ch3`` for input ``ch3``)."""
    return f"r_{input_name}"


def feedthrough_name(input_name: str) -> str:
    """The parameter name of what the accelerometer reads of a support directly (``e_ch3``)."""
    return f"e_{input_name}"


def support_damping_name(input_name: str) -> str:
    """The parameter name of a support's damping beyond its share (``g_ch3``)."""
    return f"g_{input_name}"


def LinearSDOF(c: float = 0.5, k: float = 15.0, **kw) -> SDOFSystem:
    """m x'' + c x' + k x = -m ag (paper Eq. 6)."""
    return SDOFSystem([ViscousDamping(c), LinearStiffness(k)], name=kw.pop("name", "linear_sdof"), **kw)


def AmplitudeDependent(
    c: float = 2.0,
    k: float = 600.0,
    soft: float = 0.2,
    gain: float = 1.0,
    tau: float = 2.0,
    a_ref: float = 0.005,
    w0: float = 25.0,
    law: str = "bounded",
    shape: float = 1.0,
    **kw,
) -> SDOFSystem:
    """m x'' + c (1 + gain e) x' + k (1 - soft e) x = -m ag, e' = (A / a_ref - e) / tau: a stiffness
    that falls and a damping that rises with the response's recent amplitude e (``AmplitudeSoftening``),
    one model for a structure's weak and strong earthquakes. ``a_ref`` (m) and ``w0`` (rad/s) are the
    structure's scale (a typical response amplitude, the nominal circular frequency), not identified.
    The default ``law="bounded"`` softens as k / (1 + soft e): never a negative stiffness on a record
    stronger than those it was fitted on (``law="linear"``: k (1 - soft e); ``law="curved"``: the
    bounded law in e ** shape, ``shape`` identified)."""
    term = AmplitudeSoftening(soft, gain, tau, a_ref=a_ref, w0=w0, law=law, shape=shape)
    return SDOFSystem(
        [ViscousDamping(c), LinearStiffness(k), term],
        name=kw.pop("name", "amplitude"),
        **kw,
    )


def Duffing(c: float = 0.5, k1: float = 15.0, k3: float = 120.0, signed_k3: bool = False, **kw) -> SDOFSystem:
    """m x'' + c x' + k1 x + k3 x^3 = -m ag (paper Eq. 15); ``signed_k3`` admits softening (k3 < 0)."""
    return SDOFSystem(
        [ViscousDamping(c), LinearStiffness(k1, param="k1"), CubicStiffness(k3, signed=signed_k3)],
        name=kw.pop("name", "duffing"),
        **kw,
    )


def BoucWen(
    c: float = 0.3, k: float = 12.0, beta: float = 1.0, gamma: float = 2.0, n: float = 2.0, **kw
) -> SDOFSystem:
    """m x'' + c x' + k z = -m ag; z' = x' - gamma|x'||z|^(n-1)z - beta x'|z|^n (paper Eq. 16)."""
    return SDOFSystem(
        [ViscousDamping(c), BoucWenHysteresis(k, beta, gamma, n)], name=kw.pop("name", "bouc_wen"), **kw
    )
