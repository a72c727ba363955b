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
from pidyn.params import PhysicalParameters
from pidyn.systems.base import Kinematics, StructuralSystem


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
        nd, nz = system.n_dof, system.n_latent
        self.register_buffer("z_offset", torch.zeros(max(nz, 1)))
        self.register_buffer("scale_x", torch.ones(nd))
        self.register_buffer("scale_v", torch.ones(nd))
        self.register_buffer("scale_a", torch.ones(nd))
        self.register_buffer("scale_f", torch.ones(()))

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
        self.rpn.set_output_scale(s["x"], w.x.mean(0))
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
        self.lnn.set_output_scale(self.rpn.out_scale[:1].expand_as(self.lnn.out_scale),
                                  self.rpn.out_shift[:1].expand_as(self.lnn.out_shift))
        self.lnn.t_mid.copy_(self.rpn.t_mid)
        self.lnn.t_half.copy_(self.rpn.t_half)

    @torch.no_grad()
    def set_latent_offset(self, z0: torch.Tensor, x0: torch.Tensor) -> None:
        """Paper: add (z0 - x0) to the LNN output so z starts where the last window left it."""
        self.z_offset.copy_((z0 - x0).reshape(-1)[: self.z_offset.numel()])

    # ----------------------------------------------------------------- forward
    def kinematics(self, t: torch.Tensor, f: torch.Tensor | None = None, order: int = 2) -> Kinematics:
        xs = self.rpn.taylor(t, order=order, f=f)
        x, v = xs[0], xs[1] if order >= 1 else None
        a = xs[2] if order >= 2 else None
        z = zd = None
        if self.lnn is not None:
            zs = self.lnn.taylor(t, order=1, f=f)
            z, zd = zs[0] + self.z_offset, zs[1]
        return Kinematics(t=t, x=x, v=v, a=a, z=z, zd=zd)  # type: ignore[arg-type]

    def physics_losses(self, t: torch.Tensor, f: torch.Tensor) -> dict[str, torch.Tensor]:
        k = self.kinematics(t, f if self.rpn.use_excitation_input else None)
        res = self.system.residual(k, f, self.params.values())
        out = {"physics/motion": ((res.pop("motion") / self.scale_f) ** 2).mean()}
        for name, r in res.items():
            out[f"physics/{name}"] = ((r / self.scale_v[0]) ** 2).mean()
        return out

    def data_losses(self, w: Window, order: int = 1) -> dict[str, torch.Tensor]:
        f = w.f_data if self.rpn.use_excitation_input else None
        need = 2 if w.a is not None else (1 if w.v is not None else 0)
        xs = self.rpn.taylor(w.t_data, order=need, f=f)
        out = {"data/x": (((xs[0] - w.x) / self.scale_x) ** 2).mean()}
        if w.v is not None:
            out["data/v"] = (((xs[1] - w.v) / self.scale_v) ** 2).mean()
        if w.a is not None:
            out["data/a"] = (((xs[2] - w.a) / self.scale_a) ** 2).mean()
        return out

    # ----------------------------------------------------------------- helpers
    def net_parameters(self) -> list[nn.Parameter]:
        ps = list(self.rpn.parameters())
        if self.lnn is not None:
            ps += list(self.lnn.parameters())
        return ps

    def physical_parameters(self) -> list[nn.Parameter]:
        return [p for p in self.params.raw.values() if p.requires_grad]

    @torch.no_grad()
    def latent_state_at(self, t: float) -> torch.Tensor:
        assert self.lnn is not None
        tt = torch.tensor([t], dtype=self.z_offset.dtype)
        return self.lnn.taylor(tt, order=0)[0][0] + self.z_offset

    def least_squares_init(self, t: torch.Tensor, f: torch.Tensor, names: list[str] | None = None) -> dict[str, float]:
        """Solve for the parameters the motion residual is linear in, with the current networks.

        r(p) = r(0) + J p exactly for those parameters, so one linear least-squares solve
        gives the best values for the current response estimate (and the LNN's z).
        """
        names = names if names is not None else self.system.linear_params()
        if not names:
            return {}
        vals = {k: v.detach() for k, v in self.params.values().items()}
        with torch.no_grad():
            k = self.kinematics(t, f if self.rpn.use_excitation_input else None)
        theta = torch.stack([vals[n] for n in names]).requires_grad_(True)

        def motion(th: torch.Tensor) -> torch.Tensor:
            p = dict(vals)
            p.update({n: th[i] for i, n in enumerate(names)})
            return self.system.residual(k, f, p)["motion"].reshape(-1)

        r0 = motion(torch.zeros_like(theta)).detach()
        J = torch.autograd.functional.jacobian(motion, theta.detach())
        sol = torch.linalg.lstsq(J, -r0[:, None]).solution[:, 0]
        est = {n: float(sol[i]) for i, n in enumerate(names)}
        self.params.set_values(est)
        return est
