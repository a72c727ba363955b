"""Every registered effect keeps the contract the diagnosis relies on (as a solver library runs one
set of tests over every solver), and an effect's name is written in its own file only."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import numpy as np
import pytest

from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Candidate, Signals
from pidyn.discrepancy.hidden import OUTSIDE
from pidyn.discrepancy.screening import EXCLUSIVE
from pidyn.systems.terms import TERMS, ForceTerm

SRC = Path(__file__).resolve().parents[1] / "src" / "pidyn"


@pytest.fixture(scope="module")
def signals() -> Signals:
    """A decaying two-tone response of a structure of k = 15, m = 1 (plain numbers, no model)."""
    t = np.linspace(0.0, 20.0, 2001)
    x = np.exp(-0.05 * t) * (np.sin(2 * np.pi * 0.6 * t) + 0.3 * np.sin(2 * np.pi * 1.7 * t))
    return Signals(t, x, np.gradient(x, t), 1.0, 15.0, t_fit_end=16.0)


def test_the_library_is_found_in_its_order():
    assert list(EFFECTS)[:3] == ["cubic_stiffness", "quadratic_stiffness", "coulomb_friction"]
    assert [e.order for e in EFFECTS.values()] == sorted(e.order for e in EFFECTS.values())
    assert set(LIBRARY) == {n for n, e in EFFECTS.items() if e.library}


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_effect_keeps_the_contract(name, signals):
    eff = EFFECTS[name]
    assert Path(inspect.getfile(type(eff))).stem == name  # one file, named for the effect
    assert 0 < eff.tolerance < 1 and eff.order < 100
    cands = list(eff.candidates(signals))
    assert cands and all(isinstance(c, Candidate) and c.effect == name for c in cands)
    for c in cands:
        assert c.columns.shape == (len(signals.t), len(c.coef_names)) and np.all(np.isfinite(c.columns))
        assert not c.positive or len(c.positive) == len(c.coef_names)
    assert eff.n_grid <= len(cands[0].fixed)  # the grid counts no more parameters than it fixes
    drawn = eff.sample(np.random.default_rng(0), signals)
    assert eff.key in drawn or eff.key in eff.parameters(
        dict.fromkeys(cands[0].coef_names, 1.0), cands[0].fixed, {"k": 15.0, "c": 0.5}
    )
    term = eff.term(drawn, {**signals.context(), "t_min": 0.0, "t_max": 20.0})
    assert isinstance(term, ForceTerm)
    z = np.zeros((len(signals.t), term.n_latent)) if term.n_latent else None
    values = {s.name: s.init for s in term.specs()}
    force = term.force(signals.t, signals.x, signals.v, z, {"k": 15.0, "c": 0.5, **values})
    assert np.all(np.isfinite(force))
    # a change in time says what changes and is read back from a located step
    assert (eff.changes is not None) == eff.step_in_time
    if eff.step_in_time:
        p = eff.from_change(-0.2 if eff.changes == "stiffness" else 0.5, 8.0)
        assert p["t_d"] == 8.0 and eff.key in p
    assert set(eff.stands_for) <= set(OUTSIDE)
    if eff.signed:  # a sign is a finding: the sampler draws the one it is given
        for sign in (-1.0, 1.0):
            assert np.sign(eff.sample(np.random.default_rng(1), signals, sign=sign)[eff.key]) == sign
    trials = eff.storey_trials(dict(drawn), (0.0, 16.0), 0.1, 15.0)
    if eff.step_in_time:  # the drawn size at every time of a grid inside the span
        assert len(trials) > 1 and all(
            {**t, "t_d": drawn["t_d"]} == drawn and 0 < t["t_d"] < 16 for t in trials
        )
    else:
        assert trials[0] == drawn


def test_effects_of_a_group_exclude_each_other():
    groups = {e.exclusive_group for e in EFFECTS.values()} - {None}
    assert len(EXCLUSIVE) == len(groups)
    for g in EXCLUSIVE:
        assert len({EFFECTS[n].exclusive_group for n in g}) == 1


def test_no_effect_name_is_written_outside_its_own_file():
    """An effect's name appears as a string in its effect's file and its force term's only: the
    rest of the package asks the effect (``Effect`` attributes), so a new effect is its file."""
    files = {f: f.read_text() for f in SRC.rglob("*.py")}
    for name, eff in EFFECTS.items():
        own = {Path(inspect.getfile(type(eff)))}
        if name in TERMS:
            own.add(Path(inspect.getfile(TERMS[name])))
        quoted = re.compile(r"[\"']" + re.escape(name) + r"[\"']")
        elsewhere = sorted(
            str(f.relative_to(SRC)) for f, text in files.items() if f not in own and quoted.search(text)
        )
        assert not elsewhere, (name, elsewhere)
