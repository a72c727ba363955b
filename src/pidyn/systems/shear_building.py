"""Linear N-storey shear building (paper Eq. 4-5): M x'' + C x' + K x = -M 1 ag.

Storey i has mass m_i, inter-storey damping c_i and stiffness k_i between floor i-1 and i
(floor 0 is the ground), giving the usual tridiagonal C and K.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
import torch

from pidyn.params import ParamSpec
from pidyn.systems.base import ExcitationKind, Kinematics, StructuralSystem, merge_specs


def _tridiag(vals: Sequence, lib) -> object:
    n = len(vals)
    rows = []
    for i in range(n):
        row = []
        for j in range(n):
            if i == j:
                row.append(vals[i] + (vals[i + 1] if i + 1 < n else 0.0 * vals[i]))
            elif j == i + 1:
                row.append(-vals[i + 1])
            elif j == i - 1:
                row.append(-vals[i])
            else:
                row.append(0.0 * vals[i])
        rows.append(lib.stack(row) if lib is torch else row)
    return torch.stack(rows) if lib is torch else np.array(rows, dtype=float)


class ShearBuilding(StructuralSystem):
    """Linear MDOF shear building with storey-wise masses, dampings and stiffnesses."""

    def __init__(
        self,
        masses: Sequence[float] = (1.0, 1.0, 1.0),
        dampings: Sequence[float] = (0.5, 0.5, 0.5),
        stiffnesses: Sequence[float] = (200.0, 150.0, 100.0),
        excitation: ExcitationKind = "ground",
        params: dict | None = None,
        name: str = "shear_building",
    ) -> None:
        super().__init__(excitation)
        if not len(masses) == len(dampings) == len(stiffnesses):
            raise ValueError(f"{name}: masses, dampings and stiffnesses need the same length")
        self.name = name
        self.n_dof = len(masses)
        defaults: list[ParamSpec] = []
        for i, m in enumerate(masses, 1):
            defaults.append(ParamSpec(f"m{i}", init=m, scale=m, true=m, trainable=False, unit="kg"))
        for i, c in enumerate(dampings, 1):
            defaults.append(ParamSpec(f"c{i}", init=c, scale=c, true=c, unit="N s/m"))
        for i, k in enumerate(stiffnesses, 1):
            defaults.append(ParamSpec(f"k{i}", init=k, scale=k, true=k, unit="N/m"))
        self._specs = merge_specs(defaults, params)

    def param_specs(self) -> list[ParamSpec]:
        return list(self._specs)

    def linear_params(self) -> list[str]:
        return [s.name for s in self._specs if s.trainable and s.name[0] in "ck"]

    def _mck(self, p, lib):
        n = self.n_dof
        m = [p[f"m{i}"] for i in range(1, n + 1)]
        c = [p[f"c{i}"] for i in range(1, n + 1)]
        k = [p[f"k{i}"] for i in range(1, n + 1)]
        return m, _tridiag(c, lib), _tridiag(k, lib)

    def residual(self, k: Kinematics, f: torch.Tensor, p: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        m, C, K = self._mck(p, torch)
        M = torch.stack(m)
        rhs = -M[None, :] * f[:, None] if self.excitation == "ground" else f[:, None] * (torch.arange(self.n_dof) == self.n_dof - 1)
        return {"motion": M[None, :] * k.a + k.v @ C.T + k.x @ K.T - rhs}

    def state_rate(self, t, y, p, f):
        """Storey forces on the inter-storey drifts, element by element (no matrices), so
        the same code runs on NumPy and dual arrays."""
        n = self.n_dof
        x = [y[..., i] for i in range(n)]
        v = [y[..., n + i] for i in range(n)]
        storey = []
        for i in range(n):
            drift = x[i] - x[i - 1] if i else x[i]
            rate = v[i] - v[i - 1] if i else v[i]
            storey.append(p[f"k{i + 1}"] * drift + p[f"c{i + 1}"] * rate)
        acc = []
        for i in range(n):
            net = storey[i] - storey[i + 1] if i + 1 < n else storey[i]
            m = p[f"m{i + 1}"]
            ext = -m * f if self.excitation == "ground" else (f if i == n - 1 else 0.0 * f)
            acc.append((ext - net) / m)
        return np.stack(v + acc, axis=-1)

    def rhs(self, t: float, y: np.ndarray, p: dict[str, float], f: Callable[[float], float]) -> np.ndarray:
        return self.state_rate(t, np.asarray(y, dtype=float), p, f(t))

    def describe(self, p: dict[str, float]) -> str:
        return "M x'' + C x' + K x = -M 1 ag; " + ", ".join(f"{k}={v:.5g}" for k, v in p.items())
