"""A shear building's state rate on whole floor vectors (NumPy and dual arrays).

The integrator calls the state rate four times a substep, for every shooting segment and
every sensitivity direction at once. Written term by term and storey by storey, a 3-storey
building made some fifty small array operations a call, and those were most of a building
diagnosis's time. Here every storey's viscous damper and linear spring act in one vector
operation on the drifts, the floors' balance is one shift, and only the storeys' further
terms (a gap, a hysteresis, a change in time) are evaluated one by one, through the same
``ForceTerm.force`` code as before.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from pidyn.autodiff import Dual
from pidyn.systems.base import stack_last
from pidyn.systems.terms import LinearStiffness, ViscousDamping


@dataclass(frozen=True)
class Layout:
    """Which parameter is each storey's damper and spring (None: no such term), and the other
    terms with their latent slices, by storey (0-based)."""

    dampers: tuple[str | None, ...]
    springs: tuple[str | None, ...]
    others: tuple[tuple[int, Any, slice | None], ...]
    masses: tuple[str, ...]


def layout(storeys: list, slices: list) -> Layout:
    """The split of a building's terms: the first viscous damper and linear spring of a storey
    go to the vector operation, every other term stays a term."""
    dampers: list[str | None] = []
    springs: list[str | None] = []
    others = []
    for i, (storey, sl_row) in enumerate(zip(storeys, slices)):
        c = k = None
        for term, sl in zip(storey, sl_row):
            inner = term.term
            if c is None and type(inner) is ViscousDamping and sl is None:
                c = term.rename["c"]
            elif k is None and type(inner) is LinearStiffness and sl is None:
                k = term.rename[inner.param]
            else:
                others.append((i, term, sl))
        dampers.append(c)
        springs.append(k)
    masses = tuple(f"m{i + 1}" for i in range(len(storeys)))
    return Layout(tuple(dampers), tuple(springs), tuple(others), masses)


#: (written, subtracted) floor slices: a storey's drift takes the floor below from its own
#: floor (floor 1's drift is itself); a floor's net force takes the storey above from its own
_BELOW = (slice(1, None), slice(None, -1))
_ABOVE = (slice(None, -1), slice(1, None))


def _minus_neighbour(u: Any, sides: tuple[slice, slice]) -> Any:
    """u_i - u_{i-1} (``_BELOW``) or u_i - u_{i+1} (``_ABOVE``) along the floors: a plain
    array's last axis, a dual array's values and its derivatives' axis before the directions."""
    put, take = sides
    if not isinstance(u, (Dual, np.ndarray)):  # another array type (traced, torch): by slices
        if sides is _BELOW:
            return _cat([u[..., :1], u[..., 1:] - u[..., :-1]], u)
        return _cat([u[..., :-1] - u[..., 1:], u[..., -1:]], u)
    if isinstance(u, Dual):
        v, d = u.v.copy(), u.d.copy()
        v[..., put] -= u.v[..., take]
        d[..., put, :] -= u.d[..., take, :]
        return Dual(v, d)
    out = np.array(u, dtype=float)
    out[..., put] -= u[..., take]
    return out


def _cat(parts: list, like: Any) -> Any:
    """``parts`` joined along the last axis: torch where ``like`` is a tensor, NumPy otherwise."""
    if isinstance(like, torch.Tensor):
        return torch.cat(parts, dim=-1)
    return np.concatenate(parts, axis=-1)


def _vector(p: dict, names: tuple[str | None, ...]) -> Any:
    """The parameters ``names`` on a last axis (0 where None); scalars beside per-trajectory
    values (an output-error step's perturbed copies) are broadcast to the trajectories."""
    vals = [0.0 if n is None else p[n] for n in names]
    tensor = next((v for v in vals if isinstance(v, torch.Tensor)), None)
    if tensor is not None:  # a learned force trained through the simulation: the parameters in torch
        vals = [torch.as_tensor(v, dtype=tensor.dtype) for v in vals]
        return torch.stack(torch.broadcast_tensors(*vals), dim=-1)
    shapes = [v.shape if hasattr(v, "shape") else () for v in vals]
    widest = max(shapes, key=len)
    if any(sh != widest for sh in shapes):
        zeros = np.zeros(widest)
        vals = [v if sh == widest else v + zeros for v, sh in zip(vals, shapes)]
    return np.stack(vals, axis=-1)


class Vectors:
    """The dampers' and springs' parameters and the masses' reciprocals as floor vectors, kept while the
    integrator passes the same parameter values (every call of a simulation). The values are
    told apart by identity: a value changed in place (an array written into) would be missed;
    the refinement and output error build new values for every iterate."""

    def __init__(self) -> None:
        self.key: tuple = ()
        self.value: tuple = ()

    def get(self, p: dict, lay: Layout, like: Any = None) -> tuple:
        """The vectors; torch tensors of ``like``'s precision where ``like`` is one (parameters
        held fixed beside trained ones come as floats)."""
        tensor = isinstance(like, torch.Tensor)
        key = (p, tensor, *(None if k is None else p[k] for k in lay.dampers + lay.springs + lay.masses))
        if len(key) == len(self.key) and all(a is b for a, b in zip(key, self.key)):
            return self.value
        self.key = key
        self.value = (_vector(p, lay.dampers), _vector(p, lay.springs), 1.0 / _vector(p, lay.masses))
        if tensor:
            self.value = tuple(torch.as_tensor(a, dtype=like.dtype) for a in self.value)
        return self.value


def state_rate(building: Any, lay: Layout, cache: Vectors, t: Any, y: Any, p: dict, f: Any) -> Any:
    """(x', v', z') of a ground-driven shear building: NumPy, dual, traced or torch arrays, ``y``
    (..., n_state)."""
    n = building.n_dof
    x, v, z = y[..., :n], y[..., n : 2 * n], y[..., 2 * n :]
    d, dv = _minus_neighbour(x, _BELOW), _minus_neighbour(v, _BELOW)
    damp, spring, per_mass = cache.get(p, lay, y)
    force = damp * dv + spring * d
    latent = []
    if lay.others:
        cols: dict[int, Any] = {}
        for i, term, sl in lay.others:
            zi = None if sl is None else z[..., sl]
            fi = term.force(t, d[..., i], dv[..., i], zi, p)
            cols[i] = fi if i not in cols else cols[i] + fi
            if sl is not None:
                latent.append(term.latent_rate(t, d[..., i], dv[..., i], zi, p))
        zero = 0.0 * d[..., 0]
        extra = [cols[i] + zero if i in cols else zero for i in range(n)]
        force = force + stack_last(extra, zero)
    ground = f[..., None] if isinstance(f, torch.Tensor) else np.asarray(f)[..., None]
    acc = -ground - _minus_neighbour(force, _ABOVE) * per_mass
    return _cat([v, acc, *latent], v)
