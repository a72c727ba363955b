"""PIDynNet in plain PyTorch: response network (RPN), latent network (LNN), physical
parameters and the named loss terms of paper Eq. 7-13. No training framework here: the
Lightning module and the benchmark's plain loop both drive this object.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from pidyn.data.windows import Window
from pidyn.nets import TaylorMLP
from pidyn.params import PhysicalParameters, in_range
from pidyn.systems.base import Kinematics, StructuralSystem
from pidyn.systems.lstsq import forward_jacobian, lstsq, solve_linear_params


class PIDynNet(nn.Module):
    """RPN (t -> x), optional LNN (t -> z), trainable physical parameters, named losses.

    Loss terms (all dimensionless, each divided by its window scale so that unit weights
    balance them; paper Eq. 8, 9, 12):
      ``physics/motion``: mean ((m x'' + restoring - forcing) / force scale)^2
      ``physics/<latent>``: mean ((z' - g(x', z)) / velocity scale)^2
      ``data/x``, ``data/v``, ``data/a``: mean ((pred - measured) / channel scale)^2
    """

    def __init__(
        self,
        system: StructuralSystem,
        rpn: TaylorMLP,
        lnn: TaylorMLP | None = None,
        normalize_losses: bool = True,
    ) -> None:
        super().__init__()
        self.system = system
        self.params = PhysicalParameters(system.param_specs())
        self.rpn = rpn
        if system.n_latent and lnn is None:
            raise ValueError(f"{system.name} has latent states {system.latent_names}: an LNN is required")
        self.lnn = lnn if system.n_latent else None
        self.normalize_losses = normalize_losses
        # networks inside the equations (a learned force term): trained with the networks, saved in checkpoints
        self.learned = nn.ModuleList(
            [t.net for t in getattr(system, "terms", []) if isinstance(getattr(t, "net", None), nn.Module)]
        )
        nd, nz = system.n_dof, system.n_latent
        self.register_buffer("z_offset", torch.zeros(max(nz, 1)))
        self.register_buffer("scale_x", torch.ones(nd))
        self.register_buffer("scale_v", torch.ones(nd))
        self.register_buffer("scale_a", torch.ones(nd))
        self.register_buffer("scale_f", torch.ones(()))
        # displacement drift of the current window, x += scale_x (d0 + d1 tau): used where the
        # displacement is not measured (floor accelerometers), where the data leave x + a + b t
        # free and the physics alone pins a and b (see ``solve_drift``)
        self.drift = nn.Parameter(torch.zeros(2, nd))
        self.use_drift = False
        # hard initial condition for prediction: (t0, x0, v0, z0) or None
        self.anchor: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None] | None = None

    def _apply(self, fn, recurse: bool = True):  # type: ignore[override]
        # .to() / .cpu() / .double() carry the prediction anchor along (plain tensors, not state)
        super()._apply(fn, recurse)
        if self.anchor is not None:
            self.anchor = tuple(None if a is None else fn(a) for a in self.anchor)  # type: ignore[assignment]
        return self

    # ----------------------------------------------------------------- windows
    @torch.no_grad()
    def enter_window(self, w: Window, transfer_lnn: bool = False) -> None:
        """Map the networks to the window's local time and set the loss scales."""
        s = w.scales()
        if self.normalize_losses:
            self.scale_x.copy_(s["x"])
            self.scale_v.copy_(s["v"])
            self.scale_a.copy_(s["a"])
            m = self.params.values()
            mass = m.get("m", torch.ones(()))
            self.scale_f.copy_(s["f"] * (mass if self.system.excitation == "ground" else 1.0))
        for net in (self.rpn, self.lnn):
            if net is not None:
                net.set_window(w.t0, w.t1)
        self.use_drift = not w.complete.get("x", False)
        self.drift.zero_()
        q = w.q_data[:, None] if w.q_data is not None else torch.zeros_like(w.t_data)[:, None]
        if w.complete.get("x", False):
            y = w.x + q
            self.rpn.set_output_scale(y.std(0).clamp_min(1e-12), y.mean(0))
        else:  # displacement not measured everywhere: its estimated spread beside the ground's
            self.rpn.set_output_scale(
                torch.sqrt(s["x"] ** 2 + q.std() ** 2).clamp_min(1e-12), q.mean() * torch.ones_like(s["x"])
            )
        if self.lnn is not None and transfer_lnn:
            self.transfer_rpn_to_lnn()

    @torch.no_grad()
    def transfer_rpn_to_lnn(self) -> None:
        """Transfer-learning initialisation (paper): LNN starts as a copy of the RPN."""
        assert self.lnn is not None
        if self.lnn.layers[-1].out_features != self.rpn.layers[-1].out_features:
            # copy the hidden layers and repeat the output row for each latent state
            for a, b in zip(self.lnn.layers[:-1], self.rpn.layers[:-1]):
                a.load_state_dict(b.state_dict())
            last_l, last_r = self.lnn.layers[-1], self.rpn.layers[-1]
            last_l.weight.copy_(last_r.weight[:1].expand_as(last_l.weight))
            last_l.bias.copy_(last_r.bias[:1].expand_as(last_l.bias))
        else:
            self.lnn.load_state_dict(copy.deepcopy(self.rpn.state_dict()))
        self.lnn.set_output_scale(
            self.rpn.out_scale[:1].expand_as(self.lnn.out_scale),
            self.rpn.out_shift[:1].expand_as(self.lnn.out_shift),
        )
        self.lnn.t_mid.copy_(self.rpn.t_mid)
        self.lnn.t_half.copy_(self.rpn.t_half)

    @torch.no_grad()
    def set_latent_offset(self, z0: torch.Tensor, x0: torch.Tensor) -> None:
        """Paper: add (z0 - x0) to the LNN output so z starts where the last window left it."""
        self.z_offset.copy_((z0 - x0).reshape(-1)[: self.z_offset.numel()])

    # ----------------------------------------------------------------- forward
    def kinematics(
        self,
        t: torch.Tensor,
        f: torch.Tensor | None = None,
        q: torch.Tensor | None = None,
        qd: torch.Tensor | None = None,
        order: int = 2,
        latent: bool = True,
    ) -> Kinematics:
        """x, x', x'' (and z, z') at ``t``.

        With the excitation transform the networks represent y = x + q and z + q, where
        q'' is the excitation as an acceleration (ag, or -u/m) with q(t0) = q'(t0) = 0 in
        the window. Then x = y - q, x' = y' - q', x'' = y'' - q''. This is an exact change of
        variable; it spares the network the broadband ag that x'' must otherwise contain
        (y is the smooth absolute displacement of a base-excited structure).
        ``latent=False`` skips the LNN (the data terms need x only).
        """
        fin = f if self.rpn.use_excitation_input else None
        xs = self.rpn.taylor(t, order=order, f=fin)
        if self.anchor is not None:
            xs = self._anchored(self.rpn, t, xs, f)
        x, v = xs[0], xs[1] if order >= 1 else None
        a = xs[2] if order >= 2 else None
        if self.use_drift:
            tau = ((t - self.rpn.t_mid) / self.rpn.t_half)[:, None]
            x = x + self.scale_x * (self.drift[0] + self.drift[1] * tau)
            v = v + self.scale_x * self.drift[1] / self.rpn.t_half if v is not None else None
        if q is not None:
            assert qd is not None and f is not None
            x = x - q[:, None]
            v = v - qd[:, None] if v is not None else None
            if a is not None:
                a = a - self.system.excitation_as_acceleration(f)[:, None]
        z = zd = None
        if self.lnn is not None and latent:
            zs = self.lnn.taylor(t, order=1, f=fin)
            if self.anchor is not None and self.anchor[3] is not None:
                t0 = self.anchor[0].reshape(1)
                zs = [
                    zs[0]
                    - self.lnn.taylor(t0, order=0, f=None if fin is None else fin[:1])[0]
                    + self.anchor[3],
                    zs[1],
                ]
                z, zd = zs[0], zs[1]
            else:
                z, zd = zs[0] + self.z_offset, zs[1]
            if q is not None:
                z, zd = z - q[:, None], zd - qd[:, None]
        return Kinematics(t=t, x=x, v=v, a=a, z=z, zd=zd)  # type: ignore[arg-type]

    def _anchored(self, net: TaylorMLP, t: torch.Tensor, ys: list[torch.Tensor], f: torch.Tensor | None):
        """y - y(t0) - y'(t0)(t - t0) + x0 + v0 (t - t0): the initial state holds exactly.

        Valid because q(t0) = q'(t0) = 0, so the state at t0 is that of y itself.
        """
        assert self.anchor is not None
        t0, x0, v0, _ = self.anchor
        fin = f[:1] if (f is not None and net.use_excitation_input) else None
        y0 = net.taylor(t0.reshape(1), order=1, f=fin)
        dt = (t - t0)[:, None]
        out = [ys[0] - y0[0] - y0[1] * dt + x0 + v0 * dt]
        if len(ys) > 1:
            out.append(ys[1] - y0[1] + v0)
        out.extend(ys[2:])
        return out

    def physics_losses(
        self, t: torch.Tensor, f: torch.Tensor, q: torch.Tensor | None = None, qd: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        k = self.kinematics(t, f, q, qd)
        res = self.system.residual(k, f, self.params.values())
        out = {"physics/motion": ((res.pop("motion") / self.scale_f) ** 2).mean()}
        for name, r in res.items():
            out[f"physics/{name}"] = ((r / self.scale_v[0]) ** 2).mean()
        return out

    def data_losses(self, w: Window, fill: bool = False) -> dict[str, torch.Tensor]:
        """Supervised terms over the measured entries; ``fill`` (pretraining only) also fits the
        floors without a sensor to their neighbours' signals interpolated over the floor number."""
        need = 2 if w.a is not None else (1 if w.v is not None else 0)
        k = self.kinematics(w.t_data, w.f_data, w.q_data, w.qd_data, order=need, latent=False)
        a = k.a
        if a is not None and self.system.n_inputs > 1:  # several supports: the record's a is absolute
            a = self.system.acceleration_output(a, w.f_data, self.params.values())
        out = {}
        for name, pred, meas, scale in (
            ("x", k.x, w.x, self.scale_x),
            ("v", k.v, w.v, self.scale_v),
            ("a", a, w.a, self.scale_a),
        ):
            complete = w.complete.get(name, False)
            if fill and meas is not None:
                meas, complete = w.filled(name)
            if meas is not None:
                out[f"data/{name}"] = _masked_mse(pred, meas, scale, complete)
        return out

    @torch.no_grad()
    def enter_prediction_window(
        self, w: Window, x_scale: torch.Tensor, v_scale: torch.Tensor, f_scale: torch.Tensor
    ) -> None:
        """Like ``enter_window`` for a window without measurements (scales given).

        The force scale is the whole record's, so a loss value means the same in every
        window of a prediction.
        """
        self.scale_x.copy_(x_scale)
        self.scale_v.copy_(v_scale)
        self.use_drift = False
        self.drift.zero_()
        mass = self.params.values().get("m", torch.ones(()))
        self.scale_f.copy_(f_scale.clamp_min(1e-12) * (mass if self.system.excitation == "ground" else 1.0))
        for net in (self.rpn, self.lnn):
            if net is not None:
                net.set_window(w.t0, w.t1)
        y_scale = torch.maximum(
            x_scale, (w.q_pool.std() if w.q_pool is not None else x_scale[0]) * torch.ones_like(x_scale)
        )
        self.rpn.set_output_scale(y_scale, torch.zeros_like(x_scale))
        if self.lnn is not None:
            self.lnn.set_output_scale(
                y_scale[:1].expand_as(self.lnn.out_scale), torch.zeros_like(self.lnn.out_shift)
            )

    @torch.no_grad()
    def state_at_end(self, w: Window) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        sl = slice(-1, None)
        k = self.kinematics(
            w.t_pool[sl],
            w.f_pool[sl],
            None if w.q_pool is None else w.q_pool[sl],
            None if w.qd_pool is None else w.qd_pool[sl],
            order=1,
        )
        return k.x[0], k.v[0], None if k.z is None else k.z[0]

    # ----------------------------------------------------------------- helpers
    def net_parameters(self) -> list[nn.Parameter]:
        ps = list(self.rpn.parameters()) + ([self.drift] if self.use_drift else [])
        if self.lnn is not None:
            ps += list(self.lnn.parameters())
        return ps + list(self.learned.parameters())

    def physical_parameters(self) -> list[nn.Parameter]:
        return [p for p in self.params.raw.values() if p.requires_grad]

    @torch.no_grad()
    def latent_state_at(self, w: Window, end: bool = True) -> torch.Tensor:
        """z at the end (or start) of window ``w`` (the next window starts from it)."""
        assert self.lnn is not None
        sl = slice(-1, None) if end else slice(0, 1)
        q = None if w.q_pool is None else w.q_pool[sl]
        qd = None if w.qd_pool is None else w.qd_pool[sl]
        k = self.kinematics(w.t_pool[sl], w.f_pool[sl], q, qd, order=1)
        assert k.z is not None
        return k.z[0]

    @torch.no_grad()
    def states_at_samples(self, w: Window, stride: int = 10) -> list[list[float]]:
        """[t, x..., x'..., z...] from the networks at every ``stride``-th sample of the window:
        the segment initial states of the multiple-shooting refinement."""
        sl = slice(0, None, stride)
        q = None if w.q_data is None else w.q_data[sl]
        qd = None if w.qd_data is None else w.qd_data[sl]
        k = self.kinematics(w.t_data[sl], w.f_data[sl], q, qd, order=1)
        parts = [w.t_data[sl][:, None], k.x, k.v] + ([k.z] if k.z is not None else [])
        return torch.cat([p.to(torch.float64) for p in parts], dim=1).tolist()

    @torch.no_grad()
    def response_at_start(self, w: Window) -> torch.Tensor:
        k = self.kinematics(
            w.t_pool[:1],
            w.f_pool[:1],
            None if w.q_pool is None else w.q_pool[:1],
            None if w.qd_pool is None else w.qd_pool[:1],
            order=0,
            latent=False,
        )
        return k.x[0]

    def solve_drift(
        self, w: Window, names: list[str] | None = None, max_rel_std: float = 0.5
    ) -> tuple[dict[str, float], dict[str, float]]:
        """The window's displacement drift, and the linear parameters ``names`` with it, from the
        physics residuals (Gauss-Newton: the residual is bilinear in stiffness and drift).

        Accelerations determine x only up to a + b t per degree of freedom; a network fitted to
        them carries an arbitrary such drift, and a least-squares start on it is biased
        (measured on a 3-storey building from floor accelerometers: c1 3.2 for 0.5). The
        physics pins the drift, so the two are solved together. A value outside its range or
        not determined by the window is rejected as in ``least_squares_init``. Returns
        (accepted, rejected)."""
        return self._accept_determined(
            lambda ns, std: _drift_solve(self, w, ns, std=std), list(names or []), max_rel_std, always=True
        )

    def least_squares_init(
        self, w: Window, names: list[str] | None = None, max_rel_std: float = 0.5
    ) -> tuple[dict[str, float], dict[str, float]]:
        """Solve for the parameters the motion residual is linear in, with the current networks.

        r(p) = r(0) + J p exactly for those parameters, so one linear least-squares solve
        gives the best values for the current response estimate (and the LNN's z). A value
        outside a parameter's range (a negative value for a log-parameter) is not clipped to
        the bound, where a log-parameter would be stuck: that parameter keeps its current
        value, the others are solved again, and the rejected values are returned for the
        log. A value the window does not determine (standard error above ``max_rel_std`` of it:
        a cubic stiffness in a window of small motion, whose estimate is then near zero) is
        rejected the same way: a log-parameter started near zero could not come back under the
        clamp. Returns (accepted, rejected)."""
        names = list(names if names is not None else self.system.linear_params())
        if not names:
            return {}, {}
        with torch.no_grad():
            k = self.kinematics(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)
        return self._accept_determined(
            lambda ns, std: solve_linear_params(self.system, k, w.f_pool, self.params.values(), ns, std=std),
            names,
            max_rel_std,
        )

    def _accept_determined(
        self, solve, names: list[str], max_rel_std: float, always: bool = False
    ) -> tuple[dict[str, float], dict[str, float]]:
        """Solve for ``names`` (``solve(names, std) -> values``, filling standard errors), drop the
        values out of range or with a standard error above ``max_rel_std`` of them, solve again
        without them; set and return the accepted values and the rejected ones. ``always``: solve
        even when no name is left (the solve has other unknowns, the drift)."""
        rejected: dict[str, float] = {}
        while names or always:
            std: dict[str, float] = {}
            est = solve(names, std)
            bad = {
                n: v
                for n, v in est.items()
                if not in_range(self.params.spec(n), v) or std.get(n, 0.0) > max_rel_std * abs(v)
            }
            if not bad:
                self.params.set_values(est)
                return est, rejected
            rejected.update(bad)
            names = [n for n in names if n not in bad]
        return {}, rejected


def _drift_solve(
    net: PIDynNet, w: Window, names: list[str], iters: int = 10, std: dict[str, float] | None = None
) -> dict[str, float]:
    """Gauss-Newton on all physics residuals over the window's pool for the drift (2 n_dof
    numbers) and the parameters ``names``; sets the drift, returns the parameter values
    (``std``: filled with their standard errors, residual variance times (J^T J)^-1)."""
    with torch.no_grad():
        saved = net.use_drift
        net.use_drift = False
        k = net.kinematics(w.t_pool, w.f_pool, w.q_pool, w.qd_pool)
        net.use_drift = saved
    vals = {n: v.detach().double() for n, v in net.params.values().items()}
    tau = ((w.t_pool - net.rpn.t_mid) / net.rpn.t_half).double()[:, None]
    sx, th = net.scale_x.double(), float(net.rpn.t_half)
    D = lambda a: None if a is None else a.detach().double()  # noqa: E731
    x0, v0, a0, z0, zd0, f = D(k.x), D(k.v), D(k.a), D(k.z), D(k.zd), w.f_pool.double()
    nd = x0.shape[1]
    sf, sv = float(net.scale_f), float(net.scale_v[0])

    def residual(u: torch.Tensor) -> torch.Tensor:
        d0, d1 = u[:nd], u[nd : 2 * nd]
        p = dict(vals)
        p.update({n: u[2 * nd + i] for i, n in enumerate(names)})
        kk = Kinematics(t=k.t.double(), x=x0 + sx * (d0 + d1 * tau), v=v0 + sx * d1 / th, a=a0, z=z0, zd=zd0)
        res = net.system.residual(kk, f, p)
        parts = [res.pop("motion").reshape(-1) / sf] + [r.reshape(-1) / sv for r in res.values()]
        return torch.cat(parts)

    u = torch.cat(
        [
            torch.zeros(2 * nd, dtype=torch.float64),
            torch.stack([vals[n] for n in names]) if names else torch.zeros(0, dtype=torch.float64),
        ]
    )
    scale = torch.cat([torch.ones(2 * nd, dtype=torch.float64), u[2 * nd :].abs().clamp_min(1e-12)])
    for _ in range(iters):
        r = residual(u)
        J = forward_jacobian(residual, u) * scale
        step = lstsq(J, -r) * scale
        u = u + step
        if float(step.detach().abs().div(scale).max()) < 1e-10:
            break
    if std is not None and names:
        r = residual(u)
        J = forward_jacobian(residual, u) * scale
        dof = max(J.shape[0] - J.shape[1], 1)
        cov = torch.linalg.pinv(J.T @ J, hermitian=True) * float((r @ r).detach()) / dof
        var = torch.diagonal(cov)[2 * nd :] * scale[2 * nd :] ** 2
        std.update({n: float(var[i].detach().clamp_min(0).sqrt()) for i, n in enumerate(names)})
    with torch.no_grad():
        net.drift.copy_(torch.stack([u[:nd], u[nd : 2 * nd]]).to(net.drift.dtype))
    return {n: float(u[2 * nd + i]) for i, n in enumerate(names)}


def _masked_mse(pred: torch.Tensor, meas: torch.Tensor, scale: torch.Tensor, complete: bool) -> torch.Tensor:
    """Mean squared scaled error over the measured entries (a floor without the sensor is NaN).

    ``complete`` (every entry measured) is known on the host, so no step waits on the device."""
    if complete:
        return (((pred - meas) / scale) ** 2).mean()
    seen = ~torch.isnan(meas)
    err = torch.where(seen, (pred - torch.nan_to_num(meas)) / scale, torch.zeros_like(pred))
    return (err**2).sum() / seen.sum().clamp_min(1)
