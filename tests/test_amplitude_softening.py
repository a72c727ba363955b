"""The amplitude-dependent structure: a stiffness and damping that follow the response's recent
amplitude (a latent envelope), identified from accelerations, and tried by the diagnosis where
the running period moves."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.data.sources import synthetic
from pidyn.refine.output_error import fit_output_error
from pidyn.simulate import simulate_response
from pidyn.systems import AmplitudeDependent, LinearSDOF, SDOFSystem
from pidyn.systems.terms import AmplitudeSoftening, LinearStiffness, ViscousDamping


def test_an_amplitude_dependent_structure_is_recovered_from_its_accelerations():
    """A 20 s accelerometer record whose stiffness falls by 40 % of its envelope (time constant
    1.5 s): the linear fit is 12 % soft; the extension started at 10 % and 1 s recovers the
    softening, the damping's gain, the time constant and the stiffness at rest."""
    k, c = 400.0, 2.0
    lin = LinearSDOF(c=c, k=k)
    calm = synthetic(lin, "el_centro", channels=("a",), duration=20.0, dt=0.02)
    a_ref = float(np.max(np.abs(simulate_response(lin, {"m": 1.0, "c": c, "k": k}, calm, 4)["x"])))
    true = SDOFSystem(
        [ViscousDamping(c), LinearStiffness(k), AmplitudeSoftening(0.4, 0.8, 1.5, a_ref=a_ref, w0=20.0)]
    )
    seg = synthetic(true, "el_centro", noise=0.02, channels=("a",), duration=20.0, dt=0.02).segment(0, 13.0)
    nominal = fit_output_error(seg, lin, init={"c": c, "k": k}, max_nfev=100, tol=1e-8)
    assert nominal.params["k"] < 0.92 * k  # the linear model takes a softer spring
    w0 = float(np.sqrt(nominal.params["k"]))  # as the diagnosis builds it: at the nominal frequency
    ext = lin.with_term(AmplitudeSoftening(0.1, 0.1, 1.0, a_ref=a_ref, w0=w0))
    fit = fit_output_error(
        seg, ext, init={**nominal.params, "soft": 0.1, "gain": 0.1, "tau": 1.0}, max_nfev=100, tol=1e-8
    )
    p = fit.params
    assert fit.cost < 0.1 * nominal.cost
    assert p["k"] == pytest.approx(k, rel=0.01)
    assert p["soft"] == pytest.approx(0.4, rel=0.1)
    assert p["gain"] == pytest.approx(0.8, rel=0.15)
    assert p["tau"] == pytest.approx(1.5, rel=0.1)


def test_the_term_softens_with_the_envelope_and_recovers_as_it_decays():
    """The latent envelope rises towards A / a_ref with the time constant and falls back after
    the motion stops; the force is the stiffness and damping changed by its shares."""
    term = AmplitudeSoftening(0.5, 1.0, 2.0, a_ref=0.01, w0=10.0)
    p = {"k": 100.0, "c": 1.0, "soft": 0.5, "gain": 1.0, "tau": 2.0}
    z = np.array([[0.5]])
    rate = term.latent_rate(0.0, np.array([0.01]), np.array([0.0]), z, p)
    assert rate[0, 0] == pytest.approx((1.0 - 0.5) / 2.0)  # amplitude 0.01 = a_ref: towards 1
    assert term.latent_rate(0.0, np.array([0.0]), np.array([0.0]), z, p)[0, 0] < 0  # at rest: recovers
    f = term.force(0.0, np.array([0.01]), np.array([0.1]), z, p)
    assert f[0] == pytest.approx(-0.5 * 100.0 * 0.5 * 0.01 + 1.0 * 1.0 * 0.5 * 0.1)


@pytest.mark.parametrize("soft, gain", [(0.5, 1.0), (-0.3, -0.6)])
def test_the_bounded_law_has_the_linear_slopes_and_never_a_negative_stiffness(soft, gain):
    """At a small envelope the bounded law is the linear one to first order; at an envelope far
    beyond the fitted records (where k (1 - soft e) < 0) its stiffness and damping stay positive."""
    p = {"k": 100.0, "c": 1.0, "soft": soft, "gain": gain, "tau": 2.0}
    linear = AmplitudeSoftening(soft, gain, 2.0, law="linear")
    bounded = AmplitudeSoftening(soft, gain, 2.0, law="bounded")
    assert bounded.linear == () and linear.linear == ("soft", "gain")  # not a regression's columns
    e = 1e-4
    for a, b in zip(linear.at_envelope(p, e), bounded.at_envelope(p, e)):
        assert b == pytest.approx(a, rel=1e-6)
    e = np.array([0.0, 1.0, 3.0, 30.0])
    k_e, c_e = bounded.at_envelope(p, e)
    assert np.all(k_e > 0) and np.all(c_e > 0)
    assert np.all(np.diff(k_e) < 0) == (soft > 0) and np.all(np.diff(c_e) > 0) == (gain > 0)
    x, v, z = np.array([0.01]), np.array([0.1]), np.array([[30.0]])
    restoring = p["k"] * x + p["c"] * v + bounded.force(0.0, x, v, z, p)
    k30, c30 = bounded.at_envelope(p, 30.0)
    assert restoring[0] == pytest.approx(k30 * x[0] + c30 * v[0])
    with pytest.raises(ValueError, match="law"):
        AmplitudeSoftening(law="cubic")


def test_the_curved_law_is_the_bounded_one_at_shape_one_and_holds_moderate_shaking_stiffer_above():
    """At shape 1 the curved law is the bounded law; at shape 2 the same softening at e = 1 comes
    with less softening below it and more above it (what the exponent is for), and its
    derivative by the exponent is finite from rest, where e is 0."""
    torch = pytest.importorskip("torch")
    p = {"k": 100.0, "c": 1.0, "soft": 2.0, "gain": 1.0, "tau": 2.0, "shape": 1.0}
    e = np.array([0.0, 0.2, 0.5, 1.0, 2.0])
    bounded = AmplitudeSoftening(2.0, 1.0, 2.0, law="bounded")
    curved = AmplitudeSoftening(2.0, 1.0, 2.0, law="curved", shape=1.0)
    for a, b in zip(bounded.at_envelope(p, e), curved.at_envelope(p, e)):
        np.testing.assert_allclose(b, a, rtol=1e-9)
    assert [s.name for s in curved.specs()] == ["soft", "gain", "tau", "shape"]
    assert "shape" not in [s.name for s in bounded.specs()]
    k1, _ = bounded.at_envelope(p, e)
    k2, _ = curved.at_envelope({**p, "shape": 2.0}, e)
    assert k2[3] == pytest.approx(k1[3])  # the same at e = 1
    assert np.all(k2[1:3] > k1[1:3]) and k2[4] < k1[4]  # stiffer below, softer above
    pt = {k: torch.tensor(v, dtype=torch.float64, requires_grad=True) for k, v in {**p, "shape": 2.0}.items()}
    k_t, c_t = curved.at_envelope(pt, torch.tensor([0.0, 0.3], dtype=torch.float64))
    (k_t.sum() + c_t.sum()).backward()
    assert torch.isfinite(pt["shape"].grad) and float(pt["shape"].grad) != 0.0
    assert "e^2" in curved.formula({**p, "shape": 2.0})


def test_a_moving_period_adds_the_amplitude_dependent_structure_to_the_check(monkeypatch):
    """On an accelerometer record whose running period moves beyond its windows' intervals, the
    output-error check also fits the amplitude-dependent structure; where the period holds, or
    the user lists the effects to screen, it does not."""
    from types import SimpleNamespace

    from pidyn.discrepancy import sdof_steps as pipeline
    from pidyn.discrepancy.confirm import Confirmation

    seen = {}

    def fake(case, system, values, node, sc, s, k, everything=False, extra=None):
        seen["extra"] = [r.effect for r in extra or []]
        return Confirmation()

    monkeypatch.setattr(pipeline, "confirm_undecided", fake)
    nom = SimpleNamespace(system=None, values={}, node={}, s=None)
    sc = SimpleNamespace(cause=None, verdict="none")
    holds = SimpleNamespace(failed=False)
    moves, still = {"variation": {"varies": True}}, {"variation": {"varies": False}}
    for effects, running, expect in (
        ([], moves, ["amplitude_softening"]),
        ([], still, []),
        ([], None, []),
        (["cubic_stiffness"], moves, []),
    ):
        case = SimpleNamespace(from_accelerometers=True, settings=SimpleNamespace(effects=effects))
        assert pipeline._first_cause(case, nom, sc, holds, None, None, running)[0] is None
        assert seen["extra"] == expect


def test_a_period_that_moves_between_any_two_separate_windows_counts():
    """The running period at 0.25 s with tight intervals, but 0.33 s in the window at 0.5 s: a
    tiling of the record from its first window (0, 1, 2, ... s; width 1 s) steps over it, every
    pair of windows a width apart does not. A window at 0.02 s (a mode near the sampling rate,
    fitted to a quiet stretch) is not counted against the nominal period."""
    from pidyn.discrepancy.running import period_varies

    t = np.arange(0.0, 10.01, 0.25)
    period = np.full(t.shape, 0.25)
    period[t == 0.5] = 0.33
    run = {
        "t": t,
        "period": period,
        "period_lo": 0.98 * period,
        "period_hi": 1.02 * period,
        "peak": np.ones_like(t),
    }
    out = period_varies(run, width=1.0, period=0.25)
    assert out["varies"] and out["longest"]["t"] == 0.5 and out["longest"]["period"] == pytest.approx(0.33)
    held = dict(run, period=np.full(t.shape, 0.25))
    held["period_lo"], held["period_hi"] = 0.98 * held["period"], 1.02 * held["period"]
    assert not period_varies(held, width=1.0, period=0.25)["varies"]
    held["period"] = np.where(t == 3.0, 0.02, held["period"])
    held["period_lo"], held["period_hi"] = 0.98 * held["period"], 1.02 * held["period"]
    assert period_varies(held, width=1.0)["varies"]  # no nominal period: the outlier counts
    assert not period_varies(held, width=1.0, period=0.25)["varies"]
    # two windows closer than a width share samples: not a pair
    near = np.where(t == 4.75, 0.30, np.where(t == 5.25, 0.20, 0.25))
    sure = (t == 4.75) | (t == 5.25)  # the other windows are unsure of their period
    near_run = dict(
        run,
        period=near,
        period_lo=np.where(sure, near - 0.001, 0.15),
        period_hi=np.where(sure, near + 0.001, 0.35),
    )
    assert not period_varies(near_run, width=1.0, period=0.25)["varies"]
    assert period_varies(near_run, width=0.5, period=0.25)["varies"]


def test_forcing_the_amplitude_dependent_structure_screens_it_and_a_wrong_name_fails_first(tmp_path):
    """``diagnosis.force_effect=amplitude_softening`` (not screened by default) is screened, so the
    screening ranks it and the extension starts from its row (it used to end in a StopIteration);
    a name outside the library, or an effect the nominal model already has, is a named error
    before any work."""
    from pidyn.discrepancy.case import prepare
    from pidyn.discrepancy.settings import DiagnosisSettings

    rec = synthetic(LinearSDOF(c=2.0, k=400.0), "el_centro", channels=("a",), duration=10.0, dt=0.02)

    def case(**kw):
        settings = DiagnosisSettings(**kw)
        return prepare(rec, LinearSDOF(c=2.0, k=400.0), {}, settings, 1.0, tmp_path, None)

    assert "amplitude_softening" not in case().effects
    assert "amplitude_softening" in case(force_effect="amplitude_softening").effects
    assert set(case(effects=["cubic_stiffness"], force_effect="hysteresis").effects) == {
        "cubic_stiffness",
        "hysteresis",
    }
    with pytest.raises(ValueError, match=r"force_effect: unknown effect\(s\) \['cubic_stifness'\]"):
        case(force_effect="cubic_stifness")
    with pytest.raises(ValueError, match="already has it"):
        prepare(
            rec,
            SDOFSystem([ViscousDamping(2.0), LinearStiffness(400.0), AmplitudeSoftening(0.1, 0.1, 1.0)]),
            {},
            DiagnosisSettings(force_effect="amplitude_softening"),
            1.0,
            tmp_path,
            None,
        )


def test_the_extension_draws_its_own_period_through_the_record(tmp_path):
    """The amplitude-dependent model's period along its simulated response: the period at rest
    at the start, longer in the strong shaking, shorter again in the quieter end, drawn beside
    the windows' periods."""
    from types import SimpleNamespace

    from pidyn.discrepancy.case import Extension
    from pidyn.discrepancy.report_figures import plot_running_period
    from pidyn.discrepancy.summary import amplitude_path

    k, c = 400.0, 2.0
    system = LinearSDOF(c=c, k=k).with_term(AmplitudeSoftening(0.4, 0.8, 1.5, a_ref=0.016, w0=20.0))
    values = {"m": 1.0, "c": c, "k": k, "soft": 0.4, "gain": 0.8, "tau": 1.5}
    rec = synthetic(system, "el_centro", channels=("a",), duration=20.0, dt=0.02)
    n = len(rec.t)
    case = SimpleNamespace(record=rec, x_raw=np.zeros(n), settings=SimpleNamespace(substeps=4))
    o = SimpleNamespace(  # the free run from rest the diagnosis measured its gain on
        extension=Extension(system=system, values=values),
        nominal=SimpleNamespace(s=SimpleNamespace(v=np.zeros(n))),
        sims={"extended": simulate_response(system, values, rec, 4, np.zeros(system.n_state))},
    )
    t, period, zeta = amplitude_path(case, o)
    rest = 2 * np.pi / np.sqrt(k)
    assert period[0] == pytest.approx(rest, rel=1e-6) and zeta[0] == pytest.approx(c / (2 * np.sqrt(k)))
    strong = int(np.argmax(period))
    assert period[strong] > 1.1 * rest and zeta[strong] > 1.2 * zeta[0]
    assert period[-1] < period[strong] - 0.5 * (period[strong] - rest)  # recovering in the coda
    w = np.arange(1.0, 19.0, 1.0)
    running = {
        "t": w,
        **{
            f"{q}{s}": np.full(w.shape, v)
            for q, v in (("period", rest), ("damping", 0.05))
            for s in ("", "_lo", "_hi")
        },
    }
    plot_running_period(tmp_path / "running_period.png", running, (0, 13), (13, 20), model=(t, period, zeta))
    assert (tmp_path / "running_period.png").stat().st_size > 0


def test_the_identified_equation_reads_as_written_by_hand_whatever_the_signs():
    """A softening share below zero (a stiffening) and a support dashpot below zero are joined by
    their own sign: no "+ +" or "+ -" in the equation a run reports."""
    system = AmplitudeDependent(soft=-0.3, inputs=["a", "b"])
    p = {s.name: float(s.init) for s in system.param_specs()}
    p.update({"g_a": 2.0, "g_b": -2.4, "e_b": -1.5})
    text = system.describe(p)
    assert "+ +" not in text and "+ -" not in text, text
    assert "+ 0.3 600 e x" in text and "- 2.4 vg_b(t)" in text
