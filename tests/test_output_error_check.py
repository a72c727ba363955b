"""The output-error check that decides what the weak-form screening leaves undecided, and the
extension that holds a located change time."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.baselines.least_squares import output_error
from pidyn.discrepancy.confirm import confirm, independent_samples, undecided
from pidyn.discrepancy.effects import Signals
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.extend import extended_system
from pidyn.discrepancy.hidden import hidden_case
from pidyn.discrepancy.screening import pair_lead
from pidyn.discrepancy.screening_rules import Thresholds
from pidyn.systems import LinearSDOF


def test_white_noise_counts_every_sample_and_a_coloured_one_fewer():
    rng = np.random.default_rng(0)
    n = 4000
    white = rng.normal(size=n)
    assert 0.85 * n < independent_samples(white) < 1.15 * n
    phi = 0.8  # AR(1): n (1 - phi) / (1 + phi) independent samples
    ar = np.zeros(n)
    for i in range(1, n):
        ar[i] = phi * ar[i - 1] + rng.normal()
    expected = n * (1 - phi) / (1 + phi)
    assert 0.6 * expected < independent_samples(ar) < 1.6 * expected


def test_only_leaning_unrefused_effects_are_checked():
    th = Thresholds()
    rows = [
        Evidence("gap_contact", score=25.0),
        Evidence("cubic_stiffness", score=4.0),
        Evidence("stiffness_loss", score=6.0, step_in_time=True),
        Evidence("quadratic_stiffness", score=3.0, heldout_miss=True),
        Evidence("quadratic_damping", score=-2.0),
        Evidence("hysteresis"),
    ]
    assert [r.effect for r in undecided(rows, th, 3)] == ["cubic_stiffness"]


def _check(effect: str | None, seed: int, noise: float, sign: float | None = None):
    case = hidden_case(effect, seed, noise=noise, sign=sign)
    rec = case.record
    nominal = LinearSDOF(c=case.nominal["c"], k=case.nominal["k"])
    s = Signals(rec.t, rec.x[:, 0], rec.v[:, 0], 1.0, case.nominal["k"], "k", t_fit_end=case.fit_end)
    # the current model as the diagnosis holds it: the best linear fit by output error (the
    # polish), which has already bent c and k towards the missing force
    fitted = output_error(rec.segment(0.0, case.fit_end), nominal, substeps=4, max_nfev=30).params
    values = {"m": 1.0, **fitted}
    start = -30.0 if (sign or 1.0) < 0 else 30.0
    row = Evidence("cubic_stiffness", score=4.0, parameters={"k3": start})
    out = confirm(
        rec,
        nominal,
        values,
        [row],
        lambda r: extended_system(nominal, r.effect, r.parameters, s.context()),
        (0.0, case.fit_end),
        (case.fit_end, float(rec.t[-1])),
        Thresholds(),
    )
    return case, out


def test_the_simulated_response_names_a_softening_cubic_the_weak_form_leaves_undecided():
    """A softening cubic (its force 6-15 % of the linear one at the peak, as the benchmark draws
    it) under 3 % noise, against the best linear model."""
    case, out = _check("cubic_stiffness", 11, 0.03, sign=-1.0)
    (tested,) = out.tested
    assert out.row is not None and out.row.effect == "cubic_stiffness", tested
    assert tested.delta_bic < -10 and tested.heldout_gain > 0
    assert tested.parameters["k3"] == pytest.approx(case.truth["k3"], rel=0.15)
    assert out.row.rivals == []  # one candidate: nothing to tell it from


def test_the_simulated_response_names_nothing_when_nothing_is_missing():
    _, out = _check(None, 12, 0.03)
    (tested,) = out.tested
    assert out.row is None and not tested.passes, tested
    assert tested.delta_bic > -10


def test_an_effect_is_judged_against_the_nominal_models_own_refit():
    """A nominal model fitted elsewhere (its c and k off) leaves a misfit any effect with every
    parameter free removes by refitting c and k: the check refits the nominal first, so on a clean
    record nothing passes."""
    case = hidden_case(None, 12, noise=0.03)
    rec = case.record
    nominal = LinearSDOF(c=case.nominal["c"], k=case.nominal["k"])
    s = Signals(rec.t, rec.x[:, 0], rec.v[:, 0], 1.0, case.nominal["k"], "k", t_fit_end=case.fit_end)
    fitted = output_error(rec.segment(0.0, case.fit_end), nominal, substeps=4, max_nfev=30).params
    off = {"m": 1.0, "c": 1.6 * fitted["c"], "k": 1.06 * fitted["k"]}
    rows = [
        Evidence("cubic_stiffness", score=4.0, parameters={"k3": 30.0}),
        Evidence("quadratic_damping", score=3.0, parameters={"c2": 0.1}),
    ]
    out = confirm(
        rec,
        nominal,
        off,
        rows,
        lambda r: extended_system(nominal, r.effect, r.parameters, s.context()),
        (0.0, case.fit_end),
        (case.fit_end, float(rec.t[-1])),
        Thresholds(),
        max_nfev=60,
    )
    assert out.nominal["refit"] and out.nominal["rss_fit"] < 0.2 * out.nominal["rss_fit_before"], out.nominal
    assert out.row is None and not any(t.passes for t in out.tested), out.tested


def test_a_located_change_time_is_held_in_the_extension():
    nominal = LinearSDOF()
    ctx = {"t_min": 0.0, "t_max": 25.0, "stiffness": "k"}
    ext = extended_system(nominal, "stiffness_loss", {"drop": 0.2, "t_d": 7.5}, ctx, held=["t_d"])
    specs = {s.name: s for s in ext.param_specs()}
    assert not specs["t_d"].trainable and specs["t_d"].init == 7.5 and specs["drop"].trainable
    with pytest.raises(ValueError, match="cannot hold"):
        extended_system(nominal, "stiffness_loss", {"drop": 0.2, "t_d": 7.5}, ctx, held=["t_change"])


def test_a_pair_holding_an_effect_the_held_out_rule_refuses_leads_nowhere():
    th = Thresholds()
    ranking = [
        Evidence("quadratic_stiffness", score=14.0, passes=False, heldout_miss=True),
        Evidence("cubic_stiffness", score=12.0, passes=True),
        Evidence("gap_contact", score=11.0, passes=True),
    ]
    pairs = [
        {
            "effects": ["gap_contact", "quadratic_stiffness"],
            "score": 40.0,
            "delta_bic": -40.0,
            "cv_gain": 0.9,
        },
        {"effects": ["cubic_stiffness", "gap_contact"], "score": 15.0, "delta_bic": -15.0, "cv_gain": 0.8},
    ]
    structure = {"cv_gain": 0.9}
    assert pair_lead(ranking, pairs, structure, th) is None  # the best pair holds the refused spring
    ranking[0].heldout_miss = False
    lead = pair_lead(ranking, pairs, structure, th)
    assert lead is not None and lead["lead"] == "quadratic_stiffness"
    ranking[0].heldout_small = True  # a small held-out share refuses an effect alone, not in a pair
    assert pair_lead(ranking, pairs, structure, th) is not None


def test_a_learned_force_is_kept_only_when_it_predicts_the_held_out_part_better():
    """The guard on a learned force: a network started at the force the linear model misses
    (here the hidden cubic spring itself) predicts the held-out part better and is kept; one
    started at a force the structure does not have (a softening cubic twice as strong, an extra
    linear spring) predicts it worse and is not."""
    from pidyn.discrepancy.learned_step import learned_predicts
    from pidyn.systems.terms import LearnedForce

    case = hidden_case("cubic_stiffness", 5, noise=0.0, sign=1.0)
    rec = case.record
    x, v = rec.x[:, 0], rec.v[:, 0]
    nominal = LinearSDOF(c=case.nominal["c"], k=case.nominal["k"])
    values = {"m": 1.0, **case.nominal}
    held = (case.fit_end, float(rec.t[-1]))
    k3 = case.truth["k3"]
    scales = (float(np.abs(x).max()), float(np.abs(v).max()), float(k3 * np.abs(x).max() ** 3))
    fit = rec.t <= case.fit_end
    kept = {}
    for name, force in (("truth", k3 * x**3), ("softening", -2 * k3 * x**3), ("spring", 5 * x)):
        term = LearnedForce(*scales, seed=0)
        term.fit_to(x[fit], v[fit], force[fit], iters=200)
        kept[name], errors = learned_predicts(
            rec, nominal, values, nominal.with_term(term), values, x, float(v[0]), held, 4
        )
        assert errors["without"] > 0.3, errors  # the linear model misses the cubic spring
        if name == "truth":
            assert errors["with"] < 0.1 * errors["without"], errors
    assert kept == {"truth": True, "softening": False, "spring": False}


def _located_change(rec, fit_end: float, drop: float, t_d: float) -> tuple[dict, object]:
    """A located change as the diagnosis passes it to the check, and the check's output."""
    from types import SimpleNamespace

    from pidyn.discrepancy.sdof_steps import _change_candidate

    nominal = LinearSDOF(c=0.5, k=15.0)
    s = Signals(rec.t, rec.x[:, 0], rec.v[:, 0], 1.0, 15.0, "k", t_fit_end=fit_end)
    fitted = output_error(rec.segment(0.0, fit_end), nominal, substeps=4, max_nfev=30).params
    located = {"t_change": t_d, "t_change_ci95": [t_d - 1.5, t_d + 1.0], "fraction": -drop}
    change = SimpleNamespace(to_dict=lambda: located)
    row = _change_candidate(
        Evidence("stiffness_loss", score=40.0, parameters={"drop": drop, "t_d": t_d}, change=change)
    )
    out = confirm(
        rec,
        nominal,
        {"m": 1.0, **fitted},
        [row],
        lambda r: extended_system(nominal, r.effect, r.parameters, s.context()),
        (0.0, fit_end),
        (fit_end, float(rec.t[-1])),
        Thresholds(),
        max_nfev=60,
        tol=1e-6,
    )
    return row, out


def test_a_located_change_is_one_candidate_of_the_check_with_its_time_free():
    """On an accelerometer record the weak form can locate a change that is not there (a 73 % loss
    on a Painter Street record): the check fits it by output error from where it was located, its
    time free, and names it only where the simulated response decides for it."""
    clean = hidden_case(None, 12, noise=0.03)
    row, out = _located_change(clean.record, clean.fit_end, 0.5, 8.0)
    assert row.change is None and row.located["t_change"] == 8.0  # nothing held
    (tested,) = out.tested
    assert out.row is None and not tested.passes, tested
    assert tested.located["t_change"] == 8.0 and tested.located["fraction"] == -0.5
    from pidyn.discrepancy.report import _confirmation_lines

    assert any(
        "stiffness_loss (located at 8.00 s)" in line
        for line in _confirmation_lines({"confirmation": [r.to_dict() for r in out.tested]})
    )
    damaged = hidden_case("stiffness_loss", 3, noise=0.03, params={"t_d": 9.0})
    truth = damaged.truth
    _, out = _located_change(damaged.record, damaged.fit_end, 0.7 * truth["drop"], 10.0)
    assert out.row is not None and out.row.effect == "stiffness_loss", out.tested
    assert out.row.parameters["t_d"] == pytest.approx(9.0, abs=0.3)


def test_the_first_cause_keeps_a_located_change_only_when_the_check_names_it(monkeypatch):
    """While the nominal model holds on the held-out part, a change the weak form located on an
    accelerometer record is passed to the output-error check with the other candidates; where the
    check names something else, or nothing, no change is reported."""
    from types import SimpleNamespace

    from pidyn.discrepancy import sdof_steps as pipeline
    from pidyn.discrepancy.confirm import Confirmation

    seen = {}

    def fake(case, system, values, node, sc, s, k, everything=False, extra=None):
        seen["extra"], seen["everything"] = extra, everything
        return Confirmation(row=named)

    monkeypatch.setattr(pipeline, "confirm_undecided", fake)
    case = SimpleNamespace(from_accelerometers=True)
    nom = SimpleNamespace(system=None, values={}, node={}, s=None)
    sc = SimpleNamespace(cause="stiffness_loss", verdict="discrepancy")
    change = SimpleNamespace(to_dict=lambda: {"t_change": 5.0})
    row = Evidence("stiffness_loss", score=30.0, parameters={"drop": 0.4, "t_d": 5.0}, change=change)
    holds, fails = SimpleNamespace(failed=False), SimpleNamespace(failed=True)
    named = Evidence("cubic_stiffness")
    assert pipeline._first_cause(case, nom, sc, holds, row, None) == (
        "cubic_stiffness",
        Confirmation(row=named),
        None,
    )
    assert seen["everything"] and [r.effect for r in seen["extra"]] == ["stiffness_loss"]
    named = Evidence("stiffness_loss")
    cause, _, kept = pipeline._first_cause(case, nom, sc, holds, row, None)
    assert cause == "stiffness_loss" and kept is row
    seen.clear()  # the nominal model failed on the held-out part: the located change stands
    assert pipeline._first_cause(case, nom, sc, fails, row, None) == ("stiffness_loss", None, row)
    assert seen == {}


def test_the_polish_of_an_extension_starts_from_the_checks_fit_where_that_simulates_better(tmp_path):
    """The extension's network estimate can land far from the fit that named the effect (on a
    Painter Street record its simulation cost 28 times the check's); the polish then starts from
    the check's fit, chosen on the fitting part, and says so."""
    from pidyn.data.sources import synthetic
    from pidyn.discrepancy.case import Case
    from pidyn.discrepancy.nominal import polish
    from pidyn.discrepancy.settings import DiagnosisSettings
    from pidyn.systems import Duffing

    truth = Duffing(c=0.5, k1=15.0, k3=120.0)
    record = synthetic(truth, "el_centro", duration=12.0, dt=0.02, channels=("x",))
    case = Case(
        record, LinearSDOF(), {}, {}, DiagnosisSettings(), 1.0, (0.0, 8.0), (8.0, 12.0), tmp_path, None
    )
    far = {"m": 1.0, "c": 2.0, "k1": 6.0, "k3": 900.0}  # a network's estimate in another basin
    near = {"c": 0.55, "k1": 14.0, "k3": 100.0}  # the check's fit
    values, note = polish(case, truth, far, max_nfev=40, alternative=near)
    assert "from the check's fit" in note
    assert values["k1"] == pytest.approx(15.0, rel=1e-3) and values["k3"] == pytest.approx(120.0, rel=1e-2)
    values, note = polish(case, truth, {**far, **near}, max_nfev=40, alternative=far)
    assert "check's fit" not in note  # the network's estimate is the cheaper start: kept
    assert values["k1"] == pytest.approx(15.0, rel=1e-3)
