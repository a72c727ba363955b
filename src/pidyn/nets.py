"""Response networks that return x and its exact time derivatives in one forward pass.

The physics residual needs x, dx/dt and d2x/dt2 at every collocation point. Nested
``autograd.grad`` builds three graphs; here the derivatives are carried forward through
each layer (Taylor mode): for h = W a + b we have h' = W a', h'' = W a'', and for
y = tanh(h): y' = (1 - y^2) h', y'' = (1 - y^2) h'' - 2 y (1 - y^2) h'^2. One matmul per
layer on the stacked (value, d, d2) block, exact to round-off, and it keeps the ordinary
backward pass for training.

Inputs are the window's local time mapped to tau in [-1, 1] (absolute time saturates
tanh), optionally expanded into Fourier features sin/cos(pi k tau) that remove the
spectral bias against the broadband part of the response. The paper's second input, the
ground acceleration, is available (``use_excitation_input``); its derivative is then the
*partial* derivative with respect to t, as in the paper, which is not the total time
derivative the ODE needs.
"""

from __future__ import annotations

import math

import torch
from torch import nn


class TaylorMLP(nn.Module):
    """tanh MLP on Fourier features of local time; ``taylor`` returns (y, dy/dt, d2y/dt2)."""

    def __init__(
        self,
        out_features: int = 1,
        width: int = 32,
        depth: int = 4,
        n_fourier: int = 8,
        use_excitation_input: bool = False,
    ) -> None:
        super().__init__()
        self.n_fourier = n_fourier
        self.use_excitation_input = use_excitation_input
        in_features = 1 + 2 * n_fourier + int(use_excitation_input)
        dims = [in_features] + [width] * depth + [out_features]
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.register_buffer(
            "freqs", math.pi * torch.arange(1, n_fourier + 1, dtype=torch.get_default_dtype())
        )
        # output de-normalisation: y = out_scale * net + out_shift (set from the data)
        self.register_buffer("out_scale", torch.ones(out_features))
        self.register_buffer("out_shift", torch.zeros(out_features))
        # time map t -> tau = (t - t_mid) / t_half
        self.register_buffer("t_mid", torch.zeros(()))
        self.register_buffer("t_half", torch.ones(()))

    @torch.no_grad()
    def set_window(self, t0: float, t1: float) -> None:
        self.t_mid.fill_(0.5 * (t0 + t1))
        self.t_half.fill_(0.5 * (t1 - t0))

    @torch.no_grad()
    def set_output_scale(self, scale: torch.Tensor, shift: torch.Tensor | None = None) -> None:
        self.out_scale.copy_(torch.as_tensor(scale).clamp_min(1e-12))
        if shift is not None:
            self.out_shift.copy_(torch.as_tensor(shift))

    def _features(self, tau: torch.Tensor, order: int, f: torch.Tensor | None):
        """Input features and their tau-derivatives, stacked as (order+1, N, d)."""
        tau = tau[:, None]
        ph = tau * self.freqs
        s, c = torch.sin(ph), torch.cos(ph)
        feats = [torch.cat([tau, s, c], dim=1)]
        if order >= 1:
            one, w = torch.ones_like(tau), self.freqs
            feats.append(torch.cat([one, w * c, -w * s], dim=1))
        if order >= 2:
            w2 = self.freqs**2
            feats.append(torch.cat([torch.zeros_like(tau), -w2 * s, -w2 * c], dim=1))
        if self.use_excitation_input:
            if f is None:
                raise ValueError("this network takes the excitation as an input; pass f")
            f = f[:, None]
            feats = [torch.cat([feats[0], f], dim=1)] + [
                torch.cat([g, torch.zeros_like(f)], dim=1) for g in feats[1:]
            ]
        return torch.stack(feats)

    def taylor(self, t: torch.Tensor, order: int = 2, f: torch.Tensor | None = None) -> list[torch.Tensor]:
        """[y, dy/dt, ..., d^order y/dt^order], each (N, out_features)."""
        tau = (t - self.t_mid) / self.t_half
        h = self._features(tau, order, f)  # (K, N, d)
        last = len(self.layers) - 1
        # the bias enters the value only, added where it is used: no (value, d, d2) block is
        # rebuilt around it (one copy less a layer, forward and backward; the same arithmetic)
        for i, layer in enumerate(self.layers):
            z = h @ layer.weight.T
            if i == last:
                break
            y = torch.tanh(z[0] + layer.bias)
            s = 1 - y * y
            parts = [y]
            if order >= 1:
                parts.append(s * z[1])
            if order >= 2:
                parts.append(s * z[2] - 2 * y * s * z[1] * z[1])
            h = torch.stack(parts)
        out = [(z[0] + layer.bias) * self.out_scale + self.out_shift]
        for k in range(1, order + 1):
            out.append(z[k] * self.out_scale / self.t_half**k)
        return out

    def forward(self, t: torch.Tensor, f: torch.Tensor | None = None) -> torch.Tensor:
        return self.taylor(t, order=0, f=f)[0]
