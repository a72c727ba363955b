"""Output error over shooting segments: residuals and exact Jacobians for any system.

A record is cut into segments at sample indices b_0 < b_1 < ... < b_S = N - 1. Each segment
is simulated from its own initial state y_s (x, x' and latent z of every degree of freedom)
with the shared parameters theta, all segments as one batch (``pidyn.integrate.rk4``). The
residuals are the measured channels minus the simulated ones, each divided by its noise
level, and the continuity defects y_{s+1} - y_s(b_{s+1}) at the segment edges. One segment
with a fixed initial state is classical output error (single shooting).

Unknowns u = [theta (the parameters' unconstrained coordinates, as PIDynNet trains them),
y_0 / scale, ..., y_{S-1} / scale]; y_0 drops out when the initial state is fixed.
Jacobians are exact: the integrator runs on dual arrays with one direction per parameter
and one per state component (the state directions are shared by all segments, since a
segment depends on its own initial state only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix

from pidyn.autodiff import Dual
from pidyn.integrate import input_hold, piece_starts, rk4, stage_excitation
from pidyn.params import ParamSpec, fixed_values, from_theta, to_theta, trainable_specs
from pidyn.reporting import BLOWN_UP, diverged
from pidyn.systems.base import StructuralSystem

CHANNELS = ("x", "v", "a")


@dataclass
class Channel:
    """One measured signal: ``kind`` (x, v or a: relative to the ground) of degree of freedom ``dof``."""

    kind: str
    dof: int
    data: np.ndarray
    sigma: float  # noise std used as the residual's unit (refined from the residuals)
    weight: np.ndarray | None = None  # several records: each sample's record's weight (record_weights)

    @property
    def name(self) -> str:
        return self.kind if self.dof == 0 else f"{self.kind}{self.dof + 1}"

    def unit(self, rows) -> float | np.ndarray:
        """The residual's unit at samples ``rows``: the noise std over the record's weight."""
        return self.sigma if self.weight is None else self.sigma / self.weight[rows]


def record_weights(record, data: np.ndarray) -> np.ndarray | None:
    """Several records joined: each record's weight, the joined spread over its own to the power
    ``meta.record_weighting`` (None: 1), so the cost sums the records' squared NRMSE, the measure a
    prediction of the next record is scored by. At 0 (unweighted) the strongest events outweigh the
    rest by their amplitude squared; at 1 Painter Street's unseen events are predicted better, the
    strongest one worse (``experiments/results/real/README.md``). None for one record."""
    starts, power = piece_starts(record), record.meta.record_weighting
    if not starts or power == 0.0:
        return None
    edges, whole, w = [0, *starts, len(data)], max(float(np.nanstd(data)), 1e-300), np.ones(len(data))
    for i0, i1 in zip(edges[:-1], edges[1:]):
        piece = data[i0:i1][np.isfinite(data[i0:i1])]
        own = float(np.std(piece)) if piece.size else 0.0
        w[i0:i1] = (whole / own) ** (1.0 if power is None else power) if own > 0 else 1.0
    return w


def record_channels(record, n_dof: int) -> list[Channel]:
    """Every measured channel of a record, with its standard deviation as the first noise unit."""
    out = []
    for kind in CHANNELS:
        arr = getattr(record, kind, None)
        if arr is None:
            continue
        arr = np.asarray(arr, float).reshape(len(record.t), -1)
        if arr.shape[1] != n_dof:
            raise ValueError(
                f"record '{record.name}': channel '{kind}' has {arr.shape[1]} columns, "
                f"the system has {n_dof} degrees of freedom"
            )
        for j in range(n_dof):
            col = arr[:, j]
            if np.all(np.isnan(col)):
                continue
            out.append(Channel(kind, j, col, max(float(np.nanstd(col)), 1e-300), record_weights(record, col)))
    if not out:
        raise ValueError(f"record '{record.name}' has no measured response channel")
    return out


def _column(unit: float | np.ndarray) -> float | np.ndarray:
    return unit if np.ndim(unit) == 0 else np.asarray(unit)[:, None]  # to divide a Jacobian's rows


def segment_bounds(
    t: np.ndarray,
    length: float | None,
    t_start: float | None = None,
    t_end: float | None = None,
    breaks: tuple[int, ...] | list[int] = (),
) -> np.ndarray:
    """Sample indices b_0 < ... < b_S of segments of about ``length`` s over [t_start, t_end]
    (None: one segment). A last piece shorter than half a segment joins its neighbour.
    ``breaks``: sample indices where another record begins; with ``length`` every record is cut
    on its own, so that a segment never spans two records."""
    i0 = 0 if t_start is None else int(np.searchsorted(t, t_start - 1e-9))
    i1 = len(t) - 1 if t_end is None else int(np.searchsorted(t, t_end + 1e-9)) - 1
    if i1 - i0 < 2:
        raise ValueError(f"segment span [{t_start}, {t_end}] s holds fewer than 3 samples")
    if length is None:
        return np.array([i0, i1])
    step = max(2, int(round(length / float(t[1] - t[0]))))
    edges = [i0, *sorted(b for b in breaks if i0 + 2 < b < i1 - 2), i1]
    out: list[int] = []
    for a, z in zip(edges[:-1], edges[1:]):
        b = list(range(a, z, step))
        if z - b[-1] < step // 2 and len(b) > 1:
            b.pop()
        out += b
    return np.array(out + [i1])


#: a residual (noise units) is capped here: a blown-up trial step costs a large finite amount,
#: which the solvers reject, instead of an overflow
RESIDUAL_CAP = 1e8


def _bounded(r: np.ndarray) -> np.ndarray:
    return np.clip(
        np.nan_to_num(r, nan=RESIDUAL_CAP, posinf=RESIDUAL_CAP, neginf=-RESIDUAL_CAP),
        -RESIDUAL_CAP,
        RESIDUAL_CAP,
    )


class ShootingProblem:
    """Residuals r(u) of the measured channels and continuity defects c(u), with Jacobians."""

    def __init__(
        self,
        system: StructuralSystem,
        t: np.ndarray,
        f: np.ndarray,
        channels: list[Channel],
        bounds: np.ndarray,
        substeps: int = 4,
        fixed_state0: np.ndarray | None = None,
        state_scale: np.ndarray | None = None,
        fixed: dict[str, float] | None = None,
        hold: str = "linear",
        restarts: tuple[int, ...] | list[int] = (),
    ) -> None:
        """``fixed``: values of the known (non-trainable) parameters, default their specs' init;
        ``hold``: how the excitation is read between samples (``pidyn.integrate``); ``restarts``:
        sample indices where another record begins (``pidyn.data.multi``): a segment boundary
        there has its own free state and no continuity defect, a single segment restarts from
        rest there."""
        self.system = system
        self.t, self.f = np.asarray(t, float), np.asarray(f, float)
        self.channels = channels
        self.bounds = np.asarray(bounds, int)
        self.substeps = substeps
        self.specs: list[ParamSpec] = trainable_specs(system)
        self.fixed = {
            **fixed_values(system),
            **{k: v for k, v in (fixed or {}).items() if k in fixed_values(system)},
        }
        self.names = [s.name for s in self.specs]
        self.n_theta = len(self.specs)
        self.ns = system.n_state
        self.S = len(self.bounds) - 1
        self.restarts = sorted({int(r) for r in restarts if self.bounds[0] < int(r) < self.bounds[-1]})
        inner = set(int(b) for b in self.bounds[1:-1])
        if self.S > 1 and not set(self.restarts) <= inner:
            raise ValueError("segments must end where another record begins (segment_bounds(..., breaks=))")
        #: the continuity defects kept: between segments of one record
        self.link = np.array([int(b) not in set(self.restarts) for b in self.bounds[1:-1]], bool)
        self.fixed_state0 = None if fixed_state0 is None else np.asarray(fixed_state0, float).reshape(self.ns)
        self.state_scale = np.ones(self.ns) if state_scale is None else np.asarray(state_scale, float)
        lengths = np.diff(self.bounds)
        self.L = int(lengths.max())
        j = np.arange(self.L + 1)
        self.idx = np.minimum(self.bounds[:-1, None] + j[None, :], len(self.t) - 1)  # (S, L+1) sample index
        own = j[None, :] < lengths[:, None]  # a segment owns its samples up to (not incl.) its end ...
        own[-1, lengths[-1]] = True  # ... the last one its end too
        self.sel_s, self.sel_j = np.nonzero(own)
        self.ends = lengths
        self.t_local = self.t[: self.L + 1] - self.t[0]
        self.t0 = self.t[self.bounds[:-1]]
        self.F = np.swapaxes(self.f[self.idx], 0, 1)  # (L+1, S), or (L+1, S, n_inputs)
        self.hold = hold
        stages = stage_excitation(self.f, substeps, hold)  # of the whole record, then cut
        self.record_stages = stages
        self.stages = (
            None
            if stages is None
            else np.moveaxis(stages[np.minimum(self.idx[:, :-1], len(self.t) - 2)], 0, 2)
        )  # (L, 2 substeps + 1, S, ...)

    # ------------------------------------------------------------------ unknowns
    @property
    def free_state0(self) -> bool:
        return self.fixed_state0 is None

    @property
    def n_unknowns(self) -> int:
        return self.n_theta + self.ns * (self.S - (0 if self.free_state0 else 1))

    @classmethod
    def from_rest(
        cls, system: StructuralSystem, record, substeps: int = 4, fixed: dict[str, float] | None = None
    ) -> ShootingProblem:
        """Single shooting: one segment over the whole record, every measured channel, the
        initial state held at rest (output error and the simulated-channel checks)."""
        return cls(
            system,
            record.t,
            record.f,
            record_channels(record, system.n_dof),
            segment_bounds(record.t, None),
            substeps,
            fixed_state0=np.zeros(system.n_state),
            fixed=fixed,
            hold=input_hold(record),
            restarts=piece_starts(record),
        )

    def pack(self, values: dict[str, float], states: np.ndarray) -> np.ndarray:
        """u from physical parameter values and segment initial states (S, n_state)."""
        states = np.asarray(states, float).reshape(self.S, self.ns)
        keep = states if self.free_state0 else states[1:]
        return np.concatenate([to_theta(self.specs, values), (keep / self.state_scale).ravel()])

    def unpack(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(theta, states (S, n_state)) from u."""
        theta = u[: self.n_theta]
        rest = u[self.n_theta :].reshape(-1, self.ns) * self.state_scale
        states = rest if self.free_state0 else np.vstack([self.fixed_state0[None, :], rest])
        return theta, states

    def values(self, theta: np.ndarray) -> dict[str, float]:
        return {k: float(v) for k, v in from_theta(self.specs, np.asarray(theta, float)).items()}

    # ------------------------------------------------------------------ simulation
    def _params(self, theta: np.ndarray, dual: bool) -> dict:
        if not dual:
            p = from_theta(self.specs, theta)
        else:
            D = self.n_theta + self.ns
            eye = np.eye(D)
            p = from_theta(self.specs, [Dual(theta[i], eye[i]) for i in range(self.n_theta)])  # type: ignore[arg-type]
        p = dict(p)
        p.update(self.fixed)
        return p

    def simulate(self, u: np.ndarray, dual: bool = False):
        """States (L+1, S, n_state), rates and the accelerometers' readings (L+1, S, n_dof;
        ``StructuralSystem.acceleration_output``) of every segment (dual arrays when ``dual``)."""
        theta, states = self.unpack(u)
        y0 = states
        if dual:
            D = self.n_theta + self.ns
            d = np.zeros((self.S, self.ns, D))
            d[:, np.arange(self.ns), self.n_theta + np.arange(self.ns)] = self.state_scale
            if not self.free_state0:
                d[0] = 0.0
            y0 = Dual(states, d)
        p = self._params(theta, dual)
        with np.errstate(all="ignore"):
            inner = [r - int(self.bounds[0]) for r in self.restarts] if self.S == 1 else []
            Y, R = rk4(
                self.system,
                p,
                self.t_local,
                self.F,
                y0,
                self.substeps,
                t0=self.t0,
                stages=self.stages,
                restarts=inner,
            )
            return Y, R, self._accelerations(R, p, self.F)

    def _accelerations(self, R, p: dict, F: np.ndarray):
        """The accelerometers' readings from the rates: the relative x'' for one input, absolute
        (the influence-weighted ground added) for several."""
        n = self.system.n_dof
        return self.system.acceleration_output(R[..., n : 2 * n], F, p)

    def _channel_sim(self, Y, A, ch: Channel):
        n = self.system.n_dof
        if ch.kind == "x":
            return Y[..., ch.dof]
        if ch.kind == "v":
            return Y[..., n + ch.dof]
        return A[..., ch.dof]

    # ------------------------------------------------------------------ residuals
    def residuals(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(measured-channel residuals in noise units, continuity defects in state scales)."""
        Y, _, A = self.simulate(u)
        return self._data_res(Y, A), self._defects(u, Y)

    def _data_res(self, Y, A) -> np.ndarray:
        out = []
        rows = self.rows
        for ch in self.channels:
            sim = self._channel_sim(Y, A, ch)
            v = sim.v if isinstance(sim, Dual) else sim
            out.append((v[self.sel_j, self.sel_s] - ch.data[rows]) / ch.unit(rows))
        return _bounded(np.concatenate(out))

    def _defects(self, u: np.ndarray, Y) -> np.ndarray:
        if self.S == 1:
            return np.zeros(0)
        _, states = self.unpack(u)
        yv = Y.v if isinstance(Y, Dual) else Y
        end = yv[self.ends[:-1], np.arange(self.S - 1)]  # (S-1, ns)
        return _bounded(((states[1:] - end) / self.state_scale)[self.link].ravel())

    def _state_cols(self, s: np.ndarray) -> np.ndarray:
        """Columns of segment s's initial state in u (-1 where it is fixed)."""
        k = s if self.free_state0 else s - 1
        cols = self.n_theta + k[:, None] * self.ns + np.arange(self.ns)[None, :]
        return np.where(k[:, None] >= 0, cols, -1)

    def linearize(
        self, u: np.ndarray, sparse: bool = False
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """r, J = dr/du, c, C = dc/du, all exact. ``sparse``: J and C as scipy CSR matrices (a
        sample's row holds the parameters' and its own segment's columns only)."""
        Y, _, A = self.simulate(u, dual=True)
        r = self._data_res(Y, A)
        nt, n_u = self.n_theta, self.n_unknowns
        rows = self.rows
        G = np.concatenate(
            [
                self._channel_sim(Y, A, ch).d[self.sel_j, self.sel_s] / _column(ch.unit(rows))
                for ch in self.channels
            ]
        )  # (M, D): d r / d (theta, own segment's state)
        G[np.abs(r) >= RESIDUAL_CAP] = 0.0  # a capped (blown-up) residual is flat in u
        G[~(np.abs(G) < BLOWN_UP)] = 0.0
        cols = self._state_cols(np.tile(self.sel_s, len(self.channels)))
        rows = np.arange(len(r))
        if sparse:
            ok = cols >= 0
            J = csr_matrix(
                (
                    np.concatenate([G[:, :nt].ravel(), G[:, nt:][ok]]),
                    (
                        np.concatenate([np.repeat(rows, nt), np.broadcast_to(rows[:, None], cols.shape)[ok]]),
                        np.concatenate([np.tile(np.arange(nt), len(r)), cols[ok]]),
                    ),
                ),
                shape=(len(r), n_u),
            )
        else:
            J = np.zeros((len(r), n_u))
            J[:, :nt] = G[:, :nt]
            ok = cols[:, 0] >= 0
            J[rows[ok][:, None], cols[ok]] = G[ok, nt:]
        c = self._defects(u, Y)
        C = self._defect_jacobian(Y, c)
        return r, J, c, (csr_matrix(C) if sparse else C)

    def _defect_jacobian(self, Y, c: np.ndarray) -> np.ndarray:
        nt, ns = self.n_theta, self.ns
        C = np.zeros((len(c), self.n_unknowns))
        if self.S > 1 and self.link.any():
            s = np.nonzero(self.link)[0]
            end_d = Y.d[self.ends[s], s] / self.state_scale[None, :, None]  # (links, ns, D)
            rr = np.arange(len(s))[:, None] * ns + np.arange(ns)[None, :]  # defect rows
            C[rr.ravel(), :nt] = -end_d[..., :nt].reshape(-1, nt)
            own = self._state_cols(s)
            ok = own[:, 0] >= 0
            for k in np.nonzero(ok)[0]:
                C[np.ix_(rr[k], own[k])] = -end_d[k, :, nt:]
            nxt = self._state_cols(s + 1)
            C[rr.ravel(), nxt.ravel()] = 1.0
        # a capped (blown-up) defect is flat in u: its row carries no derivative
        C[np.abs(c) >= RESIDUAL_CAP] = 0.0
        C[~(np.abs(C) < BLOWN_UP)] = 0.0
        return C

    def residuals_and_fd_jacobian(
        self, u: np.ndarray, step: float = 1e-6, columns: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Residuals and their forward-difference Jacobian from one batched plain simulation.

        Single shooting only (from a fixed state, or from a free one: a window of the running
        period): the unperturbed and every perturbed unknown are members of one batch, so both
        cost about one simulation (the classical output-error recipe; the refinement uses the
        exact ``linearize``). ``columns``: the unknowns whose columns are wanted (default every
        one); each trajectory is integrated by itself, so a column is the same either way."""
        cols = np.arange(self.n_unknowns) if columns is None else np.asarray(columns, int)
        us = np.repeat(np.asarray(u, float)[:, None], len(cols) + 1, axis=1)
        us[cols, np.arange(1, len(cols) + 1)] += step
        res = self.batch_residuals(us)
        if not len(cols):
            return res[0], np.zeros((len(res[0]), 0))
        return res[0], np.stack([(res[j + 1] - res[0]) / step for j in range(len(cols))], axis=1)

    def batch_residuals(self, us: np.ndarray) -> list[np.ndarray]:
        """The residuals of every column of ``us`` (unknowns x batch) from one batched plain
        simulation (single shooting only)."""
        if self.S != 1:
            raise ValueError("a batch of unknowns is simulated for single shooting only")
        nt, B = self.n_theta, us.shape[1]
        p = dict(from_theta(self.specs, us[:nt]))
        p.update({k: np.full(B, v) for k, v in self.fixed.items()})
        if self.free_state0:
            y0 = (us[nt:] * self.state_scale[:, None]).T
        else:
            y0 = np.repeat(self.fixed_state0[None, :], B, axis=0)
        with np.errstate(all="ignore"):
            st = None if self.stages is None else self.stages[:, :, 0]
            Y, R = rk4(
                self.system,
                p,
                self.t_local,
                self.F[:, 0],
                y0,
                self.substeps,
                t0=float(self.t0[0]),
                stages=st,
                restarts=[r - int(self.bounds[0]) for r in self.restarts],
            )
            A = self._accelerations(
                R, p, np.broadcast_to(self.F[:, :1], (self.F.shape[0], B) + self.F.shape[2:])
            )
        return [self._data_res(Y[:, j : j + 1], A[:, j : j + 1]) for j in range(B)]

    def fd_fun_and_jac(self, columns: np.ndarray | None = None):
        """(fun, jac) for ``scipy.optimize.least_squares`` on ``residuals_and_fd_jacobian``: the
        residuals and the Jacobian at one point come from the same batch, one simulation for both.
        ``columns``: only these unknowns' columns (a profile holds the others; none: residuals alone)."""
        cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

        def evaluate(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            key = np.asarray(u, float).tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = self.residuals_and_fd_jacobian(u, columns=columns)
            return cache[key]

        return (lambda u: evaluate(u)[0]), (lambda u: evaluate(u)[1])

    # ------------------------------------------------------------------ helpers
    @property
    def rows(self) -> np.ndarray:
        """The record's sample behind each residual of a channel (``channel_slices`` order)."""
        return self.idx[self.sel_s, self.sel_j]

    def channel_slices(self) -> list[slice]:
        m = len(self.sel_s)
        return [slice(i * m, (i + 1) * m) for i in range(len(self.channels))]

    def free_run(
        self, theta: np.ndarray, y0: np.ndarray, i0: int | None = None, i1: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Samples i0..i1 (default: the whole span) as one trajectory from ``y0``: states
        (N_span, n_state) and rates."""
        i0 = int(self.bounds[0]) if i0 is None else i0
        i1 = int(self.bounds[-1]) if i1 is None else i1
        p = self._params(np.asarray(theta, float), False)
        with np.errstate(all="ignore"):
            Y, R = rk4(
                self.system,
                p,
                self.t[i0 : i1 + 1],
                self.f[i0 : i1 + 1],
                np.asarray(y0, float)[None, :],
                self.substeps,
                t0=float(self.t[i0]),
                stages=None if self.record_stages is None else self.record_stages[i0:i1],
                restarts=[r - i0 for r in self.restarts if i0 < r <= i1],
            )
        return Y[:, 0], R[:, 0]

    def free_run_cost(self, theta: np.ndarray, y0: np.ndarray) -> float:
        """Sum of squared channel residuals (noise units) of one free simulation over the span."""
        return self.free_run_fit(theta, y0)[0]

    def free_run_fit(self, theta: np.ndarray, y0: np.ndarray) -> tuple[float, bool]:
        """``free_run_cost`` and whether the simulation blows up (non-finite states, or beyond
        any response: a blown-up sample costs 1e16 in noise units)."""
        Y, R = self.free_run(theta, y0)
        i0, i1 = self.bounds[0], self.bounds[-1]
        n = self.system.n_dof
        with np.errstate(all="ignore"):
            A = self._accelerations(R, self._params(np.asarray(theta, float), False), self.f[i0 : i1 + 1])
        total = 0.0
        for ch in self.channels:
            sim = {"x": Y[:, ch.dof], "v": Y[:, n + ch.dof], "a": A[:, ch.dof]}[ch.kind]
            with np.errstate(all="ignore"):
                e = (sim - ch.data[i0 : i1 + 1]) / ch.unit(slice(i0, i1 + 1))
            total += float(np.sum(_bounded(e) ** 2))
        return total, diverged(Y)
