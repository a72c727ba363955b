"""N-storey shear buildings (paper Eq. 4-5) whose storeys carry the same force terms as the
single-degree-of-freedom systems, acting on the inter-storey drift.

Storey i joins floor i-1 (floor 0 is the ground) to floor i. Its restoring force F_i is the
sum of its terms evaluated on the drift d_i = x_i - x_{i-1} and its rate; a hysteretic storey
has its own latent z_i. Floor i then obeys

    m_i x_i'' + F_i - F_{i+1} = -m_i ag(t)        (F_{N+1} = 0; ground excitation)

With viscous dampers and linear springs in every storey this is M x'' + C x' + K x = -M 1 ag
with the usual tridiagonal C and K. The equations are written once, on array operations, so
torch tensors (the physics loss), NumPy arrays (simulation) and dual arrays (exact
sensitivities for the refinement and the Cramer-Rao bound) all run the same code.

Masses unknown (``masses: unknown``): a record of accelerations and the ground's determines the
model only up to one common scale (M, C, K and a M: the same accelerations), so floor 1's mass is
the unit (``m1 = 1``), the others are identified as ratios to it, and every damping and
stiffness is per kilogram of floor 1 (``k1`` in N/m per kg = s^-2). ``absolute_values`` refuses
to turn them into N/m without a mass.

Parameters carry their storey's number: ``c1, k1`` for storey 1, ``beta1, gamma1, n1`` for a
Bouc-Wen storey, ``k3_2`` for a cubic spring in storey 2 (an underscore after a base name that
ends in a digit).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch

import pidyn.systems.shear_rate as shear_rate
from pidyn.params import ParamSpec, positive
from pidyn.systems.base import ExcitationKind, Kinematics, StructuralSystem, merge_specs, stack_last
from pidyn.systems.places import OnStorey, PlacedTerms, latent_slices, place_terms
from pidyn.systems.terms import BoucWenHysteresis, ForceTerm, LinearStiffness, ViscousDamping, signed_sum


def _per_unit_m1(spec: ParamSpec) -> ParamSpec:
    """A storey parameter's unit per kg of floor 1 (the masses unknown): N/m -> s^-2, N s/m -> s^-1."""
    per = {"N/m": "N/m per kg of m1 (s^-2)", "N s/m": "N s/m per kg of m1 (s^-1)"}
    return replace(
        spec, unit=per.get(spec.unit, f"{spec.unit} per kg of m1" if spec.unit else "per kg of m1")
    )


def _per_storey(value: float | Sequence[float], n: int, what: str) -> list[float]:
    if isinstance(value, (int, float)):
        return [float(value)] * n
    vals = [float(v) for v in value]
    if len(vals) != n:
        raise ValueError(
            f"shear_building: {what} has {len(vals)} values for {n} storeys; give {n} or one scalar"
        )
    return vals


#: ``masses: unknown``: floor 1's mass is the unit, the others are identified as ratios to it
UNKNOWN_MASSES = "unknown"


class UnknownMassError(ValueError):
    """An absolute stiffness or damping asked of a model whose masses the records do not give."""


class ShearBuilding(PlacedTerms, StructuralSystem):
    """N-storey shear building; every storey a viscous damper plus a spring (linear, or
    hysteretic) plus any further force terms, all on its drift.

    Args:
        n_storeys: number of storeys (None: the length of the per-storey lists).
        masses: per storey (kg); a scalar means every storey. ``masses="unknown"``: floor 1's
            mass is the unit and the others' ratios to it are identified; dampings and
            stiffnesses are then per kg of floor 1 (s^-1, s^-2).
        dampings: per storey (N s/m); a scalar means every storey.
        stiffnesses: per storey (N/m); a scalar means every storey.
        stiffness_taper: with a scalar stiffness, the top storey's stiffness as a share of the
            first's, linear in between (1: uniform).
        storey_terms: ``{storey: [ {term: hysteresis, beta: .., gamma: .., n: ..}, ...]}``
            (1-based storeys; a ``ForceTerm`` object in place of an entry is used as it is; ``hysteresis`` replaces the storey's linear spring, its k being
            the storey stiffness; other terms add to it).
        guess: starting values by base name for every storey (``{c: 1.0, k: 100.0}``);
            ``params`` overrides any single parameter (``{k2: {init: 80}}``).
        mass_ratio_range: with the masses unknown, the range of each floor's mass over floor 1's,
            held by the parameters' transform (a box), so that no fit can reach a floor of almost
            no mass, whose damping rate the integrator's step cannot follow (a flexible shake-table
            model had ended at m2 = 0.0098, c2 = 547 and diverged).
    """

    def __init__(
        self,
        n_storeys: int | None = 3,
        masses: float | Sequence[float] | str = 1.0,
        dampings: float | Sequence[float] = 0.5,
        stiffnesses: float | Sequence[float] = 200.0,
        stiffness_taper: float = 0.5,
        storey_terms: Mapping[Any, Sequence[Mapping[str, Any]] | Mapping[str, Any]] | None = None,
        guess: Mapping[str, float] | None = None,
        excitation: ExcitationKind = "ground",
        params: dict | None = None,
        name: str = "shear_building",
        mass_ratio_range: Sequence[float] = (0.1, 10.0),
    ) -> None:
        super().__init__(excitation)
        self.name = name
        self.mass_ratio_range = (float(mass_ratio_range[0]), float(mass_ratio_range[1]))
        if not 0 < self.mass_ratio_range[0] < 1 < self.mass_ratio_range[1]:
            raise ValueError(
                f"shear_building: mass_ratio_range must hold 1 inside (0, inf), got {list(mass_ratio_range)}"
            )
        self.mass_known = not (isinstance(masses, str) and masses == UNKNOWN_MASSES)
        if isinstance(masses, str) and self.mass_known:
            raise ValueError(
                f"shear_building: masses '{masses}': give kg per storey, a list, or '{UNKNOWN_MASSES}'"
            )
        lists = [v for v in (masses, dampings, stiffnesses) if not isinstance(v, (int, float, str))]
        n = int(n_storeys) if n_storeys is not None else (len(lists[0]) if lists else 3)
        if n < 1:
            raise ValueError(f"shear_building: n_storeys must be >= 1, got {n}")
        self.n_dof = n
        self.masses = _per_storey(1.0 if not self.mass_known else masses, n, "masses")
        c = _per_storey(dampings, n, "dampings")
        if isinstance(stiffnesses, (int, float)):
            k = [float(stiffnesses) * (1 - (1 - stiffness_taper) * i / max(n - 1, 1)) for i in range(n)]
        else:
            k = _per_storey(stiffnesses, n, "stiffnesses")
        extra, replaced = place_terms(storey_terms, n, k, "shear_building: storey_terms")
        self.storeys: list[list[OnStorey]] = []
        for i in range(n):
            terms: list[ForceTerm] = [ViscousDamping(c[i])]
            if not replaced[i]:
                terms.append(LinearStiffness(k[i]))
            terms += extra[i]
            self.storeys.append([OnStorey(t, i + 1) for t in terms])
        defaults = self._mass_specs()
        #: parameters in force units: per kg of floor 1 when the masses are unknown
        self.force_params = {
            s.name for st in self.storeys for t in st for s in t.specs() if s.unit.startswith("N")
        }
        for storey in self.storeys:
            for term in storey:
                defaults += term.specs() if self.mass_known else [_per_unit_m1(s) for s in term.specs()]
        defaults = self._apply_guess(defaults, guess or {})
        self._specs = merge_specs(defaults, params)
        self.n_latent = sum(t.n_latent for s in self.storeys for t in s)
        self.latent_names = tuple(t.name for s in self.storeys for t in s if t.n_latent)

    def _mass_specs(self) -> list[ParamSpec]:
        if self.mass_known:
            return [
                ParamSpec(f"m{i + 1}", init=m, scale=m, true=m, trainable=False, unit="kg")
                for i, m in enumerate(self.masses)
            ]
        lo, hi = self.mass_ratio_range
        return [ParamSpec("m1", init=1.0, scale=1.0, true=1.0, trainable=False, unit="m1 (the unit)")] + [
            ParamSpec(f"m{i + 1}", init=1.0, scale=1.0, transform="box", lower=lo, upper=hi, unit="m1")
            for i in range(1, self.n_dof)
        ]

    @staticmethod
    def _apply_guess(specs: list[ParamSpec], guess: Mapping[str, float]) -> list[ParamSpec]:
        """Starting values by base name (``k`` sets k1..kN): an unknown base name fails."""
        bases = {re.sub(r"_?\d+$", "", s.name) for s in specs if s.trainable}
        unknown = set(guess) - bases
        if unknown:
            raise ValueError(
                f"shear_building: guess for {sorted(unknown)}; the parameters' base names are {sorted(bases)}"
            )
        out = []
        for s in specs:
            base = re.sub(r"_?\d+$", "", s.name)
            if s.trainable and base in guess:
                g = float(guess[base])
                s = (
                    replace(s, init=g, scale=abs(g) or s.scale)
                    if s.transform != "box"
                    else replace(s, init=g)
                )
            out.append(s)
        return out

    # ------------------------------------------------------------------ structure
    @property
    def places(self) -> list[list[OnStorey]]:
        """The storeys, each its terms (``PlacedTerms``); the masses stay under a period scaling."""
        return self.storeys

    def linear_params(self) -> list[str]:
        """The parameters the motion residual is linear in: the terms' linear ones and, with the
        masses unknown, the mass ratios (m_i a_i enters linearly too)."""
        trainable = {s.name for s in self._specs if s.trainable}
        masses = [f"m{i + 1}" for i in range(self.n_dof) if f"m{i + 1}" in trainable]
        return masses + [n for t in self.terms for n in t.linear if n in trainable]

    def own_units(self, truth: Mapping[str, Any] | None) -> dict[str, Any] | None:
        """A simulation's true values (kg, N/m) in this model's units: with the masses unknown,
        the masses and every force parameter divided by floor 1's mass."""
        if truth is None or self.mass_known or truth.get("m1") is None:
            return None if truth is None else dict(truth)
        m1 = float(truth["m1"])
        scaled = self.force_params | {f"m{i + 1}" for i in range(self.n_dof)}
        return {k: (v / m1 if k in scaled and v is not None else v) for k, v in truth.items()}

    def absolute_values(self, values: Mapping[str, float], m1: float | None = None) -> dict[str, float]:
        """The parameters in absolute units. With the masses unknown they are per kg of floor 1,
        and only a mass of floor 1 (kg) turns them into kg, N s/m, N/m: without one this refuses."""
        if self.mass_known:
            return {k: float(v) for k, v in values.items()}
        if m1 is None:
            raise UnknownMassError(
                f"{self.name}: the masses are unknown (masses: {UNKNOWN_MASSES}); the records determine the mass "
                f"ratios m_i/m1 and the stiffnesses and dampings per kg of floor 1 (k_i/m1 in s^-2), not absolute "
                f"N/m: give floor 1's mass (m1 in kg) to scale them"
            )
        return {k: float(v) * float(m1) for k, v in values.items()}

    def _latent_slices(self) -> list[list[slice | None]]:
        key = tuple(id(t) for storey in self.storeys for t in storey)
        cached = getattr(self, "_slices", None)
        if cached is not None and cached[0] == key:  # an integrator asks at every step
            return cached[1]
        out = latent_slices(self.storeys)
        self._slices = (key, out)
        return out

    def _drifts(self, x, v):
        n = self.n_dof
        d = [x[..., i] - x[..., i - 1] if i else x[..., 0] for i in range(n)]
        dv = [v[..., i] - v[..., i - 1] if i else v[..., 0] for i in range(n)]
        return d, dv

    def storey_forces(self, t, x, v, z, p, drifts: tuple | None = None) -> list:
        """Restoring force of every storey, each shaped like ``x[..., 0]``."""
        d, dv = self._drifts(x, v) if drifts is None else drifts
        out = []
        for i, (storey, slices) in enumerate(zip(self.storeys, self._latent_slices())):
            total = None  # the first term's force, not 0.0 + it
            for term, sl in zip(storey, slices):
                force = term.force(t, d[i], dv[i], None if sl is None else z[..., sl], p)
                total = force if total is None else total + force
            out.append(0.0 if total is None else total)
        return out

    def _floor_forces(self, t, x, v, z, p, f, drifts: tuple | None = None) -> list:
        """Net force on every floor from the storeys and the excitation (right-hand side minus
        restoring): m_i x_i'' = this."""
        n = self.n_dof
        F = self.storey_forces(t, x, v, z, p, drifts)
        out = []
        for i in range(n):
            net = F[i] - F[i + 1] if i + 1 < n else F[i]
            m = p[f"m{i + 1}"]
            ext = -m * f if self.excitation == "ground" else (f if i == n - 1 else 0.0 * f)
            out.append(ext - net)
        return out

    # ------------------------------------------------------------------ equations
    def residual(self, k: Kinematics, f: torch.Tensor, p: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        if self.n_latent and k.z is None:
            raise ValueError(f"{self.name}: latent states {self.latent_names} are required")
        rhs = self._floor_forces(k.t, k.x, k.v, k.z, p, f)
        motion = [p[f"m{i + 1}"] * k.a[..., i] - rhs[i] for i in range(self.n_dof)]
        d, dv = self._drifts(k.x, k.v)
        return {
            "motion": stack_last(motion, k.x),
            **self.latent_residuals(k, d, dv, p, self._latent_slices()),
        }

    def state_rate(self, t, y, p, f):
        if self.excitation == "ground":  # the integrators' path (NumPy, dual, traced and torch arrays)
            return shear_rate.state_rate(self, *self._layout(), t, y, p, f)
        return self._state_rate_by_term(t, y, p, f)

    def _layout(self) -> tuple[shear_rate.Layout, shear_rate.Vectors]:
        """The terms' split for ``shear_rate`` and its parameter store, rebuilt when the terms change."""
        slices = self._latent_slices()
        cached = getattr(self, "_lay", None)
        if cached is not None and cached[0] is slices:
            return cached[1]
        lay = (shear_rate.layout(self.storeys, slices), shear_rate.Vectors())
        self._lay = (slices, lay)
        return lay

    def _state_rate_by_term(self, t, y, p, f):
        """The state rate term by term: torch tensors (a learned force trained through it) and
        any excitation; ``shear_rate`` is the same on whole floor vectors."""
        n = self.n_dof
        x, v, z = y[..., :n], y[..., n : 2 * n], y[..., 2 * n :]
        d, dv = drifts = self._drifts(x, v)
        rhs = self._floor_forces(t, x, v, z, p, f, drifts)
        acc = [rhs[i] / p[f"m{i + 1}"] for i in range(n)]
        parts = [v[..., i] for i in range(n)] + acc
        if self.n_latent:
            for i, (storey, slices) in enumerate(zip(self.storeys, self._latent_slices())):
                for term, sl in zip(storey, slices):
                    if sl is not None:
                        rate = term.latent_rate(t, d[i], dv[i], z[..., sl], p)
                        parts += [rate[..., j] for j in range(term.n_latent)]
        if all(isinstance(q, (float, np.floating)) for q in parts):  # one plain state (an integrator's step)
            return np.array(parts, dtype=float)
        return stack_last(parts, parts[0])

    def rhs(self, t: float, y: np.ndarray, p: dict[str, float], f: Callable[[float], float]) -> np.ndarray:
        return self.state_rate(t, np.asarray(y, dtype=float), p, f(t))

    # ------------------------------------------------------------------ for engineers
    def storey_equations(self, p: Mapping[str, float]) -> list[str]:
        """One line per storey: its restoring force on the drift d_i (and its latent rate)."""
        lines = []
        for i, storey in enumerate(self.storeys, 1):
            lines.append(f"storey {i}: F{i} = " + signed_sum([t.formula(p) for t in storey]))
            for t in storey:
                if isinstance(t.term, BoucWenHysteresis):
                    q = t._local(p)
                    lines.append(
                        f"  z{i}' = d{i}' - {q['gamma']:.5g} |d{i}'| |z{i}|^({q['n']:.5g}-1) z{i} "
                        f"- {q['beta']:.5g} d{i}' |z{i}|^{q['n']:.5g}"
                    )
        return lines

    def describe(self, p: dict[str, float]) -> str:
        eq = "m_i x_i'' + F_i - F_(i+1) = " + (
            "-m_i ag(t)" if self.excitation == "ground" else "u(t) on the top floor"
        )
        return eq + "; " + "; ".join(s.strip() for s in self.storey_equations(p))

    def linear_at(
        self, values: Mapping[str, float], storey_terms: Mapping[int, list], name: str
    ) -> ShearBuilding:
        """A building with this one's masses, dampers and springs at ``values`` and ``storey_terms``
        (term objects) added: how the diagnosis extends a nominal building."""
        n = self.n_dof
        return ShearBuilding(
            n_storeys=n,
            masses=[values[f"m{i + 1}"] for i in range(n)],
            dampings=[positive(values[f"c{i + 1}"]) for i in range(n)],
            stiffnesses=[positive(values[f"k{i + 1}"]) for i in range(n)],
            storey_terms=dict(storey_terms),
            excitation=self.excitation,
            name=name,
        )

    def linear_matrices(self, p: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C, K of the linear part about rest: the viscous dampers and each storey's
        initial stiffness (a Bouc-Wen storey's k, since dz/dd = 1 at z = 0)."""
        n = self.n_dof
        c, k = np.zeros(n), np.zeros(n)
        for i, storey in enumerate(self.storeys):
            for t in storey:
                if t.damping_param:
                    c[i] += float(p[t.damping_param])
                if t.initial_stiffness_param:
                    k[i] += float(p[t.initial_stiffness_param])
        M = np.diag([float(p[f"m{i + 1}"]) for i in range(n)])
        return M, _tridiagonal(c), _tridiagonal(k)


def _tridiagonal(s: np.ndarray) -> np.ndarray:
    """Storey values -> the floor matrix of springs (or dampers) in series up the building."""
    n = len(s)
    A = np.zeros((n, n))
    for i in range(n):
        A[i, i] += s[i]
        if i > 0:
            A[i - 1, i - 1] += s[i]
            A[i - 1, i] -= s[i]
            A[i, i - 1] -= s[i]
    return A
