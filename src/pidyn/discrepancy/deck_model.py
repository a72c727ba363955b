"""A bridge deck seen support by support: its channels as the sensors read them, each support's
deformation along the model's motion, the deck a list of found support terms makes, and what
the diagnosis holds of it.

A deck's supports are not measured one by one: every deck channel reads the sum of what all of
them do. So a support's effect is not read from its own force (as a storey's is from its measured
shear) but from what it would change in the deck channels: each candidate is simulated once, and
its change of the channels is scored against what the current model misses
(``pidyn.discrepancy.deck_steps``)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pidyn.adequacy import trivial_predictions
from pidyn.data.sources import Record
from pidyn.discrepancy.effects import Signals
from pidyn.discrepancy.score_test import terms_at_places
from pidyn.discrepancy.verdicts import Verdict
from pidyn.reporting import nrmse
from pidyn.simulate import input_hold, simulate_batch, simulate_response
from pidyn.systems.deck import RigidDeck


@dataclass(frozen=True)
class ChannelErrors:
    """A model's NRMSE of every deck channel's absolute acceleration on a span, simulated from
    rest over the record, their mean, and the same of the deck moving with a support."""

    per_channel: dict[str, float]
    mean: float
    trivial_per_channel: dict[str, float]
    trivial: float
    trivial_label: str

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class Placed:
    """An effect at a support: its term's parameters in the effect's own names, and the support's
    signals' context (scales, the names of the support's spring and dashpot)."""

    effect: str
    support: int
    params: dict[str, float]
    ctx: dict


@dataclass
class DeckState:
    """The deck model the loop holds: its system and values, its held-out channel errors and the
    refinement's result."""

    system: RigidDeck
    values: dict[str, float]
    heldout: ChannelErrors
    result: Any = None


@dataclass
class DeckDiagnosis:
    """What a deck's diagnosis ends with (its ``detail``)."""

    verdict: Verdict
    found: list[Placed]
    nominal: dict[str, Any]  # parameters, intervals, correlations, errors, fit test
    final: DeckState
    nominal_state: DeckState
    steps: list[dict[str, Any]]
    ranking: list[dict[str, Any]]  # the last screening's candidates, best first
    alike: list[dict[str, Any]]  # supports the data cannot tell apart
    notes: list[str] = field(default_factory=list)


def channels(record: Record) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The deck channels as measured (N, c; absolute), how each reads the deck's two end motions
    (H, c x 2) and their names (``a7``)."""
    H, raw = record.meta.observation, record.meta.sensor_a
    if H is None or raw is None:
        raise ValueError(
            f"record '{record.name}': a deck's diagnosis reads every deck channel where it stands; this "
            "record has no sensor layout (read it with data=csmip and data.station, or give system.layout)"
        )
    names = [f"a{c}" for c in record.meta.sensor_channels or range(1, np.shape(raw)[1] + 1)]
    return np.asarray(raw, float), np.asarray(H, float), names


def simulated_channels(system: RigidDeck, sets: list[dict[str, float]], record: Record) -> np.ndarray:
    """Every deck channel's absolute acceleration for each parameter set, from rest: (P, N, c)."""
    _, H, _ = channels(record)
    names = sorted(set().union(*sets))
    params = {n: np.array([s.get(n, np.nan) for s in sets], float) for n in names}
    f = np.asarray(record.f, float)
    with np.errstate(all="ignore"):  # a candidate that blows up gives NaN: not finite, not scored
        a = simulate_batch(system, params, record.t, f, hold=input_hold(record))["a"]
        a = np.asarray(a, float).reshape(len(record.t), len(sets), system.n_dof)
        a = system.acceleration_output(a, f[:, None, :], params)  # absolute: + R u_g''
    return np.transpose(a @ H.T, (1, 0, 2))


def channel_errors(
    record: Record, system: RigidDeck, values: dict[str, float], span: tuple[float, float], fit_span
) -> ChannelErrors:
    """NRMSE of every deck channel on ``span``, simulated from rest over the record, and the deck
    moving with a support (chosen per channel on ``fit_span``)."""
    meas, _, names = channels(record)
    sim = simulated_channels(system, [values], record)[0]
    m = (record.t >= span[0] - 1e-9) & (record.t <= span[1] + 1e-9)
    per = {
        n: nrmse(sim[m, i], meas[m, i]) if np.all(np.isfinite(sim[m, i])) else float("inf")
        for i, n in enumerate(names)
    }
    view = replace(record, a=meas, x=None, v=None)
    trivial = trivial_predictions(view, fit_span)
    triv, labels = {}, set()
    for i, n in enumerate(names):
        label, series = trivial.get(f"a{i + 1}", trivial.get("a", ("at rest", np.zeros(len(record.t)))))
        triv[n] = nrmse(series[m], meas[m, i])
        labels.add(label)
    return ChannelErrors(
        per,
        float(np.mean(list(per.values()))),
        triv,
        float(np.mean(list(triv.values()))),
        ", ".join(sorted(labels)),
    )


def support_signals(record: Record, system: RigidDeck, values: dict[str, float]) -> list[Signals]:
    """Each support's deformation and its rate along the model's simulated motion (the signals an
    effect's typical size and scales are read from; a support's own force is not measured)."""
    sim = simulate_response(system, values, record)
    f = np.asarray(record.f, float)
    d, dv = system.support_deformation(sim["x"], sim["v"], f, values)
    out = []
    for j in range(len(system.inputs)):
        k = float(values[f"k{j + 1}"])
        out.append(
            Signals(
                record.t,
                np.asarray(d[j], float),
                np.asarray(dv[j], float),
                1.0,
                k,
                f"k{j + 1}",
                damping=f"c{j + 1}",
            )
        )
    return out


def deck_with(system: RigidDeck, values: dict[str, float], found: list[Placed]) -> tuple[RigidDeck, dict]:
    """The deck with the found terms at their supports, started at ``values`` and the terms' own
    starting values."""
    start = dict(values)
    terms = terms_at_places([(f.effect, f.support, f.params, f.ctx) for f in found], start)
    name = f"{system.name}+" + "+".join(f"{f.effect}@{f.support}" for f in found) if found else system.name
    ext = system.extended(start, terms, name)
    names = {s.name for s in ext.param_specs()}
    return ext, {k: v for k, v in start.items() if k in names}


def candidate_deck(
    system: RigidDeck, values: dict[str, float], found: list[Placed], cand: Placed
) -> tuple[RigidDeck, dict]:
    """The deck with ``found`` and the candidate ``cand`` added. A candidate that is a spring at rest
    too (a hysteresis: k d + kh z, and z follows d near rest) starts with its support's linear
    spring lowered by its own stiffness at rest, so that the deck starts as stiff as the model it
    extends. On top of the whole spring it started far stiffer, and on case 22 of
    ``experiments/discrepancy_bench_deck.py`` (a Bouc-Wen abutment) its refinement ended at a
    held-out NRMSE of 0.62 against the nominal's 0.21; lowered, it reaches 0.197 and is named."""
    before = set(deck_with(system, values, found)[0].support_stiffness_params()[cand.support - 1])
    ext, start = deck_with(system, values, [*found, cand])
    added = [n for n in ext.support_stiffness_params()[cand.support - 1] if n not in before]
    spring = f"k{cand.support}"
    at_rest = sum(float(start[n]) for n in added)
    if at_rest > 0 and spring in start:
        start[spring] = max(float(start[spring]) - at_rest, 0.1 * float(start[spring]))
    return ext, start
