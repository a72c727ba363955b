"""The library of candidate effects a nominal model may be missing.

The force itself is written once, as a term in ``pidyn.systems.terms``; an effect keeps only
what is its own:

* ``candidates``: the grid over the parameters the force is nonlinear in (a gap, a damage
  time, a hysteresis shape); at each point the term's own columns (``ForceTerm.columns``) on
  the measured signals. The screening fits the coefficients by least squares.
* ``term``: the term that extends the model at the screening's estimate, whose parameters
  PIDynNet then trains.
* ``sample``: a hidden instance of itself with a random magnitude, for the tests and the
  benchmark that hide an effect in simulated data and require the diagnosis to find it.
* ``admissible`` (optional): which fits describe a physical structure.

To add an effect: the force term in a file of ``systems/terms/``, one subclass here registered in ``EFFECTS``,
and a test that hides it (see the README's "Adding a force effect or an estimator").
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from pidyn.systems.terms import (
    AmplitudeSoftening,
    BoucWenHysteresis,
    CoulombFriction,
    CubicStiffness,
    DampingChange,
    ForceTerm,
    GapContact,
    LinearStiffness,
    QuadraticDamping,
    QuadraticStiffness,
    StiffnessLoss,
    ViscousDamping,
    latent_path,
)


@dataclass
class Signals:
    """Pointwise response used to evaluate candidate forces (smoothed measurements).

    ``k_nominal`` is the nominal linear stiffness (for scales and the stiffness-loss
    fraction); ``stiffness`` its parameter name.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    mass: float
    k_nominal: float
    stiffness: str = "k"
    t_fit_end: float | None = None
    v_noise: float = 0.0  # noise std left in the smoothed velocity
    damping: str = "c"

    @property
    def x_peak(self) -> float:
        return float(np.max(np.abs(self.x)))

    @property
    def v_rms(self) -> float:
        return float(np.sqrt(np.mean(self.v**2)))

    @property
    def friction_eps(self) -> float:
        """Velocity width of the smoothed sign: 2 % of the RMS velocity."""
        return 0.02 * self.v_rms

    def context(self) -> dict:
        """What a force term needs to know about the record (plain numbers, for configs)."""
        return {
            "friction_eps": self.friction_eps,
            "t_min": float(self.t[0]),
            "t_max": float(self.t[-1]),
            "stiffness": self.stiffness,
            "damping": self.damping,
            "x_scale": self.x_peak,
            "v_scale": float(np.max(np.abs(self.v))),
            "f_scale": self.k_nominal * self.x_peak,
            "w0": float(np.sqrt(self.k_nominal / self.mass)) if self.k_nominal > 0 and self.mass > 0 else 1.0,
        }


@dataclass
class Candidate:
    """One grid point of an effect: its regression columns and how to read the coefficients."""

    effect: str
    columns: np.ndarray  # (N, q) force per unit coefficient
    coef_names: tuple[str, ...]
    fixed: dict[str, float] = field(default_factory=dict)  # grid-searched (nonlinear) parameters
    positive: tuple[bool, ...] = ()  # coefficient must be > 0 to be physical


class Effect(ABC):
    """A candidate effect: its grid (``candidates``), its term and its sampler are abstract."""

    name: str = "effect"
    n_grid: int = 0  # parameters found by the grid (they count in the information criterion)
    #: a step in time: what changed stays changed, so it must not fit the held-out part worse
    step_in_time: bool = False
    #: a spring at small amplitude (Bouc-Wen's z follows the drift there): the weak form fits it
    #: beside a softer storey spring, and a building's trial of it starts from that spring
    #: (``storey_ranking.trial_values``)
    spring_at_rest: bool = False
    #: screened by default; False for a model tried only where a finding asks for it (the
    #: amplitude-dependent structure, where the running period moves)
    library: bool = True

    @abstractmethod
    def candidates(self, s: Signals) -> Iterator[Candidate]:
        """The regression columns at every point of the effect's grid."""

    def parameters(
        self, coef: dict[str, float], fixed: dict[str, float], nominal: dict[str, float]
    ) -> dict[str, float]:
        """The effect's physical parameters from regression coefficients (what is reported)."""
        return {**coef, **fixed}

    def admissible(self, params: dict[str, float], nominal: dict[str, float]) -> bool:
        """Whether a fit (the effect's ``params``, the ``nominal`` parameters refitted with it)
        describes a physical structure, beyond the coefficient signs a ``Candidate`` fixes; a
        fit that does not is no evidence for the effect."""
        return True

    @abstractmethod
    def term(self, params: dict[str, float], ctx: dict) -> ForceTerm:
        """The force term at ``params``; ``ctx`` is ``Signals.context()``."""

    @abstractmethod
    def sample(self, rng: np.random.Generator, s: Signals, sign: float | None = None) -> dict[str, float]:
        """Random true parameters of a hidden instance, sized against the response ``s``.

        ``sign`` (+1 / -1) fixes the sign of an effect whose sign is a finding (cubic and
        quadratic stiffness); None draws it. Effects whose sign physics fixes ignore it."""

    #: the effect's sign is a finding (its coefficient is identified with either sign)
    signed: bool = False

    #: the parameter the tests check, and its relative tolerance
    key: str = ""
    tolerance: float = 0.25

    def _size(self, rng: np.random.Generator, s: Signals, lo: float = 0.15, hi: float = 0.35) -> float:
        """Peak effect force as a share of the peak linear restoring force."""
        return float(rng.uniform(lo, hi)) * s.k_nominal * s.x_peak


class Cubic(Effect):
    name, key, tolerance = "cubic_stiffness", "k3", 0.2

    def candidates(self, s):
        col = CubicStiffness(1.0, signed=True).columns(s.t, s.x, s.v, None, {})["k3"]
        yield Candidate(self.name, col[:, None], ("k3",), positive=(False,))

    signed = True

    def term(self, p, s):
        return CubicStiffness(p["k3"], signed=True)  # hardening or softening: the data decide

    def sample(self, rng, s, sign=None):
        sign = float(rng.choice([-1.0, 1.0])) if sign is None else float(np.sign(sign))
        # softening is kept milder: its tangent stiffness k + 3 k3 x^2 must stay positive
        size = self._size(rng, s) if sign > 0 else self._size(rng, s, 0.06, 0.15)
        return {"k3": sign * size / s.x_peak**3}


class Quadratic(Effect):
    name, key, tolerance = "quadratic_stiffness", "k2", 0.25

    def candidates(self, s):
        col = QuadraticStiffness(1.0).columns(s.t, s.x, s.v, None, {})["k2"]
        yield Candidate(self.name, col[:, None], ("k2",), positive=(False,))

    def term(self, p, s):
        return QuadraticStiffness(p["k2"])

    signed = True

    def sample(self, rng, s, sign=None):
        drawn = float(rng.choice([-1.0, 1.0]))
        sign = drawn if sign is None else float(np.sign(sign))
        return {"k2": sign * self._size(rng, s) / s.x_peak**2}


#: the range of a friction's identified transition width, in shares of the record's (2 % of the
#: RMS drift velocity); narrower than half would make the sticking friction a damper too stiff
#: for the integrator's step
WIDTH_RANGE = (0.5, 3.0)


class Coulomb(Effect):
    name, key, tolerance = "coulomb_friction", "Fc", 0.25

    def candidates(self, s):
        # near rest, noise flips the sign of the measured velocity: a column no sharper than
        # the noise (the term's own rule, so a screening of the extended model sees the same)
        term = CoulombFriction(1.0, eps=s.friction_eps)
        col = term.columns(s.t, s.x, s.v, None, {}, v_noise=s.v_noise)["Fc"]
        yield Candidate(self.name, col[:, None], ("Fc",), positive=(True,))

    def term(self, p, s):
        eps = float(p.get("eps", s["friction_eps"]))
        if not s.get("free_width"):
            return CoulombFriction(p["Fc"], eps=eps)
        # the width identified too (``CoulombFriction``), within a range about the record's
        lo, hi = (f * float(s["friction_eps"]) for f in WIDTH_RANGE)
        return CoulombFriction(p["Fc"], eps=float(np.clip(eps, 1.01 * lo, 0.99 * hi)), eps_range=(lo, hi))

    def sample(self, rng, s, sign=None):
        return {"Fc": self._size(rng, s, 0.04, 0.1)}


class QuadDamping(Effect):
    name, key, tolerance = "quadratic_damping", "c2", 0.3

    def candidates(self, s):
        col = QuadraticDamping(1.0).columns(s.t, s.x, s.v, None, {})["c2"]
        yield Candidate(self.name, col[:, None], ("c2",), positive=(True,))

    def term(self, p, s):
        return QuadraticDamping(p["c2"])

    def sample(self, rng, s, sign=None):
        v_peak = float(np.max(np.abs(s.v)))
        return {"c2": self._size(rng, s, 0.08, 0.2) / v_peak**2}


class Hysteresis(Effect):
    """Bouc-Wen hysteresis kh z beside the elastic k x (a latent state: the LNN learns z)."""

    name, key, tolerance = "hysteresis", "kh", 0.3
    n_grid = 2
    spring_at_rest = True
    yield_shares = (0.15, 0.3, 0.6)  # z's ceiling (beta + gamma)^(-1/n) over the peak |x|
    shapes = (0.5, 0.75)  # gamma / (beta + gamma)
    exponents = (1.0, 2.0)

    def _grid(self, s):
        rows = []
        for n in self.exponents:
            for share in self.yield_shares:
                total = (share * s.x_peak) ** (-n)
                for g in self.shapes:
                    rows.append((total * (1 - g), total * g, n))
        return np.array(rows)

    def candidates(self, s):
        grid = self._grid(s)
        term = BoucWenHysteresis(1.0, param="kh")
        # rate independent: z along the displacement path alone (a smoothed velocity drifts from it)
        z = latent_path(term, s.t, s.x, None, {"beta": grid[:, 0], "gamma": grid[:, 1], "n": grid[:, 2]})
        for j, (beta, gamma, n) in enumerate(grid):
            yield Candidate(
                self.name,
                term.columns(s.t, s.x, s.v, z[:, j], {})["kh"][:, None],
                ("kh",),
                fixed={"beta": beta, "gamma": gamma, "n": n},
                positive=(True,),
            )

    def parameters(self, coef, fixed, nominal):
        out = {**coef, **fixed}
        out["z_max"] = float((fixed["beta"] + fixed["gamma"]) ** (-1.0 / fixed["n"]))
        return out

    def term(self, p, s):
        # beta and gamma with either sign: which loop shape (softening, hardening) is a finding
        S = max(abs(p["beta"]) + abs(p["gamma"]), 1e-12) / 2
        return BoucWenHysteresis(
            p["kh"],
            p["beta"],
            p["gamma"],
            p["n"],
            param="kh",
            shape_scale=S,
            gamma_lower=-10.0 * S,
            beta_lower=-10.0 * S,
        )

    def sample(self, rng, s, sign=None):
        n = float(rng.choice([1.0, 2.0]))
        share = float(rng.uniform(0.2, 0.5))
        total = (share * s.x_peak) ** (-n)
        g = float(rng.uniform(0.5, 0.8))
        # kh z_max sized like the other effects' peak force
        kh = self._size(rng, s, 0.1, 0.25) / (share * s.x_peak)
        return {"kh": kh, "beta": total * (1 - g), "gamma": total * g, "n": n}


class Damage(Effect):
    """The stiffness falls by a fraction at an unknown time (grid over the time)."""

    name, key, tolerance = "stiffness_loss", "drop", 0.25
    n_grid = 1
    step_in_time = True
    n_times = 40

    def _span(self, s):
        t_end = s.t_fit_end if s.t_fit_end is not None else float(s.t[-1])
        return float(s.t[0]) + 0.05 * (t_end - s.t[0]), t_end

    signal, coef = "x", "dk"  # the force that steps: k x (a damping change steps c x')
    base: ForceTerm = LinearStiffness(1.0, param="k")  # the nominal term whose column steps
    #: the column is -x H(t - t_d), so the coefficient dk is the stiffness lost (> 0): a stiffness
    #: that rises in time is no loss but the mark of an amplitude-dependent one
    column_sign, positive = -1.0, True

    def candidates(self, s):
        lo, hi = self._span(s)
        sig = self.base.columns(s.t, s.x, s.v, None, {})[self.base.linear[0]]
        for t_d in np.linspace(lo, hi, self.n_times + 2)[1:-1]:
            col = self.column_sign * sig * (s.t >= t_d)
            yield Candidate(
                self.name, col[:, None], (self.coef,), fixed={"t_d": float(t_d)}, positive=(self.positive,)
            )

    def parameters(self, coef, fixed, nominal):
        k = nominal.get("k", nominal.get("k1", 1.0))
        return {"drop": coef["dk"] / k, "t_d": fixed["t_d"]}

    def term(self, p, s):
        drop = min(max(p["drop"], 0.01), 0.9)
        return StiffnessLoss(drop, p["t_d"], t_min=s["t_min"], t_max=s["t_max"], stiffness=s["stiffness"])

    def _time_of_share(self, s, share: float) -> float:
        """The time by which the stepping force's signal has done ``share`` of its work
        (cumulative energy over the search span): a change drawn there has motion on both
        sides. Damage happens in the shaking; a change before the record's motion starts (the
        structure at rest) leaves no trace in the data, and no method could name it."""
        lo, hi = self._span(s)
        inside = (s.t >= lo) & (s.t <= hi)
        t, e = s.t[inside], getattr(s, self.signal)[inside] ** 2
        cum = np.cumsum(e)
        if len(t) < 2 or cum[-1] <= 0:
            return float(lo + share * (hi - lo))
        return float(np.interp(share * cum[-1], cum, t))

    def sample(self, rng, s, sign=None):
        return {
            "drop": float(rng.uniform(0.15, 0.4)),
            "t_d": self._time_of_share(s, float(rng.uniform(0.2, 0.7))),
        }


#: the largest relative damping change the library names (the damping ten times its value)
MAX_DAMPING_CHANGE = 9.0


class DampChange(Damage):
    """The damping changes by a fraction at an unknown time (grid over the time)."""

    name, key, tolerance = "damping_change", "change", 0.35
    signal, coef = "v", "dc"
    base = ViscousDamping(1.0)
    column_sign, positive = 1.0, False  # damping may rise or fall

    def parameters(self, coef, fixed, nominal):
        return {"change": coef["dc"] / nominal.get("c", 1.0), "t_d": fixed["t_d"]}

    def admissible(self, params, nominal):
        # the damping stays positive on both sides of the step: a "change" to no damping or less
        # is the refitted damping taking up a force the model's columns get wrong on one side
        # (dry friction near rest, where the velocity is mostly noise), not a change of the structure
        # ... and no more than the term can represent (a tenfold damping): beyond it the located
        # step is a force of another shape (dry friction in a quiet tail reads as a huge damping)
        return nominal.get("c", 1.0) > 0 and -1.0 < params["change"] <= MAX_DAMPING_CHANGE

    def term(self, p, s):
        change = min(max(p["change"], -0.9), MAX_DAMPING_CHANGE)
        return DampingChange(
            change, p["t_d"], t_min=s["t_min"], t_max=s["t_max"], damping=s.get("damping", "c")
        )

    def sample(self, rng, s, sign=None):
        # damage raises the dissipation: the damping doubles to triples
        return {
            "change": float(rng.uniform(1.0, 2.0)),
            "t_d": self._time_of_share(s, float(rng.uniform(0.2, 0.6))),
        }


class Gap(Effect):
    """A symmetric stop beyond a gap (grid over the gap)."""

    name, key, tolerance = "gap_contact", "kg", 0.3
    n_grid = 1
    gap_shares = tuple(np.linspace(0.2, 0.85, 14))

    def candidates(self, s):
        for share in self.gap_shares:
            gap = share * s.x_peak
            col = GapContact(1.0, gap).columns(s.t, s.x, s.v, None, {"gap": gap})["kg"]
            yield Candidate(self.name, col[:, None], ("kg",), fixed={"gap": float(gap)}, positive=(True,))

    def term(self, p, s):
        return GapContact(p["kg"], p["gap"])

    def sample(self, rng, s, sign=None):
        share = float(rng.uniform(0.35, 0.7))
        kg = float(rng.uniform(0.5, 2.0)) * s.k_nominal
        return {"kg": kg, "gap": share * s.x_peak}


class Amplitude(Effect):
    """A stiffness and a damping that follow the response's recent amplitude (a latent envelope
    with its time constant, ``AmplitudeSoftening``): a period that lengthens in strong shaking and
    recovers in the coda. Not screened by default: tried where the running period moves beyond
    its windows' intervals (``pipeline.run``), or when ``diagnosis.effects`` lists it."""

    name, key, tolerance = "amplitude_softening", "soft", 0.3
    n_grid = 1
    library = False
    taus = (0.5, 1.0, 2.0, 4.0, 8.0)

    def candidates(self, s):
        ctx = s.context()
        for tau in self.taus:
            term = AmplitudeSoftening(0.0, 0.0, tau, a_ref=ctx["x_scale"], w0=ctx["w0"])
            e = latent_path(term, s.t, s.x, None, {"tau": tau})[:, 0]
            cols = np.stack([-s.k_nominal * e * s.x, e * s.v], axis=1)
            yield Candidate(self.name, cols, ("soft", "gain_c"), fixed={"tau": tau})

    def parameters(self, coef, fixed, nominal):
        c = float(nominal.get("c", 0.0))
        gain = coef.get("gain_c", 0.0) / c if c > 0 else 0.0
        return {"soft": coef.get("soft", 0.0), "gain": float(gain), **fixed}

    def term(self, p, s):
        return AmplitudeSoftening(
            p.get("soft", 0.1),
            p.get("gain", 0.1),
            p.get("tau", 1.0),
            a_ref=float(s.get("x_scale", 1.0)) or 1.0,
            w0=float(s.get("w0", 1.0)),
            stiffness=s.get("stiffness", "k"),
            damping=s.get("damping", "c"),
        )

    def sample(self, rng, s, sign=None):
        return {
            "soft": float(rng.uniform(0.25, 0.45)),
            "gain": float(rng.uniform(0.3, 1.0)),
            "tau": float(rng.uniform(1.0, 3.0)),
        }


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Cubic(),
        Quadratic(),
        Coulomb(),
        QuadDamping(),
        Hysteresis(),
        Damage(),
        DampChange(),
        Gap(),
        Amplitude(),
    )
}
"""Every candidate effect by name; ``none`` is the verdict when none of them is needed."""

LIBRARY: dict[str, Effect] = {n: e for n, e in EFFECTS.items() if e.library}
"""The effects screened by default (``diagnosis.effects`` empty)."""


def get_effect(name: str) -> Effect:
    if name not in EFFECTS:
        raise ValueError(f"unknown effect '{name}'; choose from {sorted(EFFECTS)} (or 'none')")
    return EFFECTS[name]
