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

An effect is one file of this package (an ``Effect`` subclass, found by the package when it is
imported: nothing lists it); its force is a term of ``pidyn.systems.terms``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from pidyn.systems.terms import (
    ForceTerm,
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
    #: where the effect stands in the library's order (screening, reports, ties): the order the
    #: library has always had, whatever order its files are found in
    order: int = 100
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
    #: tried by the output-error check where the running period moves beyond its windows'
    #: intervals (a structure whose properties follow the amplitude)
    tried_where_period_moves: bool = False
    #: effects of one group exclude each other in a model (one change in time at a time)
    exclusive_group: str | None = None
    #: for a change in time: the property that changes (``stiffness``, ``damping``), as reports say it
    changes: str | None = None
    #: effects outside the library (``pidyn.discrepancy.hidden.OUTSIDE``) this one is physically
    #: equivalent to: the name a test or the benchmark accepts for them beside ``unexplained``
    stands_for: tuple[str, ...] = ()

    @abstractmethod
    def candidates(self, s: Signals) -> Iterator[Candidate]:
        """The regression columns at every point of the effect's grid."""

    def parameters(
        self, coef: dict[str, float], fixed: dict[str, float], nominal: dict[str, float]
    ) -> dict[str, float]:
        """The effect's physical parameters from regression coefficients (what is reported)."""
        return {**coef, **fixed}

    def from_change(self, fraction: float, t_change: float) -> dict[str, float]:
        """A change in time's parameters from a located step (its relative size and time)."""
        raise NotImplementedError(f"{self.name} is not a change in time")

    def storey_trials(
        self, params: dict[str, float], span: tuple[float, float], drift_peak: float, k: float
    ) -> list[dict[str, float]]:
        """The starts a building's trial of this effect in a storey refines from (the fitting
        ``span``, the storey's peak drift ``drift_peak``, its stiffness ``k``); the screening's
        estimate alone by default."""
        return [params]

    def shape_trials(self, params: dict[str, float], s: Signals) -> list[dict[str, float]]:
        """Starts over the effect's grid of shapes at ``params``'s size, for a fit that has no
        screening to read the shape from (a deck's support, scored on what it changes in the
        channels); ``params`` alone by default."""
        return [params]

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

    #: the effect's sign is a finding: its size is identified with either sign (a spring that
    #: hardens or softens, a damping that rises or falls), a building's linearised score counts a
    #: step of either sign, and its sampler takes a sign
    signed: bool = False

    #: the parameter the tests check, and its relative tolerance
    key: str = ""
    tolerance: float = 0.25

    def _size(self, rng: np.random.Generator, s: Signals, lo: float = 0.15, hi: float = 0.35) -> float:
        """Peak effect force as a share of the peak linear restoring force."""
        return float(rng.uniform(lo, hi)) * s.k_nominal * s.x_peak
