"""Force terms that act at places of a structure: the storeys of a building (on their drifts),
the supports of a deck (on their deformations). A place's terms carry its number in their
parameters' names (``k2``, ``beta1``), any term of the library can sit at a place, and the
structures built this way share how they list, split and scale their terms."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from pidyn.params import ParamSpec
from pidyn.systems.terms import TERMS, BoucWenHysteresis, ForceTerm, LinearStiffness, ViscousDamping


def storey_param(base: str, storey: int) -> str:
    """The name of parameter ``base`` of storey ``storey`` (1-based): c1, beta2, k3_1."""
    return f"{base}_{storey}" if base[-1].isdigit() else f"{base}{storey}"


class OnStorey(ForceTerm):
    """A force term acting on one storey's drift, its parameters renamed with the storey number."""

    def __init__(self, term: ForceTerm, storey: int) -> None:
        self.term, self.storey = term, storey
        self.name = f"{term.name}{storey}"
        self.n_latent = term.n_latent
        self.rename = {s.name: storey_param(s.name, storey) for s in term.specs()}
        self.linear = tuple(self.rename[n] for n in term.linear)
        #: parameters of other terms this one reads by their full name (a stiffness loss scales k2)
        self.reads = tuple(
            ref
            for ref in (getattr(term, "stiffness", None), getattr(term, "damping", None))
            if isinstance(ref, str)
        )

    def specs(self) -> list[ParamSpec]:
        return [replace(s, name=self.rename[s.name]) for s in self.term.specs()]

    def _local(self, p: Mapping[str, Any]) -> dict[str, Any]:
        local = {base: p[full] for base, full in self.rename.items()}
        for ref in self.reads:
            if ref in p:
                local[ref] = p[ref]
        return local

    def force(self, t, x, v, z, p):
        return self.term.force(t, x, v, z, self._local(p))

    def latent_rate(self, t, x, v, z, p):
        return self.term.latent_rate(t, x, v, z, self._local(p))

    def formula(self, p):
        out = re.sub(r"\bx\b", f"d{self.storey}", self.term.formula(self._local(p)))
        return re.sub(r"\bz\b", f"z{self.storey}", out)

    @property
    def initial_stiffness_param(self) -> str | None:
        """The parameter that is this term's stiffness about rest (dF/dd at d = 0, z = 0)."""
        if isinstance(self.term, (LinearStiffness, BoucWenHysteresis)):
            return self.rename[self.term.param]
        return None

    @property
    def damping_param(self) -> str | None:
        return self.rename["c"] if isinstance(self.term, ViscousDamping) else None


def storey_term(spec: Mapping[str, Any], k: float) -> ForceTerm:
    """A term from its config entry ``{term: <name>, <param>: value, ...}`` (names as in ``TERMS``)."""
    spec = dict(spec)
    name = spec.pop("term", None)
    if name not in TERMS or name in ("viscous_damping", "linear_stiffness", "learned_force"):
        allowed = sorted(set(TERMS) - {"viscous_damping", "linear_stiffness", "learned_force"})
        raise ValueError(f"shear_building: storey term '{name}' is not one of {', '.join(allowed)}")
    if TERMS[name].is_the_spring:
        spec.setdefault("k", k)  # the storey's stiffness becomes the hysteretic spring's
    try:
        return TERMS[name](**spec)
    except TypeError as exc:
        raise ValueError(f"shear_building: storey term '{name}': {exc}") from None


def place_terms(
    spec: Mapping[Any, Any] | None, n: int, k: list[float], what: str, own=None, place: str = "storey"
) -> tuple[list[list[ForceTerm]], list[bool]]:
    """Each place's further terms from ``{place: [entry, ...]}`` (1-based; an entry is a config
    mapping or a term object), and whether a configured hysteresis replaces the place's linear
    spring (a term object adds to it: the diagnosis's hysteresis is k d + kh z). ``own(entry, j)``
    may complete a config entry for place j."""
    extra: list[list[ForceTerm]] = [[] for _ in range(n)]
    replaced = [False] * n
    for key, entries in dict(spec or {}).items():
        j = int(key)
        if not 1 <= j <= n:
            raise ValueError(f"{what} names {place} {j}; {place}s are 1..{n}")
        entries = [entries] if isinstance(entries, (Mapping, ForceTerm)) else list(entries)
        extra[j - 1] = [
            e if isinstance(e, ForceTerm) else storey_term(own(e, j) if own else e, k[j - 1]) for e in entries
        ]
        replaced[j - 1] = any(
            not isinstance(e, ForceTerm) and isinstance(t, BoucWenHysteresis)
            for e, t in zip(entries, extra[j - 1])
        )
    return extra, replaced


def latent_slices(places: list[list[OnStorey]]) -> list[list[slice | None]]:
    """Where each place's terms' latent states sit in the state's latent part."""
    out, i = [], 0
    for place in places:
        row = []
        for t in place:
            row.append(slice(i, i + t.n_latent) if t.n_latent else None)
            i += t.n_latent
        out.append(row)
    return out


class PlacedTerms:
    """What a structure of places (``places``: a list of each place's terms) knows of its terms."""

    places: list[list[OnStorey]]
    _specs: list[ParamSpec]

    def param_specs(self) -> list[ParamSpec]:
        return list(self._specs)

    @property
    def terms(self) -> list[OnStorey]:
        return [t for p in self.places for t in p]

    @property
    def linear_time_invariant(self) -> bool:
        return all(type(t.term) in (ViscousDamping, LinearStiffness) for t in self.terms)

    def period_scaling(self) -> dict[str, float]:
        """Powers of a frequency factor (``StructuralSystem.period_scaling``): springs 2, dashpots 1."""
        if not self.linear_time_invariant:
            return {}
        return {
            s.name: (1.0 if isinstance(t.term, ViscousDamping) else 2.0)
            for t in self.terms
            for s in t.specs()
        }

    def latent_residuals(self, k: Any, d: list, dv: list, p: Any, slices: list[list[slice | None]]) -> dict:
        """Each latent term's residual (its state's rate against its law) at its place's
        deformation ``d[j]`` and rate ``dv[j]``, named by the term."""
        out = {}
        for j, (place, row) in enumerate(zip(self.places, slices)):
            for term, sl in zip(place, row):
                if sl is not None:
                    assert k.z is not None and k.zd is not None
                    out[term.name] = k.zd[:, sl] - term.latent_rate(k.t, d[j], dv[j], k.z[:, sl], p)
        return out
