"""The package's contracts: abstract force terms and effects, columns derived from the force,
verdicts as an enum, notes with codes."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import yaml

from pidyn.baselines.sindy import library, param_terms
from pidyn.discrepancy.effects import EFFECTS, Effect
from pidyn.discrepancy.verdicts import Verdict
from pidyn.notes import code_of, codes, note
from pidyn.systems.sdof import Duffing, LinearSDOF
from pidyn.systems.terms import (
    CoulombFriction,
    CubicStiffness,
    ForceTerm,
    GapContact,
    Monomial,
    QuadraticDamping,
    TrilinearSpring,
    ViscousDamping,
)


def test_a_force_term_without_its_formula_cannot_be_made():
    class Half(ForceTerm):
        def specs(self):
            return []

        def force(self, t, x, v, z, p):
            return x

    with pytest.raises(TypeError, match="abstract"):
        Half()


def test_a_latent_term_without_its_rate_fails_when_the_class_is_written():
    with pytest.raises(TypeError, match="latent_rate"):

        class Hidden(ForceTerm):  # noqa: F841
            n_latent = 1

            def specs(self):
                return []

            def force(self, t, x, v, z, p):
                return z[..., 0]

            def formula(self, p):
                return "z"


def test_an_effect_without_its_sampler_cannot_be_made():
    class NoSampler(Effect):
        def candidates(self, s):
            yield from ()

        def term(self, params, ctx):
            return ViscousDamping()

    with pytest.raises(TypeError, match="abstract"):
        NoSampler()
    assert all(isinstance(e, Effect) for e in EFFECTS.values())


@pytest.mark.parametrize(
    "term, p",
    [
        (CubicStiffness(2.0, signed=True), {"k3": -3.0}),
        (GapContact(5.0, 0.02), {"kg": 7.0, "gap": 0.02}),
        (QuadraticDamping(0.4), {"c2": 0.4}),
        (CoulombFriction(0.3, eps=1e-2), {"Fc": 0.3}),
        (CoulombFriction(0.3, eps=1e-2, eps_range=(5e-3, 3e-2)), {"Fc": 0.3, "eps": 2e-2}),
        (TrilinearSpring(-2.0, 0.01, 4.0, 0.03), {"dk1": -2.0, "x1": 0.01, "dk2": 4.0, "x2": 0.03}),
        (Monomial(2, 1), {"p21": 1.7}),
    ],
)
def test_the_columns_rebuild_the_force(term, p):
    """A regression on a term's columns reads its linear parameters off the force it wrote."""
    rng = np.random.default_rng(0)
    x, v = 0.05 * rng.standard_normal(200), 0.3 * rng.standard_normal(200)
    cols = term.columns(None, x, v, None, p)
    assert set(cols) == set(term.linear)
    rebuilt = sum(p[n] * cols[n] for n in term.linear)
    np.testing.assert_allclose(rebuilt, term.force(None, x, v, None, p), rtol=1e-12, atol=1e-15)


def test_a_friction_width_can_be_identified_within_its_range():
    """With ``eps_range`` the smoothed sign's width is a bounded parameter whose value the force
    reads; the effect library makes it so for a refinement (``free_width``) and keeps an
    identified width when it rebuilds the term."""
    term = CoulombFriction(0.3, eps=1e-2, eps_range=(5e-3, 3e-2))
    spec = {s.name: s for s in term.specs()}["eps"]
    assert spec.transform == "box" and (spec.lower, spec.upper) == (5e-3, 3e-2)
    v = torch.tensor([0.01], dtype=torch.float64)
    eps = torch.tensor(2e-2, dtype=torch.float64, requires_grad=True)
    f = term.force(None, None, v, None, {"Fc": torch.tensor(0.3, dtype=torch.float64), "eps": eps})
    f.sum().backward()
    assert float(f.detach()) == pytest.approx(0.3 * np.tanh(0.5)) and float(eps.grad) < 0
    assert [s.name for s in CoulombFriction(0.3, eps=1e-2).specs()] == ["Fc"]
    with pytest.raises(ValueError, match="inside eps_range"):
        CoulombFriction(0.3, eps=1e-2, eps_range=(2e-2, 3e-2))
    ctx = {"friction_eps": 1e-2}
    free = EFFECTS["coulomb_friction"].term({"Fc": 0.3}, {**ctx, "free_width": True})
    assert [s.name for s in free.specs()] == ["Fc", "eps"] and free.eps == 1e-2
    again = EFFECTS["coulomb_friction"].term({"Fc": 0.3, "eps": 1.7e-2}, ctx)
    assert again.eps == 1.7e-2 and [s.name for s in again.specs()] == ["Fc"]


def test_the_sindy_library_and_the_parameters_it_reads_come_from_the_terms():
    names = [t.symbol for t in library(np.array([1.0, -1.0]))]
    assert names == ["x", "x'", "x^2", "x x'", "x'^2", "x^3", "x^2 x'", "x x'^2", "x'^3", "x'|x'|", "sign x'"]
    assert param_terms(LinearSDOF()) == {"c": "x'", "k": "x"}
    assert param_terms(Duffing()) == {"c": "x'", "k1": "x", "k3": "x^3"}


def test_verdicts_are_an_enum_that_files_keep_as_plain_strings():
    assert Verdict.NONE == "none" and Verdict("unexplained") is Verdict.UNEXPLAINED
    assert json.loads(json.dumps({"verdict": Verdict.DISCREPANCY})) == {"verdict": "discrepancy"}
    assert yaml.safe_load(yaml.safe_dump({"verdict": Verdict.NONE})) == {"verdict": "none"}
    assert f"{Verdict.UNEXPLAINED}" == "unexplained"
    with pytest.raises(ValueError):
        Verdict("maybe")


def test_notes_carry_codes_that_survive_a_file():
    text = note("not_at_rest", "the record does not start at rest")
    assert code_of(text) == "not_at_rest" and text.startswith("the record")
    back = json.loads(json.dumps([text, "a note without a code"]))
    assert codes(back) == {"not_at_rest"} and code_of(back[1]) is None
    with pytest.raises(ValueError, match="note code"):
        note("Not At Rest", "x")


def test_every_note_code_the_package_makes_is_in_the_one_table():
    """A code is made in one place and explained in one: ``pidyn.notes.CODES``. Every literal code
    passed to ``note`` in the package is there, and every code there is made somewhere."""
    import ast
    from pathlib import Path

    import pidyn
    from pidyn.notes import CODES

    used = set()
    for f in Path(pidyn.__file__).parent.rglob("*.py"):
        for n in ast.walk(ast.parse(f.read_text())):
            name = getattr(getattr(n, "func", None), "id", getattr(getattr(n, "func", None), "attr", None))
            if isinstance(n, ast.Call) and name == "note" and n.args and isinstance(n.args[0], ast.Constant):
                used.add(n.args[0].value)
    assert used == set(CODES), (sorted(used - set(CODES)), sorted(set(CODES) - used))
    assert all(text and text[0].islower() for text in CODES.values())
    with pytest.raises(ValueError, match="not in pidyn.notes.CODES"):
        note("not_a_code_anyone_made", "x")
