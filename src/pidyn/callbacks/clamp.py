"""3-sigma clamping of the physical parameters between subperiods (paper, Methodology).

After a window, the latest estimate p* and the spread sigma_p of the parameter trajectory
in that window define the box [p* - 3 sigma_p, p* + 3 sigma_p] for the next window.
Taken literally a flat (converged or stuck) trajectory gives a box of zero width that
locks in whatever the first window found, so ``min_rel_width`` puts a floor under the half
width (0 reproduces the paper), and the box never leaves the parameter's physical bounds.

A flat trajectory is also what a parameter the window does not determine looks like (a cubic
stiffness in the small motion before the strong shaking): it stays at its start because the
loss does not care, not because it has converged. Its box would then lock the uninformed
start for the rest of the record (k3 held at 90 against a truth of 400, window after window).
So the trajectory spread is not the only sigma: given the posterior standard deviation of
what the windows so far know (the fused information of their physics residuals), the half
width is ``n_sigma * max(trajectory std, posterior std)``, in the parameter's unconstrained
coordinate. A parameter the windows pinned keeps a tight box; one they did not gets a wide
one (at most exp(+-10) in a log coordinate).
"""

from __future__ import annotations

import lightning as L
import torch

from pidyn.params import ParamSpec, clip_to_bounds, from_raw, to_raw


class ParameterClamp(L.Callback):
    """Clamp physical parameters into the box computed from the previous window."""

    def __init__(self, n_sigma: float = 3.0, min_rel_width: float = 0.05, tail_fraction: float = 1.0) -> None:
        self.n_sigma, self.min_rel_width, self.tail_fraction = n_sigma, min_rel_width, tail_fraction
        self.bounds: dict[str, tuple[float, float]] = {}
        self.triggered = 0

    def update_from_trajectory(
        self,
        names: list[str],
        traj: torch.Tensor,
        latest: dict[str, float],
        posterior_std_raw: dict[str, float] | None = None,
        specs: dict[str, ParamSpec] | None = None,
    ) -> None:
        """Set the next window's box from this window's trajectory (rows: iterations) and, where
        given, the window's posterior std of each parameter's unconstrained coordinate."""
        if traj.numel() == 0:
            return
        start = int((1 - self.tail_fraction) * traj.shape[0])
        sigma = traj[start:].std(0, unbiased=traj.shape[0] - start > 1)
        self.bounds = {}
        for i, n in enumerate(names):
            p = latest[n]
            half = max(self.n_sigma * float(sigma[i]), self.min_rel_width * abs(p))
            lo, hi = p - half, p + half
            s_raw = (posterior_std_raw or {}).get(n)
            if s_raw is not None and specs is not None and n in specs and s_raw == s_raw:
                spec = specs[n]
                r = to_raw(spec, p)
                step = min(self.n_sigma * s_raw, 10.0)  # an uninformed direction: wide, not infinite
                lo = min(lo, float(from_raw(spec, torch.tensor(r - step, dtype=torch.float64))))
                hi = max(hi, float(from_raw(spec, torch.tensor(r + step, dtype=torch.float64))))
            self.bounds[n] = (lo, hi)

    @torch.no_grad()
    def apply(self, pl_module: L.LightningModule) -> int:
        """Project the parameters into the box; returns how many were moved."""
        if not self.bounds:
            return 0
        params = pl_module.net.params
        vals = params.as_floats()
        moved = {}
        for n, (lo, hi) in self.bounds.items():
            v = vals[n]
            if v < lo or v > hi:
                moved[n] = clip_to_bounds(params.spec(n), min(max(v, lo), hi))
        if moved:
            params.set_values(moved)
            self.triggered += len(moved)
        return len(moved)

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:  # noqa: D102
        if getattr(pl_module, "phase", None) == "identify":
            self.apply(pl_module)

    def state_dict(self) -> dict:
        return {"bounds": self.bounds, "triggered": self.triggered}

    def load_state_dict(self, state: dict) -> None:
        self.bounds = {k: tuple(v) for k, v in state.get("bounds", {}).items()}
        self.triggered = state.get("triggered", 0)
