"""Model discrepancy: the effect library, the weak form, the screening, the full diagnosis.

The tests hide an effect (drawn by seed, random magnitude, record and noise up to 5 %) in
simulated data and require the diagnosis to name it; with nothing hidden the answer must be
``none``.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from helpers import make_cfg  # noqa: E402

from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Signals, get_effect  # noqa: E402
from pidyn.discrepancy.hidden import EQUIVALENT, hidden_case  # noqa: E402
from pidyn.discrepancy.screening import screen  # noqa: E402
from pidyn.excitation import prepare  # noqa: E402
from pidyn.simulate import simulate  # noqa: E402
from pidyn.systems import BoucWen, LinearSDOF  # noqa: E402
from pidyn.systems.terms import latent_path  # noqa: E402
from pidyn.weak_form import WeakForm, smooth_signals, velocity_noise  # noqa: E402

PERIOD = 2 * np.pi / np.sqrt(15.0)

#: a second end-to-end case of a capability another test in `make test` already proves (`make test-all`)
SECOND = pytest.mark.second_proof


def _screen(case, effects=None):
    r = case.record
    xs, vs = smooth_signals(r.t, r.x[:, 0], r.v[:, 0], PERIOD)
    s = Signals(
        r.t,
        xs,
        vs,
        1.0,
        15.0,
        "k",
        t_fit_end=case.fit_end,
        v_noise=velocity_noise(r.t, r.x[:, 0], r.v[:, 0], PERIOD),
    )
    weak = WeakForm.for_record(r.t, PERIOD)
    return screen(
        LinearSDOF(), {"m": 1.0, "c": 0.5, "k": 15.0}, s, r.f, r.x[:, 0], weak, case.fit_end, effects=effects
    )


def test_every_effect_term_matches_its_regression_columns():
    """The force the extended model uses is the force the screening fitted, for every effect."""
    rng = np.random.default_rng(0)
    t = np.linspace(0, 10, 1001)
    x = 0.05 * np.sin(2 * t) + 0.02 * np.sin(5.3 * t)
    v = np.gradient(x, t)
    s = Signals(t, x, v, 1.0, 15.0, "k", t_fit_end=8.0)
    for name, eff in EFFECTS.items():
        cand = next(iter(eff.candidates(s)))
        coef = {n: float(rng.uniform(0.5, 2.0)) for n in cand.coef_names}
        params = eff.parameters(coef, cand.fixed, {"k": 15.0, "c": 0.5})
        term = eff.term(params, s.context())
        p = {"k": 15.0, "c": 0.5, **params}
        z = latent_path(term, t, x, None, p) if term.n_latent else None
        col = cand.columns @ np.array([coef[n] for n in cand.coef_names])
        got = term.force(t, x, v, z, p)
        if name in (
            "stiffness_loss",
            "damping_change",
        ):  # a smoothed step in the term, a sharp one in the column
            far = np.abs(t - cand.fixed["t_d"]) > 1.0
            np.testing.assert_allclose(got[far], col[far], rtol=1e-6, atol=1e-9)
        else:
            np.testing.assert_allclose(got, col, rtol=1e-6, atol=1e-9, err_msg=name)


def test_bouc_wen_latent_for_several_shapes_at_once_matches_the_ode_of_each():
    """The hysteresis screening integrates z for its whole grid of shapes in one pass."""
    gm = prepare("el_centro", duration=15.0, dt=0.01)
    sys_ = BoucWen()
    tr = simulate(sys_, sys_.true_values(), gm, gm.t)
    term = next(t for t in sys_.terms if t.n_latent)
    shapes = {"beta": np.array([1.0, 0.5]), "gamma": np.array([2.0, 1.0]), "n": np.array([2.0, 1.0])}
    z = latent_path(term, gm.t, tr.x[:, 0], tr.v[:, 0], shapes)
    assert z.shape == (len(gm.t), 2, 1)
    assert np.max(np.abs(z[:, 0, 0] - tr.z[:, 0])) < 2e-3 * np.max(np.abs(tr.z))
    alone = latent_path(term, gm.t, tr.x[:, 0], tr.v[:, 0], {"beta": 0.5, "gamma": 1.0, "n": 1.0})
    np.testing.assert_allclose(z[:, 1, 0], alone[:, 0], rtol=1e-12, atol=1e-15)


def test_weak_form_recovers_a_linear_model_from_noisy_data():
    case = hidden_case(None, seed=3, noise=0.05)
    sc = _screen(case, effects={})
    assert sc.nominal_params["c"] == pytest.approx(0.5, rel=0.05)
    assert sc.nominal_params["k"] == pytest.approx(15.0, rel=0.01)


@pytest.mark.slow
def test_information_count_is_calibrated_on_noise():
    """With nothing hidden, adding one two-sided column (a cubic or a quadratic spring) lowers the
    residual by noise alone, and n_eff log(RSS0 / RSS) must average chi2_1's 1 over seeds. Counting
    one row per non-overlapping window gave 0.67 here: evidence understated by 1.8x."""
    two_sided = {n: EFFECTS[n] for n in ("cubic_stiffness", "quadratic_stiffness")}
    stats = []
    for seed in range(40):
        sc = _screen(hidden_case(None, seed, noise=0.03), effects=two_sided)
        stats += [-sc.n_independent * np.log(1.0 - r.explained) for r in sc.ranking if r.score is not None]
    assert len(stats) == 80
    # chi2_1: mean 1, sd of an 80-draw mean 0.16 (1.23 here; 0.67 with the old count)
    assert 0.75 < np.mean(stats) < 1.5, np.mean(stats)


@pytest.mark.parametrize("effect", [None, *LIBRARY])
@pytest.mark.parametrize("seed", [11, 12])
def test_screening_names_the_hidden_effect(effect, seed):
    """Seeded record, magnitude and noise (seed 12: 5 % noise); the top effect must be the hidden one."""
    case = hidden_case(effect, seed, noise=0.05 if seed == 12 else None)
    sc = _screen(case)
    assert sc.cause == effect, (effect, case.noise, sc.ranking[:2])
    if effect is None:
        assert sc.verdict == "none"
    else:
        top = sc.ranking[0]
        assert top.cv_gain > 0.3
        eff = get_effect(effect)
        # the screening is a starting point; a loose check here, the tight one after identification
        assert top.parameters[eff.key] == pytest.approx(case.truth[eff.key], rel=0.5)


def test_silverbox_screening_finds_the_cubic_stiffness():
    """Real data: the Silverbox circuit is a Duffing oscillator; starting from a linear model
    the screening must name the cubic stiffness (hardening, k3 > 0)."""
    from pidyn.data.measured.silverbox import load_silverbox
    from pidyn.signals import dominant_period

    r = load_silverbox()
    fit_end = r.meta.split.fit[1]
    m = r.t <= fit_end
    period = dominant_period(r.t[m], r.x[m])
    assert 65 < 1 / period < 75  # the resonance near 69 Hz
    xs, vs = smooth_signals(r.t, r.x[:, 0], None, period)
    s = Signals(r.t, xs, vs, 1.0, 1.0, "k", t_fit_end=fit_end)
    sys_ = LinearSDOF(excitation="force", identify_mass=True)
    sc = screen(
        sys_,
        {"m": 1.0, "c": 1.0, "k": 1.0},
        s,
        r.f,
        r.x[:, 0],
        WeakForm.for_record(r.t, period),
        fit_end,
        mass_known=False,
    )
    assert sc.cause == "cubic_stiffness"
    assert sc.ranking[0].parameters["k3"] > 0
    fn = np.sqrt(sc.nominal_params["k"] / sc.nominal_params["m"]) / (2 * np.pi)
    assert 60 < fn < 75


def test_bad_settings_fail_clearly(tmp_path):
    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(["diagnosis.effects=[cubic_stifness]", "logger=none"], tmp_path, config_name="diagnose")
    with pytest.raises(ValueError, match="cubic_stifness"):
        diagnose(cfg)
    cfg = make_cfg(["data.mass=null", "logger=none"], tmp_path, config_name="diagnose")
    with pytest.raises(ValueError, match="mass"):
        diagnose(cfg)


FAST = [
    "model.schedule.pretrain_iters=150",
    "model.schedule.pretrain_iters_window=150",
    "model.schedule.max_iters=200",
    "model.schedule.max_windows=2",
    "logger=none",
]


@pytest.mark.slow
@pytest.mark.parametrize("effect", ["coulomb_friction", "none"])
def test_diagnosis_finds_estimates_and_gains(effect, tmp_path):
    """End to end (PIDynNet, polish, screening, extension, held-out simulation) on a seeded
    hidden effect with 2 % noise: the diagnosis names it, estimates its key parameter within
    the effect's stated tolerance and lowers the held-out error; with nothing hidden: none.
    Other effects end to end: stiffness losses below (a softening cubic with ``make test-all``), quadratic damping
    in the user's CSV file and in the API walkthrough (test_api), every kind in
    ``make discrepancy-bench``."""
    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(
        [f"data.source.effect={effect}", "noise=0.02", "data_seed=5", *FAST], tmp_path, config_name="diagnose"
    )
    d = diagnose(cfg)
    saved = json.loads((tmp_path / "diagnosis.json").read_text())
    assert saved["verdict"] == d["verdict"]
    for f in [
        "report.md",
        "figures/residual.png",
        "figures/simulation_vs_measured.png",
        "figures/ranking.png",
        "nominal/config.yaml",
        "nominal/identified_params.yaml",
    ]:
        assert (tmp_path / f).exists(), f
    # its own identifications draw nothing (subrun_figures): the diagnosis's figures show both models
    assert not (tmp_path / "nominal" / "figures").exists()
    assert "transfer_function" not in json.loads((tmp_path / "nominal" / "metrics.json").read_text())
    if effect == "none":
        assert d["verdict"] == "none" and d["cause"] is None and d["gain"]["extended"] is None
        return
    assert d["verdict"] == "discrepancy" and d["cause"] == effect, d["ranking"][:2]
    eff = get_effect(effect)
    truth = d["hidden"]["parameters"][eff.key]
    assert d["parameters"][eff.key] == pytest.approx(truth, rel=eff.tolerance)
    assert d["gain"]["extended"] < 0.7 * d["gain"]["nominal"]
    assert (tmp_path / "extended" / "config.yaml").exists()


@pytest.mark.slow
@SECOND  # quadratic damping end to end: test_api's walkthrough; a user's CSV: the building diagnoses
def test_diagnosis_of_a_users_csv_file(tmp_path):
    """A CSV written by a user (t, x, ag), known mass, no split in the data: the fit_share split."""
    from pidyn.tasks.diagnose import diagnose

    case = hidden_case("quadratic_damping", seed=8, noise=0.01)
    r = case.record
    path = tmp_path / "measured.csv"
    pd.DataFrame({"t": r.t, "x": r.x[:, 0], "ag": r.f}).to_csv(path, index=False)
    cfg = make_cfg(
        ["data=csv", f"data.path={path}", "data.mass=1.0", *FAST], tmp_path / "run", config_name="diagnose"
    )
    d = diagnose(cfg)
    assert d["cause"] == "quadratic_damping"
    assert d["parameters"]["c2"] == pytest.approx(
        case.truth["c2"], rel=get_effect("quadratic_damping").tolerance
    )
    assert d["gain"]["extended"] < 0.7 * d["gain"]["nominal"]
    assert d["split"]["fit"][1] == pytest.approx(0.65 * r.t[-1], rel=1e-6)


@pytest.mark.parametrize("effect,key", [("cubic_stiffness", "k3"), ("quadratic_stiffness", "k2")])
def test_signed_effects_are_found_with_their_sign(effect, key):
    """Softening (k3 < 0) and a negative k2 are findings, not errors: the screening names them
    with the right sign and the extension term accepts the negative start."""
    for seed in (3, 4):
        case = hidden_case(effect, seed, noise=0.03, sign=-1)
        assert case.truth[key] < 0
        sc = _screen(case)
        assert sc.cause == effect, sc.ranking[:2]
        est = sc.ranking[0].parameters[key]
        assert est == pytest.approx(case.truth[key], rel=0.3)
        term = get_effect(effect).term(sc.ranking[0].parameters, {})
        spec = term.specs()[0]
        assert spec.transform == "identity" and spec.init < 0


def test_bouc_wen_benchmark_screening_names_the_hysteresis():
    """The Bouc-Wen benchmark (force in, displacement out, mass unknown): starting from a
    linear oscillator, the screening names the hysteresis; the term it would add lets beta
    and gamma take either sign (the benchmark's own x'|z|^n coefficient is negative)."""
    from pidyn.data.measured.bouc_wen_benchmark import load_bouc_wen_benchmark
    from pidyn.signals import dominant_period

    r = load_bouc_wen_benchmark()
    fit_end = r.meta.split.fit[1]
    m = r.t <= fit_end
    period = dominant_period(r.t[m], r.x[m])
    xs, vs = smooth_signals(r.t, r.x[:, 0], None, period)
    s = Signals(r.t, xs, vs, 1.0, 1.0, "k", t_fit_end=fit_end)
    sys_ = LinearSDOF(excitation="force", identify_mass=True)
    sc = screen(
        sys_,
        {"m": 1.0, "c": 1.0, "k": 1.0},
        s,
        r.f,
        r.x[:, 0],
        WeakForm.for_record(r.t, period),
        fit_end,
        mass_known=False,
    )
    assert sc.cause == "hysteresis", [row.effect for row in sc.ranking]
    params = sc.ranking[0].parameters
    specs = {sp.name: sp for sp in get_effect("hysteresis").term(params, s.context()).specs()}
    assert specs["beta"].lower < 0 and specs["gamma"].lower < 0
    assert specs["beta"].lower < -1100 < specs["beta"].upper  # the benchmark's own beta fits inside


def test_the_bouc_wen_benchmark_data_match_its_equations():
    """The shipped test signal against the benchmark's equations in the project's notation
    (PROVENANCE.md): simulated from rest, one repeated period of the validation multisine
    matches its output to about 1 % with the input linear between samples, and several times
    closer with the record's own band-limited hold."""
    from pidyn.data.measured.bouc_wen_benchmark import FS, load_bouc_wen_benchmark, load_bouc_wen_validation
    from pidyn.data.measured.bouc_wen_benchmark import PERIOD as P
    from pidyn.discrepancy.extend import extended_system
    from pidyn.integrate import rk4, stage_excitation

    train = load_bouc_wen_benchmark()
    assert len(train.t) == 5 * P and abs(train.meta.dt - 1 / FS) < 1e-15
    assert train.meta.split.fit[1] < train.meta.split.heldout[0]
    rec = load_bouc_wen_validation("val_multisine")
    system = extended_system(
        LinearSDOF(mass=2.0, excitation="force", identify_mass=True),
        "hysteresis",
        {"kh": 5e4, "beta": -1100.0, "gamma": 800.0, "n": 1.0},
        {},
    )
    truth = {"m": 2.0, "c": 10.0, "k": 5e4, "kh": 5e4, "beta": -1100.0, "gamma": 800.0, "n": 1.0}
    assert "+ 1100 x' |z|^1" in system.describe(truth)
    f = np.tile(rec.f, 3)
    y = rec.x[:, 0]
    nrms = {}
    for hold in ("linear", rec.meta.input_hold):
        stages = stage_excitation(f, 4, hold)
        Y, _ = rk4(system, truth, np.arange(len(f)) / FS, f, np.zeros((1, system.n_state)), 4, stages=stages)
        nrms[hold] = np.sqrt(np.mean((Y[-P:, 0, 0] - y) ** 2)) / np.std(y)
    assert nrms["linear"] < 0.02 and nrms["bandlimited"] < 0.3 * nrms["linear"], nrms
    with pytest.raises(Exception, match="unknown signal"):
        load_bouc_wen_validation("val_chirp")


def test_the_latent_state_along_the_measured_motion_matches_the_ode():
    """An extended model with a latent term (a hysteresis found in an earlier step) is screened
    again: its z is integrated along the measured motion, as the simulation has it."""
    gm = prepare("el_centro", duration=15.0, dt=0.01)
    sys_ = BoucWen()
    p = sys_.true_values()
    tr = simulate(sys_, p, gm, gm.t)
    s = Signals(gm.t, tr.x[:, 0], tr.v[:, 0], 1.0, 12.0, "k")
    term = next(t for t in sys_.terms if t.n_latent)
    z = latent_path(term, s.t, s.x, s.v, p)[:, 0]
    assert np.max(np.abs(z - tr.z[:, 0])) < 2e-3 * np.max(np.abs(tr.z))


def test_a_sign_physics_fixes_cannot_be_flipped():
    with pytest.raises(ValueError, match="fixed by physics"):
        hidden_case("coulomb_friction", 1, sign=-1)


def _change_rows(case, fit_end):
    from pidyn.discrepancy.screening import weak_system

    r = case.record
    xs, vs = smooth_signals(r.t, r.x[:, 0], r.v[:, 0], PERIOD)
    s = Signals(r.t, xs, vs, 1.0, 15.0, "k", t_fit_end=fit_end)
    weak = WeakForm.for_record(r.t, PERIOD)
    values = {"m": 1.0, "c": 0.5, "k": 15.0}
    names, A0, y = weak_system(LinearSDOF(), values, s, r.f, r.x[:, 0], weak)
    w = 2 * weak.half + 1
    return s, weak, values, names, A0, y, weak.t[weak.starts], weak.t[weak.starts + w - 1]


@pytest.mark.parametrize("t_d", [9.0, 20.0])
def test_a_change_in_time_is_located_before_and_after_the_split(t_d):
    """A stiffness loss hidden before (9 s) and after (20 s) the split at 16 s. The held-out
    check fails when the change is after the split (the nominal model is fine on the fitting
    part, wrong after it); the whole-record search finds the time inside its interval and the
    size of the drop; the same search on a record with nothing hidden finds nothing."""
    from pidyn.discrepancy.changes import StepRegression, locate_change
    from pidyn.discrepancy.heldout_check import heldout_check
    from pidyn.simulate import simulate_response

    case = hidden_case("stiffness_loss", 21, noise=0.02, params={"t_d": t_d})
    r = case.record
    s, weak, values, names, A0, y, t_first, t_last = _change_rows(case, float(r.t[-1]))
    x_sim = simulate_response(LinearSDOF(), values, r, state0=np.array([r.x[0, 0], r.v[0, 0]]))["x"][:, 0]
    fit, held = r.t <= case.fit_end, r.t >= case.fit_end
    check = heldout_check(
        r.x[:, 0], x_sim, fit, held, noise_std=0.02 * float(np.sqrt(np.mean(r.x[:, 0] ** 2)))
    )
    assert check.failed == (t_d > case.fit_end), check
    rows = np.ones(len(y), bool)
    n_eff = rows.sum() / weak.rows_per_independent
    reg = StepRegression(names, A0, y, t_first, t_last, s.x, s.v, s.t, weak)
    ch = locate_change(reg, rows, n_eff, {"stiffness_loss": "k", "damping_change": "c"}, values)
    assert ch is not None and ch.effect == "stiffness_loss" and ch.delta_bic < -10
    assert ch.ci95[0] <= t_d <= ch.ci95[1] and ch.ci95[1] - ch.ci95[0] < 1.0, ch.ci95
    assert -ch.fraction == pytest.approx(case.truth["drop"], rel=0.2)

    nothing = hidden_case(None, 21, noise=0.02)
    s0, weak0, _, names0, A00, y0, tf0, tl0 = _change_rows(nothing, float(r.t[-1]))
    reg0 = StepRegression(names0, A00, y0, tf0, tl0, s0.x, s0.v, s0.t, weak0)
    ch0 = locate_change(
        reg0, np.ones(len(y0), bool), n_eff, {"stiffness_loss": "k", "damping_change": "c"}, values
    )
    assert ch0 is None or ch0.delta_bic > -10, ch0


def test_a_step_found_over_the_whole_record_must_persist():
    """The held-out failure search over the whole record: on a trilinear spring it finds a
    stiffness "loss" in the strong motion (dBIC below -10), which fits the rows after the
    fitting part far worse than no step; that step does not persist and nothing is named, the
    split unchanged. A real loss at 9 s is located, and its step fits the held-out rows better."""
    from pidyn.discrepancy.changes import locate_step
    from pidyn.discrepancy.screening_rules import Thresholds

    def locate(case):
        r = case.record
        s, weak, values, *_ = _change_rows(case, float(r.t[-1]))
        fit, held = (0.0, case.fit_end), (case.fit_end, float(r.t[-1]))
        return (
            locate_step(
                LinearSDOF(),
                values,
                s,
                r.f,
                r.x[:, 0],
                weak,
                fit,
                held,
                True,
                {"stiffness_loss": "k", "damping_change": "c"},
                Thresholds(),
                True,
            ),
            fit,
            held,
        )

    for seed in (1, 8):  # the whole record's best step: a loss with dBIC below -10
        (change, fit, held), fit0, held0 = locate(hidden_case("trilinear_spring", seed, noise=0.02))
        assert change is None and (fit, held) == (fit0, held0), (seed, change)
    (change, fit, held), fit0, _ = locate(hidden_case("stiffness_loss", 1, noise=0.02, params={"t_d": 9.0}))
    assert change is not None and change.effect == "stiffness_loss" and abs(change.t_change - 9.0) < 0.3
    assert change.heldout_gain is not None and change.heldout_gain > 0.5 and fit[1] >= fit0[1]


@pytest.mark.slow
@pytest.mark.parametrize(
    "case",
    [
        pytest.param("softening_cubic", marks=SECOND),  # test_output_error_check names it too
        # the held-out test's catch: test_screening_rules; end to end: test_building_diagnosis
        pytest.param("change_after_split", marks=SECOND),
        pytest.param("change_before_split", marks=SECOND),  # located before and after the split below
    ],
)
def test_diagnosis_of_signed_effects_and_changes_in_time(case, tmp_path):
    """End to end: a softening cubic (it used to crash the extension), a stiffness loss after
    the split (the nominal model is fine on the fitting part and fails after it: the verdict
    must not be none, the change is located and the gain measured on data no fit used) and
    one late in the fitting part."""
    from pidyn.tasks.diagnose import diagnose

    over = {
        "softening_cubic": ["data.source.effect=cubic_stiffness", "data.source.sign=-1"],
        "change_after_split": ["data.source.effect=stiffness_loss", "+data.source.params={t_d: 19.0}"],
        "change_before_split": ["data.source.effect=stiffness_loss", "+data.source.params={t_d: 14.5}"],
    }[case]
    cfg = make_cfg([*over, "noise=0.02", "data_seed=5", *FAST], tmp_path, config_name="diagnose")
    d = diagnose(cfg)
    truth = d["hidden"]["parameters"]
    assert d["verdict"] == "discrepancy" and d["causes"] == [d["cause"]]
    if case == "softening_cubic":
        assert d["cause"] == "cubic_stiffness"
        assert d["parameters"]["k3"] == pytest.approx(truth["k3"], rel=0.2) and d["parameters"]["k3"] < 0
    else:
        assert d["cause"] == "stiffness_loss"
        lo, hi = d["parameters"]["t_change_ci95"]
        assert lo <= truth["t_d"] <= hi
        assert d["t_change"] == d["parameters"]["t_change"] and d["storeys"] == [None]  # a single storey
        assert d["parameters"]["drop"] == pytest.approx(truth["drop"], rel=0.25)
        assert (
            d["split"]["heldout"][0] > truth["t_d"]
        )  # the gain is measured after the change, on unused data
        assert (tmp_path / "figures" / "running_estimate.png").exists()
    assert d["gain"]["extended"] < 0.5 * d["gain"]["nominal"]


@pytest.mark.slow
@pytest.mark.parametrize(
    "pair",
    ["quadratic_stiffness+quadratic_damping", pytest.param("gap_contact+coulomb_friction", marks=SECOND)],
)
def test_diagnosis_names_two_hidden_effects_and_no_third(pair, tmp_path):
    """Two effects hidden together: diagnose, extend, diagnose the extended model again. Both
    are named (in either order), their parameters recovered, and the screening of the final
    model passes nothing more."""
    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(
        [f"data.source.effect={pair}", "noise=0.02", "data_seed=5", *FAST], tmp_path, config_name="diagnose"
    )
    d = diagnose(cfg)
    assert d["verdict"] == "discrepancy"
    assert sorted(d["causes"]) == sorted(pair.split("+")), d["steps"]
    assert d["cause"] == d["causes"][0]
    for name in pair.split("+"):
        eff = get_effect(name)
        assert d["parameters"][eff.key] == pytest.approx(
            d["hidden"]["parameters"][eff.key], rel=eff.tolerance
        )
    last = d["steps"][-1]["next_ranking"]
    assert not any(r["passes"] for r in last), last
    assert (tmp_path / "extended_2" / "config.yaml").exists()
    assert d["gain"]["extended"] < 0.7 * d["gain"]["nominal"]
    assert "Steps" in (tmp_path / "report.md").read_text()


@pytest.mark.parametrize(
    "pair, seed",
    [
        ("gap_contact+coulomb_friction", 1014),
        ("gap_contact+coulomb_friction", 1050),
        ("cubic_stiffness+coulomb_friction", 1000),
    ],
)
def test_screening_names_a_pair_that_a_third_effect_stands_in_for(pair, seed):
    """Friction plus a stop score, one at a time, most like a cubic spring (seed 1014); friction
    plus a cubic, most like a stop (1000); or friction alone, soaked up by the refitted damping,
    scores too little (1050): the greedy screening named the third effect or nothing. Fitted
    jointly, the hidden pair wins."""
    sc = _screen(hidden_case(pair, seed))
    greedy = sc.ranking[0]
    assert not (greedy.passes and greedy.effect in pair.split("+")), "greedy naming alone would do here"
    assert sc.verdict == "discrepancy" and sc.cause in pair.split("+"), (
        sc.ranking[:3],
        sc.structure.get("pair"),
    )
    assert sorted(sc.structure["pair"]["effects"]) == sorted(pair.split("+"))


@pytest.mark.parametrize("seed", [1019, 1073])
def test_the_true_friction_model_screens_clean(seed):
    """Screened again with its friction found (at the true values), a Coulomb friction case leaves
    nothing. Near rest the measured velocity is mostly noise and no friction column matches the
    force there; the refitted damping took that up as a "damping change" to less than no damping
    (scores 17 and 22), which is no change of a structure."""
    from pidyn.systems.terms import CoulombFriction

    case = hidden_case("coulomb_friction", seed)
    r = case.record
    xs, vs = smooth_signals(r.t, r.x[:, 0], r.v[:, 0], PERIOD)
    s = Signals(
        r.t,
        xs,
        vs,
        1.0,
        15.0,
        "k",
        t_fit_end=case.fit_end,
        v_noise=velocity_noise(r.t, r.x[:, 0], r.v[:, 0], PERIOD),
    )
    found = LinearSDOF().with_term(CoulombFriction(case.truth["Fc"], eps=s.friction_eps))
    rest = {n: e for n, e in LIBRARY.items() if n != "coulomb_friction"}
    sc = screen(
        found,
        {"m": 1.0, "c": 0.5, "k": 15.0, "Fc": case.truth["Fc"]},
        s,
        r.f,
        r.x[:, 0],
        WeakForm.for_record(r.t, PERIOD),
        case.fit_end,
        effects=rest,
    )
    assert sc.verdict == "none", sc.ranking[:2]
    change = next(q for q in sc.ranking if q.effect == "damping_change")
    assert change.score is None or change.parameters["change"] > -1.0


def test_ridge_fit_survives_a_column_silent_in_the_fitting_rows():
    """A stop whose polished gap lies beyond the motion of the fitting part gives a zero column;
    the ridge fit (the generic force's yardstick) used to fail there with a singular matrix."""
    from pidyn.discrepancy.regression import lstsq

    rng = np.random.default_rng(0)
    A, y = rng.normal(size=(50, 6)), rng.normal(size=50)
    ridge = np.r_[0.0, 0.0, np.full(4, 1e-3)]
    scale = np.sqrt((A**2).sum(0))
    As = A / scale
    expected = np.linalg.solve(As.T @ As + np.diag(ridge), As.T @ y) / scale
    assert np.allclose(lstsq(A, y, ridge), expected, rtol=1e-10, atol=1e-12)
    A[:, 1] = 0.0
    theta = lstsq(A, y, ridge)
    assert np.all(np.isfinite(theta)) and theta[1] == 0.0


@pytest.mark.parametrize(
    "effect", [pytest.param(e, marks=SECOND) if e == "stribeck_friction" else e for e in EQUIVALENT]
)
def test_screening_never_gives_an_outside_effect_a_wrong_name(effect):
    verdicts = {}
    for seed in range(1, 7):
        sc = _screen(hidden_case(effect, seed, noise=0.02))
        assert sc.cause is None or sc.cause in EQUIVALENT[effect], (seed, sc.ranking[:2])
        assert sc.verdict in ("none", "unexplained", "discrepancy")
        verdicts[seed] = (sc.verdict, sc.structure)
    # and a clearly structured residual no library effect explains is 'unexplained', not 'none'
    if effect == "trilinear_spring":
        verdict, structure = verdicts[3]
        assert verdict == "unexplained" and structure["structured"], structure


def test_a_learned_force_term_starts_at_the_force_it_is_shown():
    """The network term used for unexplained residuals: zero at construction (the extension
    starts as the nominal model), fitted to a force it is shown, and the same in torch and NumPy."""
    import torch

    from pidyn.systems.terms import LearnedForce

    rng = np.random.default_rng(0)
    x, v = rng.uniform(-0.1, 0.1, 2000), rng.uniform(-0.5, 0.5, 2000)
    f = 8.0 * np.maximum(np.abs(x) - 0.05, 0) * np.sign(x) + 0.2 * np.tanh(v / 0.05)
    term = LearnedForce(0.1, 0.5, 1.0, seed=1)
    assert np.all(term.force(0.0, x, v, None, {}) == 0.0)
    assert term.fit_to(x, v, f, iters=400) < 0.1
    torch_f = term.force(
        0.0, torch.as_tensor(x, dtype=torch.float32), torch.as_tensor(v, dtype=torch.float32), None, {}
    )
    np.testing.assert_allclose(
        torch_f.detach().numpy(), term.force(0.0, x, v, None, {}), rtol=1e-4, atol=1e-5
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "effect", [pytest.param(e, marks=SECOND) for e in EQUIVALENT]
)  # an outside force left unnamed: the screening test above; a learned force in its place: test_names_that_...
def test_diagnosis_of_an_effect_outside_the_library(effect, tmp_path):
    """Hidden effects the library does not hold: the verdict is 'unexplained' (then a learned
    force f(x, x') in PIDynNet's physics loss) or a physically equivalent library name, never
    another; either way the extended model gains on the held-out data."""
    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(
        [
            f"data.source.effect={effect}",
            "noise=0.02",
            "data_seed=5",
            "diagnosis.learned.max_evaluations=30",
            *FAST,
        ],
        tmp_path,
        config_name="diagnose",
    )
    d = diagnose(cfg)
    assert d["verdict"] in ("unexplained", "discrepancy")
    assert set(d["causes"]) <= EQUIVALENT[effect], d["causes"]
    if d["verdict"] == "unexplained":
        assert d["learned_force"] and (tmp_path / "figures" / "learned_force.png").exists()
        assert "f_NN" in d["extended"]
        lf = d["learned_fit"]  # trained on the simulated response after PIDynNet, its weights written
        assert lf["loss_after"] < lf["loss_before"] and (tmp_path / lf["file"]).exists(), lf
        assert "trained further on the simulated response" in (tmp_path / "report.md").read_text()
    assert d["gain"]["extended"] < 0.95 * d["gain"]["nominal"]


@pytest.mark.slow
def test_names_that_do_not_earn_their_place_give_way_to_a_learned_force(tmp_path):
    """Coulomb friction hidden, and the names required to cut the held-out error by 95 %: the
    friction's extension is not kept (``unearned``, note ``name_unearned``), a learned force is
    tried from the nominal model in its place, and the verdict is unexplained."""
    from pidyn.notes import code_of
    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(
        [
            "data.source.effect=coulomb_friction",
            "noise=0.02",
            "data_seed=5",
            "diagnosis.thresholds.min_name_gain=0.95",
            "diagnosis.learned.max_evaluations=10",
            *FAST,
        ],
        tmp_path,
        config_name="diagnose",
    )
    d = diagnose(cfg)
    assert d["verdict"] == "unexplained" and d["causes"] == [] and d["cause"] is None, d["verdict"]
    unearned = d["unearned"]
    assert unearned["causes"] == ["coulomb_friction"] and code_of(unearned["note"]) == "name_unearned"
    assert [s["effect"] for s in unearned["steps"]] == ["coulomb_friction"]  # what was tried, kept aside
    assert all(s["effect"] != "coulomb_friction" for s in d["steps"])
    assert "Fc" not in (d["extended_parameters"] or {})  # the friction is not in the reported model
    assert d["learned_force"] or d["learned_force_refused"] is not None  # tried in its place


def test_a_stiffness_that_rises_in_time_is_no_stiffness_loss():
    """Under an earthquake, a softening (or trilinear) spring looks like a stiffness that rises
    once the strong motion is over. Named `stiffness_loss`, it used to be the wrong name for
    an effect outside the library; the screening now fits only losses, and a located step
    that is a rise is not named."""
    from pidyn.discrepancy.changes import Change, is_stiffening
    from pidyn.discrepancy.regression import fit_candidate

    t = np.linspace(0.0, 20.0, 2001)
    x = np.sin(2 * np.pi * 0.6 * t) * np.exp(-0.05 * t)
    s = Signals(t, x, np.gradient(x, t), 1.0, 15.0, "k", t_fit_end=20.0)
    loss = get_effect("stiffness_loss")
    fit, ho = t < 16.0, t >= 16.0
    A0 = np.column_stack([x, s.v])
    for step, found in ((-3.0, True), (+3.0, False)):  # restoring force k x + step x H(t - 8): a loss, a rise
        y = 15.0 * x + step * x * (t >= 8.0)
        fits = [f for f in (fit_candidate(c, A0, c.columns, y, fit, ho) for c in loss.candidates(s)) if f]
        assert bool(fits) is found
        if found:
            best = min(fits, key=lambda f: f["rss_fit"])
            p = loss.parameters(best["coef"], best["fixed"], {"k": 15.0})
            assert p["drop"] == pytest.approx(0.2, rel=0.05) and abs(p["t_d"] - 8.0) < 0.6
    rise = Change("stiffness_loss", "k", 9.2, (9.0, 10.1), +0.2, -30.0, 0.8)
    assert is_stiffening(rise)
    assert not is_stiffening(Change("stiffness_loss", "k", 9.2, (9.0, 10.1), -0.2, -30.0, 0.8))
    assert not is_stiffening(Change("damping_change", "c", 9.2, (9.0, 10.1), +1.0, -30.0, 0.8))
