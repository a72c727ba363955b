"""A structure as N modes driven by several supports: modal superposition, the class of a
state-space realization of order 2N.

A bridge deck's accelerometer on three supports sees more than one mode when the supports
drive modes that a single degree of freedom cannot hold (a second mode at 0.25 s beside the
0.30 s one on Painter Street's longitudinal channel in 1987). Each mode r is an oscillator per
unit modal mass driven by the supports:

    q_r'' + c_r q_r' + k_r q_r = -sum_j r_rj ag_j + sum_j g_rj vg_j

and the sensor reads the modes and, as a rigid body, the supports:

    a = sum_r q_r'' + sum_j (sum_r r_rj + e_j) ag_j

Each mode contributes ((g_rj + r_rj c_r) s + r_rj k_r) / (s^2 + c_r s + k_r) to the transfer
function of support j, and e_j is what it reads of the support directly: N = 1 is the
single degree of freedom on supports (``SDOFSystem`` with inputs), and with r, g and e every
order-2N realization with oscillatory poles is one of these models. With one input the record
keeps accelerations relative to the ground: each mode has a participation ``r<r>`` and the
sensor reads sum_r q_r''. A second sensor o reads sum_r phi_or q_r'' (+ its supports' share),
``phi<o>_<r>`` its view of mode r; the sensor's modal coordinate scale is the first sensor's.

Parameters: ``c<r>``, ``k<r>`` (per unit modal mass: s^-1 and s^-2), ``r<r>_<input>``,
``g<r>_<input>``, ``e_<input>`` (``e<o>_<input>`` for sensor o > 1).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import torch

from pidyn.params import ParamSpec
from pidyn.systems.base import ExcitationKind, Kinematics, StructuralSystem, merge_specs, stack_last
from pidyn.systems.terms import signed_sum


class ModesOnSupports(StructuralSystem):
    """N modes, one input or several supports, one or more sensors; named residual ``motion``."""

    #: its degrees of freedom are modal coordinates: it has frequencies and damping, no mode shapes
    modal_coordinates = True
    linear_time_invariant = True

    def __init__(
        self,
        n_modes: int = 2,
        periods: Sequence[float] | float = (2.0, 0.7),
        damping_ratio: float = 0.05,
        n_outputs: int = 1,
        inputs: Sequence[str] | None = None,
        excitation: ExcitationKind = "ground",
        params: dict | None = None,
        name: str = "modes",
    ) -> None:
        super().__init__(excitation)
        if excitation != "ground":
            raise ValueError(f"{name}: modes on supports are ground-excited; got excitation '{excitation}'")
        n = int(n_modes)
        if n < 1:
            raise ValueError(f"{name}: n_modes must be >= 1, got {n_modes}")
        if not 1 <= int(n_outputs) <= n:
            raise ValueError(f"{name}: n_outputs must lie in [1, n_modes={n}], got {n_outputs}")
        self.name, self.n_dof, self.n_outputs = name, n, int(n_outputs)
        self.inputs = tuple(str(i) for i in (inputs or ()))
        if len(self.inputs) == 1:
            self.inputs = ()  # one input is the plain ag, the record relative to it
        if len(set(self.inputs)) != len(self.inputs):
            raise ValueError(f"{name}: input names repeat: {list(self.inputs)}")
        periods = [float(periods)] * n if isinstance(periods, (int, float)) else [float(p) for p in periods]
        if len(periods) < n:  # further modes at shorter periods, each a third of the last
            periods += [periods[-1] / 3 ** (i + 1) for i in range(n - len(periods))]
        self._specs = merge_specs(self._default_specs(periods[:n], float(damping_ratio)), params)

    # ------------------------------------------------------------------ parameters
    def _default_specs(self, periods: list[float], zeta: float) -> list[ParamSpec]:
        n, ins = self.n_dof, self.inputs
        specs: list[ParamSpec] = []
        for r, period in enumerate(periods, 1):
            w = 2 * np.pi / period
            specs += [  # the config's modes are also the truth a simulated record is drawn from
                ParamSpec(f"c{r}", init=2 * zeta * w, scale=2 * zeta * w, true=2 * zeta * w, unit="1/s"),
                ParamSpec(f"k{r}", init=w**2, scale=w**2, true=w**2, unit="1/s^2"),
            ]
        share = 1.0 / max(len(ins), 1)
        for r in range(1, n + 1):
            gamma = 1.0 if r == 1 else 0.3  # higher modes start with a smaller share
            if not ins:
                specs.append(
                    ParamSpec(f"r{r}", init=gamma, scale=gamma, transform="identity", true=gamma, unit="-")
                )
                continue
            c_r = next(s.init for s in specs if s.name == f"c{r}")
            for i in ins:
                specs += [
                    ParamSpec(
                        f"r{r}_{i}",
                        init=gamma * share,
                        scale=share,
                        transform="identity",
                        true=gamma * share,
                        unit="-",
                    ),
                    ParamSpec(
                        f"g{r}_{i}", init=0.0, scale=c_r * share, transform="identity", true=0.0, unit="1/s"
                    ),
                ]
        for o in range(2, self.n_outputs + 1):
            specs += [
                ParamSpec(f"phi{o}_{r}", init=1.0, scale=1.0, transform="identity", true=1.0, unit="-")
                for r in range(1, n + 1)
            ]
        for o in range(1, self.n_outputs + 1):
            specs += [
                ParamSpec(
                    self.feedthrough(o, i),
                    init=0.0,
                    scale=0.1 * share,
                    transform="identity",
                    true=0.0,
                    unit="-",
                )
                for i in ins
            ]
        return specs

    @staticmethod
    def feedthrough(output: int, input_name: str) -> str:
        """What sensor ``output`` (1-based) reads of a support directly: ``e_<input>``, ``e2_<input>``."""
        return f"e_{input_name}" if output == 1 else f"e{output}_{input_name}"

    def param_specs(self) -> list[ParamSpec]:
        return list(self._specs)

    def period_scaling(self) -> dict[str, float]:
        """Each mode's k 2, its c and its support dashpots 1: every mode's period moves together."""
        powers = {}
        for r in range(1, self.n_dof + 1):
            powers |= {f"k{r}": 2.0, f"c{r}": 1.0} | {f"g{r}_{i}": 1.0 for i in self.inputs}
        return powers

    def linear_params(self) -> list[str]:
        return []  # the sensor sees a sum of modes: no residual is linear in a mode's own c and k

    # ------------------------------------------------------------------ equations
    def _participation(self, r: int, j: int | None) -> str:
        return f"r{r}" if j is None else f"r{r}_{self.inputs[j]}"

    def modal_forces(self, f, p) -> list:
        """The right-hand side of each mode: -sum_j r_rj ag_j + sum_j g_rj vg_j."""
        out = []
        for r in range(1, self.n_dof + 1):
            if not self.inputs:
                out.append(-p[f"r{r}"] * f)
                continue
            n_in, total = len(self.inputs), None
            for j, i in enumerate(self.inputs):
                part = -p[f"r{r}_{i}"] * f[..., j] + p[f"g{r}_{i}"] * f[..., n_in + j]
                total = part if total is None else total + part
            out.append(total)
        return out

    def ground_motion(self, f, p):
        """Each mode's weighted support acceleration sum_j r_rj ag_j, on a last axis (..., N)."""
        if not self.inputs:
            return stack_last([p[f"r{r}"] * f for r in range(1, self.n_dof + 1)], f)
        parts = []
        for r in range(1, self.n_dof + 1):
            total = None
            for j, i in enumerate(self.inputs):
                part = p[f"r{r}_{i}"] * f[..., j]
                total = part if total is None else total + part
            parts.append(total)
        return stack_last(parts, parts[0])

    def acceleration_output(self, a_rel, f, p):
        """Sensor o's reading in column o - 1: sum_r phi_or (q_r'' + its supports' share) plus
        e_o ag; columns past the sensors hold each mode's own (no record measures them)."""
        n = self.n_dof
        ground = self.ground_motion(f, p) if self.inputs else None
        cols = []
        for o in range(1, n + 1):
            if o > self.n_outputs:
                cols.append(a_rel[..., o - 1] if ground is None else a_rel[..., o - 1] + ground[..., o - 1])
                continue
            total = None
            for r in range(1, n + 1):
                w = 1.0 if o == 1 else p[f"phi{o}_{r}"]
                mode = a_rel[..., r - 1] if ground is None else a_rel[..., r - 1] + ground[..., r - 1]
                total = w * mode if total is None else total + w * mode
            for j, i in enumerate(self.inputs):
                total = total + p[self.feedthrough(o, i)] * f[..., j]
            cols.append(total)
        return stack_last(cols, cols[0])

    def residual(self, k: Kinematics, f: torch.Tensor, p: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        rhs = self.modal_forces(f, p)
        motion = [
            k.a[..., r] + p[f"c{r + 1}"] * k.v[..., r] + p[f"k{r + 1}"] * k.x[..., r] - rhs[r]
            for r in range(self.n_dof)
        ]
        return {"motion": stack_last(motion, k.x)}

    def state_rate(self, t, y, p, f):
        n = self.n_dof
        x, v = y[..., :n], y[..., n : 2 * n]
        rhs = self.modal_forces(f, p)
        acc = [rhs[r] - p[f"c{r + 1}"] * v[..., r] - p[f"k{r + 1}"] * x[..., r] for r in range(n)]
        parts = [v[..., r] for r in range(n)] + acc
        if all(
            isinstance(q, (float, np.floating)) or (isinstance(q, np.ndarray) and q.ndim == 0) for q in parts
        ):
            return np.array([float(q) for q in parts])
        return stack_last(parts, parts[0])

    def rhs(self, t: float, y: np.ndarray, p: dict[str, float], f: Callable[[float], float]) -> np.ndarray:
        return self.state_rate(t, np.asarray(y, dtype=float), p, f(t))

    def start_at(self, frequency_hz: float, zeta: float) -> dict[str, float]:
        """Starting values with the fundamental at ``frequency_hz`` and every mode damped at
        ``zeta`` (the data start's transfer-function peak); the others keep their ratios to it."""
        init = {s.name: float(s.init) for s in self._specs}
        w1 = np.sqrt(init["k1"])
        out = {}
        for r in range(1, self.n_dof + 1):
            w = 2 * np.pi * frequency_hz * np.sqrt(init[f"k{r}"]) / w1
            out[f"k{r}"], out[f"c{r}"] = w**2, 2 * zeta * w
        return out

    def from_single_mode(self, values: Mapping[str, float]) -> dict[str, float] | None:
        """A single degree of freedom's estimate on the same supports (``c, k, r_<i>, g_<i>,
        e_<i>``) as mode 1, further modes at the config's period ratios and the same damping
        ratio, driven a tenth as much (what the sensor reads of the supports unchanged): the
        modes model starts next to where the simpler one ended. None when ``values`` is not one."""
        if not {"c", "k"} <= set(values) or any(f"r_{i}" not in values for i in self.inputs):
            return None
        init = {s.name: float(s.init) for s in self._specs}
        c, k = float(values["c"]), float(values["k"])
        out = {"c1": c, "k1": k}
        for r in range(2, self.n_dof + 1):
            ratio = init[f"k{r}"] / init["k1"]
            out[f"k{r}"], out[f"c{r}"] = k * ratio, c * np.sqrt(ratio)
        for r in range(1, self.n_dof + 1):
            w = 1.0 if r == 1 else 0.1
            if not self.inputs:
                out[f"r{r}"] = w
            for i in self.inputs:
                out[f"r{r}_{i}"] = w * float(values[f"r_{i}"])
                out[f"g{r}_{i}"] = float(values.get(f"g_{i}", 0.0)) if r == 1 else 0.0
        for (
            i
        ) in self.inputs:  # the further modes' supports' share comes out of what the sensor reads directly
            share = sum(out[f"r{r}_{i}"] for r in range(2, self.n_dof + 1))
            out[self.feedthrough(1, i)] = float(values.get(f"e_{i}", 0.0)) - share
        return out

    # ------------------------------------------------------------------ for engineers
    def linear_matrices(self, p: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit modal masses, each mode's damping and stiffness (diagonal: the modes are uncoupled)."""
        n = self.n_dof
        return (
            np.eye(n),
            np.diag([float(p[f"c{r}"]) for r in range(1, n + 1)]),
            np.diag([float(p[f"k{r}"]) for r in range(1, n + 1)]),
        )

    def describe(self, p: dict[str, float]) -> str:
        lines = []
        for r in range(1, self.n_dof + 1):
            if self.inputs:
                drive = signed_sum(
                    [f"{p[f'r{r}_{i}']:.4g} ag_{i}" for i in self.inputs]
                    + [f"{-p[f'g{r}_{i}']:.4g} vg_{i}" for i in self.inputs]
                )
            else:
                drive = f"{p[f'r{r}']:.4g} ag"
            lines.append(f"q{r}'' + {p[f'c{r}']:.5g} q{r}' + {p[f'k{r}']:.5g} q{r} = -({drive})")
        parts = [f"q{r}''" for r in range(1, self.n_dof + 1)]
        if self.inputs:
            parts += [
                f"{sum(p[f'r{r}_{i}'] for r in range(1, self.n_dof + 1)) + p[self.feedthrough(1, i)]:.4g} ag_{i}"
                for i in self.inputs
            ]
        sensor = signed_sum(parts)
        return "; ".join(lines) + f"; sensor: {sensor}"
