"""A building seen storey by storey: each storey's drift, its measured shear and its signals for
the weak form, the building a list of found storey terms makes, and what the diagnosis returns."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.effects import EFFECTS, Signals
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.score_test import terms_at_places
from pidyn.discrepancy.screening import Screening
from pidyn.discrepancy.step_reports import StoreyStep
from pidyn.discrepancy.verdicts import Verdict
from pidyn.params import positive
from pidyn.signals import integrate
from pidyn.simulate import simulate_response
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.shear_building import ShearBuilding
from pidyn.systems.terms import LinearStiffness, ViscousDamping
from pidyn.weak_form import WeakForm, smooth_signals, velocity_noise

log = logging.getLogger(__name__)


#: the drifts are integrated above this share of the fundamental frequency. Twice-integrated
#: accelerometer noise grows as 1/f^3 below the corner, and a drift is a small difference of two
#: floors' motions. Measured on a 3-storey building under El Centro (2 % noise): a cubic spring
#: in storey 3 (a quarter of the storey force) scored -1.0 at 0.2 f1, 27 at 0.3, 53 at 0.4 and 72
#: at 0.5; a stop and a stiffness loss rose alike (52 -> 146, 79 -> 157); two clean buildings
#: stayed below 0.3 at every corner. At 0.1 f1 a clean building read as hysteretic everywhere
CORNER_SHARE = 0.5
#: the weak form's windows span this share of the fundamental period: a storey's drift carries
#: the higher modes too, and a stop that engages briefly is seen in short windows (the gap of
#: that building scored 13 at one period, 36-55 at half of it)
WINDOW_SHARE = 0.5


#: a storey's damper below this share of the largest has collapsed; an extension starts it again
#: at ``RESTART`` of the median of the others
COLLAPSED, RESTART = 1e-6, 0.1


@dataclass
class StoreyView:
    """One storey seen as a single degree of freedom loaded by its measured shear."""

    storey: int
    t: np.ndarray
    drift: np.ndarray  # integrated, high-passed (m)
    drift_velocity: np.ndarray
    excitation: np.ndarray  # the weak form's f: -(shear + drift acceleration), filtered alike
    shear: np.ndarray  # the storey's shear force from the floor accelerations, filtered (N)
    measured_floors: list[int]


@dataclass
class Found:
    """An effect named in a storey: its term's parameters in the storey's SDOF names."""

    effect: str
    storey: int
    params: dict[str, float]
    row: Evidence  # the evidence it was tried on
    ctx: dict


@dataclass(frozen=True)
class FloorErrors:
    """A model's NRMSE of every measured floor's absolute acceleration on a span, their mean, and
    the same of the floors moving with the ground (knowing nothing)."""

    per_floor: dict[str, float]
    mean: float
    trivial_per_floor: dict[str, float]
    trivial: float

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class BuildingState:
    """The building model the loop holds: its system and values, its held-out errors (mean and per
    floor), the refinement's result and the noise it estimated per channel."""

    system: Any
    values: dict[str, float]
    heldout: FloorErrors
    result: Any = None
    noise: dict | None = None


@dataclass
class NominalBuilding:
    """The nominal building: its refined values and intervals, its errors on the held-out and the
    fitting parts, the fit test of its fitting part and, once judged, the held-out test."""

    params: dict[str, float]
    intervals: dict[str, Any]
    heldout: FloorErrors
    fit: FloorErrors
    fit_test: dict[str, Any]
    heldout_test: dict[str, Any] | None = None


@dataclass(frozen=True)
class ExtendedBuilding:
    """The model the diagnosis ends with: the named effects' (with their intervals) or a kept
    learned force's."""

    system: str
    params: dict[str, float]
    intervals: dict[str, Any]
    storey_equations: Any


@dataclass
class BuildingDiagnosis:
    verdict: Verdict
    found: list[Found]
    nominal: NominalBuilding
    extended: ExtendedBuilding | None
    steps: list[StoreyStep]
    gain: dict
    unexplained_storey: int | None
    views: list[StoreyView]
    screenings: list[Screening]
    values: dict[str, float]
    corner_hz: float
    notes: list[str] = field(default_factory=list)
    learned: dict | None = None  # the learned storey force of an unexplained verdict (storey_learned)


def floor_accelerations(
    record: Record, system: ShearBuilding, values: dict[str, float]
) -> tuple[np.ndarray, list[int]]:
    """Every floor's relative acceleration (N, n): measured where a sensor is, the model's elsewhere."""
    if record.a is None:
        raise ValueError(f"record '{record.name}': the building diagnosis needs floor accelerations (a1..aN)")
    a = np.array(record.a, float)
    measured = [j + 1 for j in range(a.shape[1]) if not np.isnan(a[:, j]).all()]
    if not measured:
        raise ValueError(f"record '{record.name}': no floor carries an accelerometer")
    missing = [j for j in range(a.shape[1]) if np.isnan(a[:, j]).all()]
    if missing:
        sim = simulate_response(system, values, record)["a"]
        for j in missing:
            a[:, j] = sim[:, j]
    return a, measured


def storey_views(
    record: Record, system: ShearBuilding, values: dict[str, float], corner: float
) -> list[StoreyView]:
    """Each storey's drift, drift velocity and shear (see the module's docstring)."""
    a, measured = floor_accelerations(record, system, values)
    ag = np.asarray(record.f, float)
    masses = np.array([values[f"m{j + 1}"] for j in range(system.n_dof)])
    absolute = a + ag[:, None]
    dt = record.dt
    views = []
    for i in range(system.n_dof):
        below = a[:, i - 1] if i > 0 else np.zeros(len(ag))
        dd = a[:, i] - below  # the drift's acceleration
        shear = -(absolute[:, i:] * masses[i:]).sum(1)
        d, v = (integrate(dd, dt, k, corner) for k in (2, 1))
        shear_f, dd_f = integrate(shear, dt, 0, corner), integrate(dd, dt, 0, corner)
        views.append(StoreyView(i + 1, record.t, d, v, -(shear_f + dd_f), shear_f, measured))
    return views


def storey_system(c: float, k: float, found: list[Found]) -> tuple[SDOFSystem, dict[str, float]]:
    """The storey's law as a unit-mass oscillator (``m d'' + c d' + k d (+ found terms) = -m f``)."""
    c, k = positive(c), positive(k)
    terms = [ViscousDamping(c), LinearStiffness(k)]
    values = {"m": 1.0, "c": c, "k": k}
    for f in found:
        terms.append(EFFECTS[f.effect].term(f.params, f.ctx))
        values.update({s.name: float(f.params.get(s.name, s.init)) for s in terms[-1].specs()})
    return SDOFSystem(terms, mass=1.0, name="storey"), values


def storey_signals(view: StoreyView, k: float, period: float, fit_end: float) -> tuple[Signals, WeakForm]:
    xs, vs = smooth_signals(view.t, view.drift, view.drift_velocity, period)
    noise = velocity_noise(view.t, view.drift, view.drift_velocity, period)
    return Signals(view.t, xs, vs, 1.0, k, "k", t_fit_end=fit_end, v_noise=noise), WeakForm.for_record(
        view.t, period
    )


def building_with(
    system: ShearBuilding, values: dict[str, float], found: list[Found]
) -> tuple[ShearBuilding, dict[str, float]]:
    """The building with the found terms in their storeys, started at ``values`` and their estimates."""
    start = dict(values)
    dampers = [f"c{i + 1}" for i in range(system.n_dof) if f"c{i + 1}" in start]
    largest = max((start[c] for c in dampers), default=0.0)
    # the median of those that have not collapsed (most of them can have: one storey's damper
    # then carries the building's whole dissipation)
    typical = float(np.median([start[c] for c in dampers if start[c] >= COLLAPSED * largest] or [0.0]))
    for c in dampers:
        # a damper the nominal fit ran to zero cannot come back in log space (its gradient is
        # proportional to it), and the extension would then draw a damper into another storey to
        # put the dissipation back
        if start[c] < COLLAPSED * typical:
            start[c] = RESTART * typical
    terms = terms_at_places([(f.effect, f.storey, f.params, f.ctx) for f in found], start)
    ext = system.linear_at(
        start, terms, f"{system.name}+" + "+".join(f"{f.effect}@{f.storey}" for f in found)
    )
    names = {s.name for s in ext.param_specs()}
    return ext, {k: v for k, v in start.items() if k in names}


def score_text(score: float | None) -> str:
    """A weak-form score for people; None where the weak form found no physical fit."""
    return "none (no physical fit)" if score is None else f"{score:.1f}"
