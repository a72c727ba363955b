"""A bridge deck rigid in plan on its supports, each driven by its own measured ground motion.

The deck moves in one horizontal direction (across it, transversely) by translation and
rotation about a vertical axis. Its two degrees of freedom are its displacements at the two
ends (positions 0 and L along the deck), so that both are in metres and a sensor at position
s reads ``(1 - s/L) x_0 + (s/L) x_1``. Support j at position s_j (an abutment, a bent) is a
spring and a dashpot, plus any force term of the library, acting on its deformation
d_j = b_j^T x, with b_j = (1 - s_j/L, s_j/L).

The records give the supports' absolute accelerations. With K = sum_j k_j b_j b_j^T and
K_s = [k_1 b_1 ... k_n b_n], the deck's quasi-static motion under support displacements u_g is
R u_g with R = K^{-1} K_s (each column the deck's response to one support moving alone; they
sum to a rigid translation). In the motion x relative to it

    M x'' + sum_j b_j F_j(d_j, d_j' + b_j^T R u_g' - u_g,j') = -M R u_g''

and an accelerometer at position s reads h(s)^T (x'' + R u_g''), absolute. The dashpots act
on each support's whole deformation rate (hence the supports' velocities in the excitation,
as for ``SDOFSystem`` with several inputs); a linear spring's quasi-static share cancels
exactly (K R = K_s). A nonlinear spring is evaluated on the dynamic deformation d_j only: the
supports' differential static motion is small for a short stiff deck, and this is said
where the model is described.

Mass per unit deck mass (records cannot tell the mass): M = [[1/4 + r, 1/4 - r],
[1/4 - r, 1/4 + r]] with r = (rho/L)^2, rho the radius of gyration in plan (a uniform deck:
rho^2 = L^2/12, M = [[1/3, 1/6], [1/6, 1/3]]). Stiffnesses are per kg of deck (s^-2),
dampings per kg (s^-1). Parameters carry their support's number in the order of the inputs:
``k1, c1`` for the first support.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from pidyn.params import ParamSpec
from pidyn.systems.base import Kinematics, StructuralSystem, merge_specs, stack_last
from pidyn.systems.places import OnStorey, PlacedTerms, latent_slices, place_terms
from pidyn.systems.terms import TERMS, ForceTerm, LinearStiffness, ViscousDamping, signed_sum


def sensor_row(position: float, length: float) -> np.ndarray:
    """How a sensor at ``position`` (m from the deck's first end) reads the two end motions."""
    xi = float(position) / float(length)
    return np.array([1.0 - xi, xi])


class RigidDeck(PlacedTerms, StructuralSystem):
    """A deck rigid in plan on ``len(inputs)`` supports (see the module docstring).

    Args:
        inputs: the supports' input names, in the order of the record's input columns.
        positions: each support's position along the deck (m from the first end).
        length: the deck's length between its ends (m).
        gyration: the deck's radius of gyration in plan (m); None: a uniform deck, L / sqrt(12).
        stiffnesses: starting values per support, per kg of deck (s^-2); a scalar means every
            support.
        dampings: starting values per support, per kg of deck (s^-1); a scalar means every
            support.
        support_terms: ``{support: [{term: hysteresis, ...}, ...]}`` (1-based, as storeys of a
            ``ShearBuilding``): a support's spring takes any force term of the library.
        sensors: the deck channels' positions by name (``ch7``: m), where the model is read
            from a station's layout (``pidyn.data.layout``).
    """

    n_dof = 2

    def __init__(
        self,
        inputs: Sequence[str],
        positions: Sequence[float],
        length: float,
        gyration: float | None = None,
        stiffnesses: float | Sequence[float] = 200.0,
        dampings: float | Sequence[float] = 1.0,
        support_terms: Mapping[Any, Any] | None = None,
        params: dict | None = None,
        name: str = "rigid_deck",
        sensors: Mapping[str, float] | None = None,
    ) -> None:
        super().__init__("ground")
        self.name = name
        self.inputs = tuple(str(i) for i in inputs)
        n = len(self.inputs)
        self.length = float(length)
        self.positions = tuple(float(s) for s in positions)
        #: the deck channels' positions (m), by name: how a record's channels read the end motions
        self.sensors = {str(k): float(v) for k, v in (sensors or {}).items()}
        _check_layout(self.inputs, self.positions, self.length)
        rho = self.length / np.sqrt(12.0) if gyration is None else float(gyration)
        self.gyration = gyration
        if not rho > 0:
            raise ValueError(f"{name}: gyration must be positive, got {gyration}")
        r = (rho / self.length) ** 2
        self.mass_matrix = np.array([[0.25 + r, 0.25 - r], [0.25 - r, 0.25 + r]])
        self._minv = np.linalg.inv(self.mass_matrix)
        self.xi = tuple(s / self.length for s in self.positions)
        k = _per_support(stiffnesses, n, "stiffnesses")
        c = _per_support(dampings, n, "dampings")
        extra, replaced = place_terms(
            support_terms, n, k, "rigid_deck: support_terms", own=_own, place="support"
        )
        self.supports: list[list[OnStorey]] = []
        for j in range(n):
            terms: list[ForceTerm] = [ViscousDamping(c[j])]
            if not replaced[j]:
                terms.append(LinearStiffness(k[j]))
            self.supports.append([OnStorey(t, j + 1) for t in terms + extra[j]])
        per = {"N/m": "N/m per kg of deck (s^-2)", "N s/m": "N s/m per kg of deck (s^-1)"}
        defaults = [
            ParamSpec("m", init=1.0, scale=1.0, true=1.0, trainable=False, unit="deck mass (the unit)")
        ]
        for term in self.terms:
            for s in term.specs():
                defaults.append(_with_unit(s, per.get(s.unit, s.unit)))
        self._specs = merge_specs(defaults, params)
        self.n_latent = sum(t.n_latent for t in self.terms)
        self.latent_names = tuple(t.name for t in self.terms if t.n_latent)
        self._slices = latent_slices(self.supports)

    # ------------------------------------------------------------------ structure
    @property
    def places(self) -> list[list[OnStorey]]:
        """The supports, each its terms (``PlacedTerms``)."""
        return self.supports

    def linear_params(self) -> list[str]:
        """None: the quasi-static influence R depends on the springs, so the motion residual is
        not linear in them (the data start uses the transmissibility's peak instead)."""
        return []

    def support_stiffness_params(self) -> list[list[str]]:
        """Each support's parameters whose sum is its stiffness about rest."""
        return [[t.initial_stiffness_param for t in s if t.initial_stiffness_param] for s in self.supports]

    def extended(self, values: Mapping[str, float], terms: Mapping[int, list], name: str) -> RigidDeck:
        """A deck with this one's layout, its supports' springs and dashpots at ``values`` and
        ``terms`` (term objects, by 1-based support) added: how the diagnosis extends a nominal deck."""
        n = len(self.inputs)
        return RigidDeck(
            inputs=self.inputs,
            positions=self.positions,
            length=self.length,
            gyration=self.gyration,
            stiffnesses=[float(values[f"k{j + 1}"]) for j in range(n)],
            dampings=[float(values[f"c{j + 1}"]) for j in range(n)],
            support_terms=dict(terms),
            name=name,
            sensors=self.sensors,
        )

    # ------------------------------------------------------------------ kinematics
    def _stiffness(self, p):
        return [sum_of([p[n] for n in names]) for names in self.support_stiffness_params()]

    def influence(self, p) -> list[list[Any]]:
        """R (2 x n_inputs) as nested lists of scalars (NumPy, dual or torch): the deck ends'
        quasi-static motion per unit motion of each support."""
        k = self._stiffness(p)
        k00 = sum_of([kj * (1 - x) ** 2 for kj, x in zip(k, self.xi)])
        k01 = sum_of([kj * (1 - x) * x for kj, x in zip(k, self.xi)])
        k11 = sum_of([kj * x**2 for kj, x in zip(k, self.xi)])
        det = k00 * k11 - k01 * k01
        r0 = [kj * ((1 - x) * k11 - x * k01) / det for kj, x in zip(k, self.xi)]
        r1 = [kj * (x * k00 - (1 - x) * k01) / det for kj, x in zip(k, self.xi)]
        return [r0, r1]

    def ground_motion(self, f, p):
        """The supports' accelerations as the deck ends feel them, R u_g'' (..., 2)."""
        R = self.influence(p)
        n = len(self.inputs)
        rows = [sum_of([R[i][j] * f[..., j] for j in range(n)]) for i in range(2)]
        return stack_last(rows, rows[0])

    def _support_motion(self, x, v, f, p, R) -> tuple[list, list]:
        """Each support's dynamic deformation and whole deformation rate."""
        n = len(self.inputs)
        vg = [f[..., n + j] for j in range(n)]
        end_v = [sum_of([R[i][j] * vg[j] for j in range(n)]) for i in range(2)]
        d, dv = [], []
        for j, xi in enumerate(self.xi):
            d.append((1 - xi) * x[..., 0] + xi * x[..., 1])
            dv.append((1 - xi) * (v[..., 0] + end_v[0]) + xi * (v[..., 1] + end_v[1]) - vg[j])
        return d, dv

    def _support_forces(self, t, d, dv, z, p) -> list:
        """Each support's force (spring, dashpot and any term, per kg of deck) at its deformation
        ``d`` and deformation rate ``dv``."""
        return [
            sum_of(
                [
                    term.force(t, d[j], dv[j], None if sl is None else z[..., sl], p)
                    for term, sl in zip(support, slices)
                ]
            )
            for j, (support, slices) in enumerate(zip(self.supports, self._slices))
        ]

    def _generalised_forces(self, t, d, dv, z, p) -> list:
        """The supports' forces on the two end coordinates, sum_j b_j F_j."""
        forces = self._support_forces(t, d, dv, z, p)
        return [
            sum_of([(1 - xi) * F for xi, F in zip(self.xi, forces)]),
            sum_of([xi * F for xi, F in zip(self.xi, forces)]),
        ]

    def support_deformation(self, x, v, f, p) -> tuple[list, list]:
        """Each support's dynamic deformation and whole deformation rate along a motion of the
        deck ends ``x``, ``v`` (what its force terms act on)."""
        return self._support_motion(x, v, f, p, self.influence(p))

    def support_response(self, t, x, v, z, f, p) -> tuple[list, list]:
        """Each support's deformation and its force along a motion of the deck ends ``x``, ``v``
        and the latent states ``z``: what its hysteresis loop draws."""
        d, dv = self._support_motion(x, v, f, p, self.influence(p))
        return d, self._support_forces(t, d, dv, z, p)

    # ------------------------------------------------------------------ equations
    def residual(self, k: Kinematics, f: torch.Tensor, p: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        if self.n_latent and k.z is None:
            raise ValueError(f"{self.name}: latent states {self.latent_names} are required")
        R = self.influence(p)
        d, dv = self._support_motion(k.x, k.v, f, p, R)
        q = self._generalised_forces(k.t, d, dv, k.z, p)
        g = self.ground_motion(f, p)
        M = self.mass_matrix
        motion = [
            M[i, 0] * (k.a[..., 0] + g[..., 0]) + M[i, 1] * (k.a[..., 1] + g[..., 1]) + q[i] for i in range(2)
        ]
        return {"motion": stack_last(motion, k.x), **self.latent_residuals(k, d, dv, p, self._slices)}

    def state_rate(self, t, y, p, f):
        x, v, z = y[..., :2], y[..., 2:4], y[..., 4:]
        R = self.influence(p)
        d, dv = self._support_motion(x, v, f, p, R)
        q = self._generalised_forces(t, d, dv, z, p)
        g = self.ground_motion(f, p)
        Mi = self._minv
        acc = [-(Mi[i, 0] * q[0] + Mi[i, 1] * q[1]) - g[..., i] for i in range(2)]
        parts = [v[..., 0], v[..., 1], *acc]
        for j, (support, slices) in enumerate(zip(self.supports, self._slices)):
            for term, sl in zip(support, slices):
                if sl is not None:
                    rate = term.latent_rate(t, d[j], dv[j], z[..., sl], p)
                    parts += [rate[..., i] for i in range(term.n_latent)]
        return stack_last(parts, parts[0])

    def rhs(self, t: float, y: np.ndarray, p: dict[str, float], f: Callable[[float], Any]) -> np.ndarray:
        return np.asarray(self.state_rate(t, np.asarray(y, dtype=float), p, np.asarray(f(t), float)))

    # ------------------------------------------------------------------ for engineers
    def linear_matrices(self, p: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C, K about rest in the end coordinates: C = sum c_j b_j b_j^T, K likewise."""
        C, K = np.zeros((2, 2)), np.zeros((2, 2))
        for xi, support in zip(self.xi, self.supports):
            b = np.array([1 - xi, xi])
            for t in support:
                if t.damping_param:
                    C += float(p[t.damping_param]) * np.outer(b, b)
                if t.initial_stiffness_param:
                    K += float(p[t.initial_stiffness_param]) * np.outer(b, b)
        return self.mass_matrix.copy(), C, K

    def support_equations(self, p: Mapping[str, float]) -> list[str]:
        return [
            f"support {j + 1} ({name}, at {s:.4g} m): F{j + 1} = "
            + signed_sum([t.formula(p) for t in support])
            for j, (name, s, support) in enumerate(zip(self.inputs, self.positions, self.supports))
        ]

    def describe(self, p: dict[str, float]) -> str:
        return (
            f"rigid deck of {self.length:.4g} m on {len(self.inputs)} supports, per kg of deck: "
            "M x'' + sum_j b_j F_j = -M R ug''; "
            + "; ".join(self.support_equations(p))
            + " (d_j: support j's deformation; nonlinear springs on its dynamic part)"
        )


def sum_of(parts: list) -> Any:
    """The sum of scalars or arrays of any kind (NumPy, dual, torch), starting from the first."""
    total = parts[0]
    for q in parts[1:]:
        total = total + q
    return total


def _check_layout(inputs: tuple[str, ...], positions: tuple[float, ...], length: float) -> None:
    if not length > 0:
        raise ValueError(f"rigid_deck: length must be positive, got {length}")
    if len(inputs) < 2 or len(positions) != len(inputs):
        raise ValueError(
            f"rigid_deck: {len(inputs)} supports and {len(positions)} positions; give one position per "
            "support, two supports at least"
        )
    if len(set(inputs)) != len(inputs):
        raise ValueError(f"rigid_deck: input names repeat: {list(inputs)}")
    bad = [s for s in positions if not 0.0 <= s <= length]
    if bad:
        raise ValueError(f"rigid_deck: support positions {bad} lie outside the deck (0 to {length} m)")
    if len(set(positions)) < 2:
        raise ValueError("rigid_deck: the supports stand at one position; the deck's rotation would be free")


def _per_support(value: float | Sequence[float], n: int, what: str) -> list[float]:
    if isinstance(value, (int, float)):
        return [float(value)] * n
    vals = [float(v) for v in value]
    if len(vals) != n:
        raise ValueError(f"rigid_deck: {what} has {len(vals)} values for {n} supports")
    return vals


def _own(entry: Mapping[str, Any], j: int) -> dict:
    """A config entry whose term reads the support's spring and dashpot by name (an amplitude
    law scales them) is pointed at support j's own (``k2``, ``c2``)."""
    entry = dict(entry)
    cls = TERMS.get(entry.get("term"))
    if cls is not None:
        args = inspect.signature(cls).parameters
        for ref, base in (("stiffness", "k"), ("damping", "c")):
            if ref in args:
                entry.setdefault(ref, f"{base}{j}")
    return entry


def _with_unit(spec: ParamSpec, unit: str) -> ParamSpec:

    return replace(spec, unit=unit)
