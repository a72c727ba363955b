"""A learned force: a small network inside the equation of motion."""

from __future__ import annotations

import numpy as np
import torch

from pidyn.systems.terms.base import ForceTerm


class LearnedForce(ForceTerm):
    """f(x, x') by a small network inside the equation of motion: a universal differential
    equation. What the diagnosis adds when the residual force is clearly structured but no
    library effect explains it. Its weights are trained in PIDynNet's physics loss (they sit
    with the networks' parameters); the last layer starts at zero, so the extension starts
    as the nominal model. Inputs and output are scaled by the record's x, x' and force scales."""

    name = "learned_force"

    def __init__(
        self,
        x_scale: float = 1.0,
        v_scale: float = 1.0,
        f_scale: float = 1.0,
        hidden: int = 24,
        depth: int = 2,
        seed: int = 0,
    ) -> None:
        from torch import nn  # lazy: the NumPy core (simulation, refinement) runs without loading torch

        self.x_scale, self.v_scale, self.f_scale = float(x_scale), float(v_scale), float(f_scale)
        gen = torch.random.fork_rng()
        with gen:
            torch.manual_seed(seed)
            layers: list[nn.Module] = []
            d = 2
            for _ in range(depth):
                layers += [nn.Linear(d, hidden), nn.Tanh()]
                d = hidden
            layers.append(nn.Linear(d, 1))
            self.net = nn.Sequential(*layers)
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def specs(self):
        return []

    def fit_to(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, iters: int = 300) -> float:
        """Start the network at a force measured pointwise (the force the model could not
        explain), by L-BFGS on all samples; returns the relative RMS misfit."""
        dtype = self.net[0].weight.dtype
        u = torch.as_tensor(np.stack([x / self.x_scale, v / self.v_scale], -1), dtype=dtype)
        target = torch.as_tensor(f / self.f_scale, dtype=dtype)
        opt = torch.optim.LBFGS(
            self.net.parameters(),
            lr=1.0,
            max_iter=iters,
            line_search_fn="strong_wolfe",
            tolerance_grad=1e-12,
            tolerance_change=1e-14,
        )

        def closure():
            opt.zero_grad()
            loss = ((self.net(u)[..., 0] - target) ** 2).mean()
            loss.backward()
            return loss

        opt.step(closure)
        with torch.no_grad():
            return float(
                ((self.net(u)[..., 0] - target) ** 2).mean().sqrt()
                / target.pow(2).mean().sqrt().clamp_min(1e-300)
            )

    def force(self, t, x, v, z, p):
        if isinstance(x, torch.Tensor):
            u = torch.stack([x / self.x_scale, v / self.v_scale], dim=-1)
            dtype = self.net[0].weight.dtype
            # a float64 solve (the drift of an accelerometer record) through a float32 network: evaluated in the
            # network's precision, returned in the caller's
            return self.net(u.to(dtype))[..., 0].to(u.dtype) * self.f_scale
        u = np.stack([x / self.x_scale, v / self.v_scale], axis=-1)
        layers = self._numpy_layers()  # the same weights, evaluated in NumPy for simulations
        for i, (w, b) in enumerate(layers):
            u = u @ w + b
            if i < len(layers) - 1:  # Linear, Tanh, ..., Linear
                u = np.tanh(u)
        return u[..., 0] * self.f_scale

    def _numpy_layers(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The linear layers' (W^T, b) in float64, converted again only when training has changed
        them (an integrator asks at every step)."""
        linear = [m for m in self.net if isinstance(m, torch.nn.Linear)]
        key = tuple((id(q), q._version) for m in linear for q in (m.weight, m.bias))
        cached = getattr(self, "_numpy_cache", None)
        if cached is None or cached[0] != key:
            self._numpy_cache = (
                key,
                [
                    (
                        m.weight.detach().cpu().double().numpy().copy().T,
                        m.bias.detach().cpu().double().numpy().copy(),
                    )
                    for m in linear
                ],
            )
        return self._numpy_cache[1]

    def formula(self, p):
        return "f_NN(x, x')"
