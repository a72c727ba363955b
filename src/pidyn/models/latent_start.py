"""A least-squares start for the parameters of latent states (Bouc-Wen's beta, gamma, n).

The motion residual is linear in c, k and the other linear parameters, so PIDynNet starts
them by one linear solve on its pretrained networks. The shape parameters of a latent state
enter only through z, and gradient training barely moves them: the LNN bends z to whatever
beta, gamma, n currently are (measured: beta, gamma, n stayed within a few per cent of their
starts, 37-89 % off the truth, on every El Centro cell). Yet given the motion x, x' the
latent path is fixed by those parameters and its initial value: integrate z' = g(x', z)
along the RPN's motion, and the motion residual is again linear in the rest. So the start
is a small variable-projection problem (Golub and Pereyra 1973): minimise over the latent
parameters (and z0 where the window does not start at rest) the motion residual left after
the linear solve. Its solution sets the parameters and is taught to the LNN.

Written for any system whose ``state_rate`` gives the latent rates from (x, x', z): SDOF
terms and storey terms of a shear building alike.
"""

from __future__ import annotations

import numpy as np
import torch

from pidyn.data.windows import Window
from pidyn.params import ParamSpec, PhysicalParameters, dvalue_draw, from_raw, in_range, to_raw
from pidyn.systems.base import Kinematics
from pidyn.systems.terms import heun_along


def latent_shape_params(system) -> list[str]:
    """Trainable parameters of latent-state terms that the motion residual is not linear in."""
    trainable = {s.name for s in system.param_specs() if s.trainable}
    out = []
    for term in getattr(system, "terms", []):
        if getattr(term, "n_latent", 0):
            out += [s.name for s in term.specs() if s.name not in term.linear and s.name in trainable]
    return out


def integrate_latent(
    system, t: np.ndarray, x: np.ndarray, v: np.ndarray, z0: np.ndarray, p: dict, substeps: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """z and z' along a prescribed motion for B parameter sets at once (Heun's rule, x and x'
    linear between samples). ``z0``: (B, n_latent); ``p``: floats or (B,) arrays.
    Returns (B, N, n_latent) twice; a path that blows up is NaN from there on."""
    nd = x.shape[1]
    B, nz = z0.shape
    z = np.full((B, len(t), nz), np.nan)
    zd = np.full((B, len(t), nz), np.nan)

    def rate(ti, xi, vi, zi):
        y = np.concatenate([np.broadcast_to(xi, (B, nd)), np.broadcast_to(vi, (B, nd)), zi], axis=1)
        return system.state_rate(ti, y, p, 0.0)[:, 2 * nd :]

    with np.errstate(all="ignore"):
        path = heun_along(rate, t, x, v, np.array(z0, dtype=float), substeps)  # (N, B, nz)
        for i in range(len(t)):
            z[:, i], zd[:, i] = path[i], rate(t[i], x[i], v[i], path[i])
    return z, zd


def _cumtrapz(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Trapezoidal integral of y from t[0] to each sample."""
    inc = 0.5 * (y[1:] + y[:-1]) * (t[1:] - t[:-1])[:, None]
    return np.concatenate([np.zeros_like(y[:1]), np.cumsum(inc, 0)], 0)


class LatentStart:
    """The variable-projection problem of one window, built on the networks' motion.

    The residual is the equation of motion integrated once from the start ts of the motion,
    M (x'(t) - x'(ts)) + int_ts^t (restoring - forcing) dt = 0: it needs the networks' x and x', which fit the data closely, and not their
    x'', which after pretraining is still 10 % off (measured on Bouc-Wen under El Centro) and
    drowns what z says about beta, gamma, n. Measured on the networks' motion of El Centro:
    from the start over 6 s, beta, gamma, n 10, 11, 2 % off; over 12 s the networks' small
    errors accumulate in the integral and the solution leaves (beta 43 for 1); in 1 s
    segments the residual is the networks' velocity error and beta, gamma, n are 74 % off.
    Hence one start, on the first span that determines them, and no later updates.
    """

    def __init__(
        self,
        system,
        params: PhysicalParameters,
        t: torch.Tensor,
        x: torch.Tensor,
        v: torch.Tensor,
        f: torch.Tensor,
        z0: np.ndarray | None,
    ) -> None:
        """The motion (t, x, x', excitation), from the networks or measured; ``z0``: the latent
        state at t[0] when known (at rest at a record's start), None to estimate it. The
        parameters' current values are the first start."""
        self.system = system
        self.names = latent_shape_params(self.system)
        self.linear = self.system.linear_params()
        self.specs: list[ParamSpec] = [params.spec(n) for n in self.names]
        self.t, self.x, self.v = (a.detach().double().numpy() for a in (t, x, v))
        self.f = f.detach().double()
        self.fn = self.f.numpy()
        self.nz = self.system.n_latent
        self.at_rest = z0 is not None
        self.z0_guess = np.zeros(self.nz) if z0 is None else np.asarray(z0, float).reshape(self.nz)
        self.z_scale = max(float(np.abs(self.x).max()), 1e-12)
        self.values = {n: float(v) for n, v in params.as_floats().items()}
        mass = self.values.get("m", 1.0) if self.system.excitation == "ground" else 1.0
        self.scale = max(float(self.f.std()) * mass, 1e-12) * max(float(self.t[-1] - self.t[0]), 1e-12)
        self.nu = len(self.specs) + (0 if self.at_rest else self.nz)

    # unknowns u = [raw latent params..., z0 / z_scale (unless at rest)]
    def unpack(self, U: np.ndarray) -> tuple[dict, np.ndarray]:
        """Rows of U (B, nu) -> parameters ((B,) arrays for the latent ones) and z0 (B, nz)."""
        p: dict = dict(self.values)
        for i, s in enumerate(self.specs):
            p[s.name] = from_raw(s, torch.from_numpy(U[:, i].copy())).numpy()
        z0 = np.tile(self.z0_guess, (len(U), 1)) if self.at_rest else U[:, len(self.specs) :] * self.z_scale
        return p, z0

    def start_vector(self) -> np.ndarray:
        u = [to_raw(s, self.values[s.name]) for s in self.specs]
        if not self.at_rest:
            u += list(self.z0_guess / self.z_scale)
        return np.array(u, dtype=float)

    def _linear_fit(self, pb: dict, z: np.ndarray, zd: np.ndarray, std: dict | None = None):
        """Solve the integrated motion residual for the linear parameters on one latent path
        (NumPy: it is affine in them, so n + 1 evaluations give its columns)."""
        dv = self.v - self.v[:1]

        def r(values: dict) -> np.ndarray:
            k0 = Kinematics(t=self.t, x=self.x, v=self.v, a=np.zeros_like(self.x), z=z, zd=zd)  # type: ignore[arg-type]
            kv = Kinematics(t=self.t, x=self.x, v=self.v, a=dv, z=z, zd=zd)  # type: ignore[arg-type]
            r0 = np.asarray(self.system.residual(k0, self.fn, values)["motion"])
            rv = np.asarray(self.system.residual(kv, self.fn, values)["motion"])
            return ((_cumtrapz(r0, self.t) + rv - r0) / self.scale).reshape(-1)

        zero = {**pb, **{n: 0.0 for n in self.linear}}
        r0 = r(zero)
        if not self.linear:
            return {}, r0
        J = np.stack([r({**zero, n: 1.0}) - r0 for n in self.linear], axis=1)
        sol = np.linalg.lstsq(J, -r0, rcond=None)[0]
        res = r0 + J @ sol
        if std is not None:
            dof = max(J.shape[0] - J.shape[1], 1)
            cov = np.linalg.pinv(J.T @ J, hermitian=True) * float(res @ res) / dof
            std.update({n: float(np.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(self.linear)})
        return {n: float(sol[i]) for i, n in enumerate(self.linear)}, res

    def residuals(self, U: np.ndarray) -> list[np.ndarray | None]:
        """The variable-projection residual of every row of U (None where the path blew up)."""
        p, z0 = self.unpack(U)
        z, zd = integrate_latent(self.system, self.t, self.x, self.v, z0, p)
        out = []
        for b in range(len(U)):
            if not np.all(np.isfinite(z[b])):
                out.append(None)
                continue
            pb = {n: (v[b] if isinstance(v, np.ndarray) else v) for n, v in p.items()}
            out.append(self._linear_fit(pb, z[b], zd[b])[1])
        return out

    def _lm(self, starts: np.ndarray, iters: int = 60) -> tuple[np.ndarray, float, np.ndarray]:
        """Levenberg-Marquardt from every start in lockstep: one batched integration gives all
        starts' forward-difference Jacobians, one more all their trial steps (a path costs about
        the same for one parameter set as for twenty). Returns the best (u, cost, Jacobian)."""
        S, nu = starts.shape
        U = starts.copy()
        R = self.residuals(U)
        cost = np.array([np.inf if r is None else float(r @ r) for r in R])
        lam = np.full(S, 1e-3)
        active = np.isfinite(cost)
        J: list[np.ndarray | None] = [None] * S
        for _ in range(iters):
            idx = np.flatnonzero(active)
            if not len(idx):
                break
            H = np.array([1e-6 * np.maximum(1.0, np.abs(U[i])) for i in idx])
            rows = self.residuals(np.vstack([U[i] + np.diag(H[j]) for j, i in enumerate(idx)]))
            trials, keep = [], []
            for j, i in enumerate(idx):
                cols = rows[j * nu : (j + 1) * nu]
                if any(c is None for c in cols):
                    active[i] = False
                    continue
                J[i] = np.stack([(cols[q] - R[i]) / H[j, q] for q in range(nu)], axis=1)
                g, A = J[i].T @ R[i], J[i].T @ J[i]
                trials.append(U[i] - np.linalg.solve(A + lam[i] * np.diag(np.diag(A) + 1e-12), g))
                keep.append(i)
            if not keep:
                break
            for i, u_new, r_new in zip(keep, trials, self.residuals(np.array(trials))):
                c_new = np.inf if r_new is None else float(r_new @ r_new)
                if c_new < cost[i]:
                    rel = (cost[i] - c_new) / max(cost[i], 1e-300)
                    U[i], R[i], cost[i], lam[i] = u_new, r_new, c_new, max(lam[i] / 10, 1e-9)
                    if rel < 1e-10:
                        active[i] = False
                else:
                    lam[i] *= 10
                    if lam[i] > 1e8:
                        active[i] = False
        b = int(np.argmin(cost))
        Jb = J[b] if J[b] is not None else np.zeros((0 if R[b] is None else len(R[b]), nu))
        return U[b], float(cost[b]), Jb

    def solve(self, n_screen: int = 32, n_local: int = 4, seed: int = 0) -> dict:
        """Screen random starts around the current values in one batched pass, polish the
        best few by Levenberg-Marquardt; return the best solution and its standard errors."""
        rng = np.random.default_rng(seed)
        u0 = self.start_vector()
        U = np.tile(u0, (n_screen + 1, 1))
        U[1:, : len(self.specs)] += rng.uniform(-1.1, 1.1, (n_screen, len(self.specs)))
        if not self.at_rest:  # z0 over its plausible range (|z| of the order of the motion)
            U[1:, len(self.specs) :] = rng.uniform(-1.0, 1.0, (n_screen, self.nz))
        rs = self.residuals(U)
        costs = np.array([np.inf if r is None else float(r @ r) for r in rs])
        cost0 = float(costs[0])
        picks = sorted({0, *[int(i) for i in np.argsort(costs)[:n_local] if np.isfinite(costs[i])]})
        u, cost, J = self._lm(U[picks])
        p, z0 = self.unpack(u[None])
        z, zd = integrate_latent(self.system, self.t, self.x, self.v, z0, p)
        pb = {n: float(v[0]) if isinstance(v, np.ndarray) else v for n, v in p.items()}
        std: dict[str, float] = {}
        lin, r = self._linear_fit(pb, z[0], zd[0], std=std)
        pb.update(lin)
        dof = max(J.shape[0] - J.shape[1] - len(lin), 1)
        cov = np.linalg.pinv(J.T @ J) * cost / dof
        for i, s in enumerate(self.specs):
            std[s.name] = float(np.sqrt(max(cov[i, i], 0.0)) * abs(dvalue_draw(s, float(u[i]))))
        # a value at the edge of its transform's range (a log-parameter driven to 0, a box one to a
        # bound) has a vanishing d value / d raw: its small standard error says nothing
        edge = [s.name for i, s in enumerate(self.specs) if abs(u[i]) > 12.0]
        return {"params": pb, "z": z[0], "std": std, "cost": cost, "cost_start": cost0, "at_edge": edge}


def fit_latent_network(net, w: Window, z_path: np.ndarray, iters: int = 400, lr: float = 3e-3) -> float:
    """Teach the LNN a latent path (supervised, like the RPN's pretraining); returns the final
    relative RMS misfit."""
    target = torch.as_tensor(z_path, dtype=w.t_data.dtype)
    scale = target.abs().max().clamp_min(1e-12)
    with torch.no_grad():
        net.z_offset.zero_()
    opt = torch.optim.Adam(net.lnn.parameters(), lr=lr)
    loss = torch.zeros(())
    for _ in range(iters):
        opt.zero_grad()
        k = net.kinematics(w.t_data, w.f_data, w.q_data, w.qd_data, order=0, latent=True)
        loss = (((k.z - target) / scale) ** 2).mean()
        loss.backward()
        opt.step()
    return float(loss.detach().sqrt())


def teach_current_path(net, w: Window, z0: torch.Tensor) -> float:
    """Teach the LNN the latent path the current parameters give along this window's
    (pretrained) motion from ``z0``: a start consistent with beta, gamma, n, where a copy of
    the RPN (the paper's transfer) is a z of the wrong shape that training then bends the
    parameters to. Returns the LNN's relative misfit (NaN where the path blew up)."""
    m = motion_on_samples(net, w)
    p = net.params.as_floats()
    z, _ = integrate_latent(
        net.system,
        m["t"].double().numpy(),
        m["x"].double().numpy(),
        m["v"].double().numpy(),
        z0.detach().double().numpy().reshape(1, -1),
        p,
    )
    if not np.all(np.isfinite(z)):
        return float("nan")
    return fit_latent_network(net, w, z[0])


def motion_on_samples(net, w: Window) -> dict[str, torch.Tensor]:
    """The networks' x and x' at the window's data samples, with the excitation there."""
    with torch.no_grad():
        k = net.kinematics(w.t_data, w.f_data, w.q_data, w.qd_data, order=1, latent=False)
    return {
        "t": w.t_data.detach().clone(),
        "x": k.x.detach().clone(),
        "v": k.v.detach().clone(),
        "f": w.f_data.detach().clone(),
    }


def join_motions(parts: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """Consecutive windows' motions as one record (a shared edge sample kept once, the later
    window's value)."""
    out: dict[str, list[torch.Tensor]] = {k: [] for k in ("t", "x", "v", "f")}
    for i, m in enumerate(parts):
        keep = torch.ones_like(m["t"], dtype=torch.bool)
        if i + 1 < len(parts):
            keep = m["t"] < parts[i + 1]["t"][0] - 1e-9
        for k in out:
            out[k].append(m[k][keep])
    return {k: torch.cat(v) for k, v in out.items()}


def latent_least_squares_start(
    net, w: Window, history: list[dict[str, torch.Tensor]], at_rest: bool, max_rel_std: float = 0.5
) -> tuple[dict[str, float], dict[str, float], str]:
    """Solve the variable-projection problem on the motion so far (earlier windows' ``history``
    and this window's networks): one window alone does not pin beta, gamma, n down (measured:
    beta 0.49 +- 1.5 from 3 s of El Centro), the record so far does. Set the parameters when
    every one is determined, and teach the LNN this window's part of the latent path.
    ``at_rest``: the motion starts at the record's start, at rest. Returns (accepted, rejected,
    a line for the log)."""
    now = motion_on_samples(net, w)
    m = join_motions([*history, now])
    prob = LatentStart(
        net.system,
        net.params,
        m["t"],
        m["x"],
        m["v"],
        m["f"],
        np.zeros(net.system.n_latent) if at_rest else None,
    )
    if not prob.names:
        return {}, {}, ""
    out = prob.solve()
    p, std = out["params"], out["std"]
    names = prob.names + prob.linear
    bad = {
        n: p[n]
        for n in names
        if not np.isfinite(p[n]) or std.get(n, 0.0) > max_rel_std * max(abs(p[n]), 1e-300)
    }
    bad.update({n: p[n] for n in names if not in_range(net.params.spec(n), p[n])})
    bad.update({n: p[n] for n in out["at_edge"]})
    line = (
        f"window {w.index}: latent least-squares start over {m['t'][0]:.1f}-{m['t'][-1]:.1f} s "
        f"(integrated motion misfit {out['cost_start']:.3g} -> {out['cost']:.3g}): "
        + ", ".join(f"{n}={p[n]:.4g} +- {std.get(n, 0.0):.2g}" for n in names)
    )
    if bad or out["cost"] > out["cost_start"]:
        return {}, {n: p[n] for n in prob.names}, line
    accepted = {n: p[n] for n in names}
    net.params.set_values(accepted)
    tail = out["z"][-len(now["t"]) :]
    misfit = fit_latent_network(net, w, tail)
    return accepted, {}, line + f"; LNN taught the path (relative misfit {misfit:.2g})"
