"""Changes in time: a stiffness loss and a damping change at an instant."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import Array, ForceTerm, _sigmoid


class StepInTime(ForceTerm):
    """A force that switches on at an unknown time t_d, smoothed over ``tau`` seconds (a sigmoid)
    so that t_d has a gradient, and kept inside (t_min, t_max): what every change in time
    shares."""

    def __init__(self, t_d: float, t_min: float, t_max: float, tau: float) -> None:
        if not t_min < t_d < t_max:
            raise ValueError(f"{self.name}: t_d={t_d} outside ({t_min}, {t_max})")
        self.t_d, self.t_min, self.t_max, self.tau = t_d, t_min, t_max, tau

    def _t_d_spec(self) -> ParamSpec:
        return ParamSpec(
            "t_d", init=self.t_d, true=self.t_d, transform="box", lower=self.t_min, upper=self.t_max, unit="s"
        )

    def _step(self, t: Array, p: dict) -> Array:
        return _sigmoid((t - p["t_d"]) / self.tau)


class StiffnessLoss(StepInTime):
    """-drop k x H(t - t_d): the stiffness ``k`` falls by the fraction ``drop`` at time t_d.

    Damage during the earthquake; ``stiffness`` names the nominal stiffness parameter it scales.
    """

    name = "stiffness_loss"

    def __init__(
        self,
        drop: float = 0.2,
        t_d: float = 10.0,
        t_min: float = 0.0,
        t_max: float = 40.0,
        stiffness: str = "k",
        tau: float = 0.05,
    ) -> None:
        super().__init__(t_d, t_min, t_max, tau)
        self.drop, self.stiffness = drop, stiffness

    def specs(self):
        return [
            ParamSpec("drop", init=self.drop, true=self.drop, transform="box", lower=0.0, upper=0.95),
            self._t_d_spec(),
        ]

    def force(self, t, x, v, z, p):
        return -p["drop"] * p[self.stiffness] * x * self._step(t, p)

    def formula(self, p):
        return f"- {p['drop']:.4g} {p[self.stiffness]:.5g} x H(t - {p['t_d']:.4g})"


class DampingChange(StepInTime):
    """change c x' H(t - t_d): the damping ``c`` changes by the fraction ``change`` at t_d.

    Damage that opens cracks or loosens joints raises the dissipation (change > 0); a lost
    damper lowers it (change < 0). ``damping`` names the nominal damping parameter it scales.
    """

    name = "damping_change"

    def __init__(
        self,
        change: float = 0.5,
        t_d: float = 10.0,
        t_min: float = 0.0,
        t_max: float = 40.0,
        damping: str = "c",
        tau: float = 0.05,
    ) -> None:
        super().__init__(t_d, t_min, t_max, tau)
        if not -0.95 < change < 10.0:
            raise ValueError(f"damping_change: change={change} outside (-0.95, 10)")
        self.change, self.damping = change, damping

    def specs(self):
        return [
            ParamSpec("change", init=self.change, true=self.change, transform="box", lower=-0.95, upper=10.0),
            self._t_d_spec(),
        ]

    def force(self, t, x, v, z, p):
        return p["change"] * p[self.damping] * v * self._step(t, p)

    def formula(self, p):
        return f"+ {p['change']:.4g} {p[self.damping]:.5g} x' H(t - {p['t_d']:.4g})"
