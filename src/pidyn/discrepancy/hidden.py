"""Simulated records with a hidden effect: the ground truth for testing a diagnosis.

A case draws (seeded) a shipped earthquake record, a measurement-noise level and one effect
of the library with a random magnitude, simulates the nominal structure plus that effect,
and measures it. The nominal model does not know the effect; the diagnosis has to find it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pidyn.data.meta import Split
from pidyn.data.sources import Record, synthetic_from_motion
from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Signals, get_effect
from pidyn.excitation.ground_motion import prepare
from pidyn.simulate import simulate
from pidyn.systems.sdof import LinearSDOF, SDOFSystem
from pidyn.systems.terms import StribeckFriction, TrilinearSpring

#: records whose strong motion lies in their first 25 s
RECORDS = (
    "el_centro",
    "el_centro_peer2000",
    "kobe",
    "kobe_090",
    "taft",
    "san_fernando",
    "loma_prieta",
    "landers",
    "northridge",
)


def _trilinear(rng: np.random.Generator, s: Signals) -> dict[str, float]:
    """Softening to 40-60 % of k beyond x1, hardening to 1.5-2.5 k beyond x2."""
    x1 = float(rng.uniform(0.3, 0.45)) * s.x_peak
    x2 = float(rng.uniform(0.65, 0.8)) * s.x_peak
    soft = float(rng.uniform(0.4, 0.6))
    hard = float(rng.uniform(1.5, 2.5))
    return {"dk1": -(1 - soft) * s.k_nominal, "x1": x1, "dk2": (hard - soft) * s.k_nominal, "x2": x2}


def _stribeck(rng: np.random.Generator, s: Signals) -> dict[str, float]:
    """Sliding friction 4-8 % of the peak linear force, static 2-3x that, drop over 5-10 % of RMS x'."""
    Fc = float(rng.uniform(0.04, 0.08)) * s.k_nominal * s.x_peak
    return {"Fc": Fc, "Fs": float(rng.uniform(2.0, 3.0)) * Fc, "vs": float(rng.uniform(0.05, 0.1)) * s.v_rms}


#: effects outside the library: the diagnosis must not give them a wrong library name
OUTSIDE = {"trilinear_spring": _trilinear, "stribeck_friction": _stribeck}

#: library names physically equivalent to an effect outside the library (what a test or the
#: benchmark accepts beside ``unexplained``): a trilinear spring softens beyond x1 and hardens
#: beyond x2, a stop beyond a displacement with a (softening) cubic spring for the branch
#: before it; Stribeck friction is dry friction with a drop at low speed
EQUIVALENT = {outside: {n for n, e in EFFECTS.items() if outside in e.stands_for} for outside in OUTSIDE}


def _outside_term(name: str, p: dict[str, float]):

    if name == "trilinear_spring":
        return TrilinearSpring(p["dk1"], p["x1"], p["dk2"], p["x2"])
    return StribeckFriction(p["Fc"], p["Fs"], p["vs"], eps=1e-3 * max(p["vs"], 1e-9) / 0.02)


#: passes of the fixed point that sizes several hidden effects against their joint response
_FIXED_POINT_PASSES = 3


def _draw(
    name: str,
    n_effects: int,
    rng: np.random.Generator,
    s: Signals,
    sign: float | None,
    params: dict[str, float] | None,
    hidden: dict[str, float],
    terms: list,
) -> tuple[dict, list]:
    """One hidden effect's parameters, sized against ``s``, added to ``hidden`` and ``terms``."""
    hidden, terms = dict(hidden), list(terms)
    if name in OUTSIDE:  # an effect the library does not hold
        drawn = OUTSIDE[name](rng, s)
        hidden.update(drawn)
        terms.append(_outside_term(name, drawn))
        return hidden, terms
    eff = get_effect(name)
    if sign is not None and not eff.signed and n_effects == 1:
        raise ValueError(
            f"hidden effect '{name}': its sign is fixed by physics; sign={sign} applies only to "
            + ", ".join(n for n, e in EFFECTS.items() if e.signed)
        )
    drawn = eff.sample(rng, s, sign=sign if eff.signed else None)
    if set(drawn) & set(hidden):
        raise ValueError(f"hidden effects share parameters {sorted(set(drawn) & set(hidden))}")
    drawn.update({k_: float(v) for k_, v in (params or {}).items() if k_ in drawn})
    hidden.update(drawn)
    terms.append(eff.term(drawn, s.context()))
    return hidden, terms


def _size_jointly(
    names: list[str],
    states: list,
    terms: list,
    rng: np.random.Generator,
    nominal: SDOFSystem,
    truth_nom: dict[str, float],
    gm,
    fit_end: float,
    sign: float | None,
    params: dict[str, float] | None,
    seed: int,
) -> tuple[dict[str, float], list]:
    """Several hidden effects, each sized against the response of the structure that holds
    them all: a fixed point from ``terms`` (sized against the nominal response), each effect's
    random shares redrawn identically from its generator state ``states``. Friction shrinks
    the motion that a gap must close or a cubic spring must feel, so shares of the linear
    response would hide one effect behind the other."""
    mass, k = nominal.mass, truth_nom["k"]
    hidden: dict[str, float] = {}
    for _ in range(_FIXED_POINT_PASSES):
        combined = SDOFSystem(terms, mass=mass, name="combined")
        truth_now = {
            **truth_nom,
            **{k_: v for k_, v in combined.true_values().items() if k_ not in truth_nom},
        }
        sim = simulate(combined, truth_now, gm, gm.t, rtol=1e-7, atol=1e-10)  # sizes, not data
        if not np.all(np.isfinite(sim.x)):
            raise RuntimeError(f"hidden effects {names} (seed {seed}): the structure holding them diverges")
        s = Signals(sim.t, sim.x[:, 0], sim.v[:, 0], mass, k, "k", t_fit_end=fit_end)
        hidden, terms = {}, list(nominal.terms)
        for name, state in zip(names, states):
            rng.bit_generator.state = state
            hidden, terms = _draw(name, len(names), rng, s, sign, params, hidden, terms)
    return hidden, terms


@dataclass
class HiddenCase:
    record: Record
    effect: str | None
    truth: dict[str, float]  # the hidden effect's parameters
    nominal: dict[str, float]  # the nominal structure's true parameters
    noise: float
    motion: str
    fit_end: float


def hidden_case(
    effect: str | None,
    seed: int,
    noise: float | None = None,
    duration: float = 25.0,
    fit_end: float = 16.0,
    dt: float = 0.01,
    pga: float = 3.0,
    c: float = 0.5,
    k: float = 15.0,
    mass: float = 1.0,
    max_noise: float = 0.05,
    sign: float | None = None,
    params: dict[str, float] | None = None,
    channels: Sequence[str] = ("x", "v"),
) -> HiddenCase:
    """Linear SDOF (m, c, k) plus ``effect`` (None: nothing hidden; "a+b": both) under a random record.

    ``noise`` None draws it uniformly in [0, max_noise] (std as a share of each channel's RMS).
    ``sign`` fixes the sign of a signed effect (softening cubic: -1); None draws it.
    ``params`` overrides drawn effect parameters (a change after the split: ``{"t_d": 19.0}``).
    ``channels``: what is measured (``("a",)``: an accelerometer, as on real structures).
    """
    rng = np.random.default_rng(seed)
    motion = str(rng.choice(RECORDS))
    gm = prepare(motion, dt=dt, duration=duration)
    gm = gm.scaled(pga / gm.pga)
    level = float(rng.uniform(0.0, max_noise)) if noise is None else float(noise)
    nominal = LinearSDOF(c=c, k=k, mass=mass)
    truth_nom = nominal.true_values()
    terms = list(nominal.terms)
    hidden: dict[str, float] = {}
    names = [] if effect is None else [e.strip() for e in effect.split("+")]
    if names:
        base = simulate(nominal, truth_nom, gm, gm.t, rtol=1e-7, atol=1e-10)  # for sizes only, not the data
        s = Signals(base.t, base.x[:, 0], base.v[:, 0], mass, k, "k", t_fit_end=fit_end)
    states = []  # the generator's state before each effect's draw: a redraw repeats its shares
    for name in names:  # "gap_contact+coulomb_friction": several effects at once
        states.append(rng.bit_generator.state)
        hidden, terms = _draw(name, len(names), rng, s, sign, params, hidden, terms)
    if len(names) > 1:
        hidden, terms = _size_jointly(
            names, states, terms, rng, nominal, truth_nom, gm, fit_end, sign, params, seed
        )
    unknown = set(params or {}) - set(hidden)
    if unknown:
        raise ValueError(
            f"hidden effect '{effect}' has no parameter(s) {sorted(unknown)}; it has {sorted(hidden)}"
        )
    system = SDOFSystem(terms, mass=mass, name=f"linear_sdof+{effect or 'none'}")
    truth = {**truth_nom, **{k_: v for k_, v in system.true_values().items() if k_ not in truth_nom}}
    truth.update(hidden)
    rec = synthetic_from_motion(
        system, gm, noise=level, data_seed=seed, channels=tuple(channels), params=truth
    )
    rec.name = f"{motion}+{effect or 'none'}"
    rec.meta = rec.meta.with_(hidden_effect=effect, hidden_params=hidden, seed=seed)
    return HiddenCase(rec, effect, hidden, truth_nom, level, motion, fit_end)


#: the effect a hidden record holds when none is named: the library's first (a cubic spring)
DEFAULT_EFFECT = next(iter(LIBRARY))


def hidden_record(
    effect: str | None = DEFAULT_EFFECT,
    seed: int = 0,
    noise: float | None = None,
    duration: float = 25.0,
    fit_end: float = 16.0,
    dt: float = 0.01,
    sign: float | None = None,
    params: dict[str, float] | None = None,
    channels: Sequence[str] = ("x", "v"),
) -> Record:
    """A hidden-effect case as a data source (``data=hidden``); ``effect: null`` hides nothing."""
    if effect in ("none", "null", ""):
        effect = None
    case = hidden_case(
        effect,
        seed,
        noise=noise,
        duration=duration,
        fit_end=fit_end,
        dt=dt,
        sign=sign,
        params=None if params is None else dict(params),
        channels=tuple(channels),
    )
    case.record.meta.split = Split.at(fit_end, float(case.record.t[-1]))
    return case.record
