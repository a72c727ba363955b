"""The refinement stage: exact Jacobians, recovery to solver precision, continuity,
covariance against a finite-difference Hessian, interval coverage over seeds."""

import numpy as np
import pytest

from pidyn.autodiff import Dual  # noqa: E402
from pidyn.baselines import cramer_rao  # noqa: E402
from pidyn.data.sources import synthetic  # noqa: E402
from pidyn.notes import codes
from pidyn.refine import (  # noqa: E402
    RefineSettings,
    ShootingProblem,
    initial_states,
    record_channels,
    refine,
    segment_bounds,
)
from pidyn.refine.uncertainty import covariance  # noqa: E402
from pidyn.systems import BoucWen, Duffing, LinearSDOF, ShearBuilding  # noqa: E402


def _problem(system, record, length, settings=None):
    settings = settings or RefineSettings(states="measured")
    bounds = segment_bounds(record.t, length)
    p = ShootingProblem(
        system, record.t, record.f, record_channels(record, system.n_dof), bounds, settings.substeps
    )
    return p


@pytest.mark.parametrize(
    "system",
    [
        BoucWen(),
        Duffing(),
        ShearBuilding(),
        ShearBuilding(
            n_storeys=5,
            storey_terms={
                1: [{"term": "hysteresis", "beta": 20.0, "gamma": 40.0, "n": 2.0, "shape_scale": 20.0}],
                2: [{"term": "cubic_stiffness", "k3": 5e3}],
            },
        ),
    ],
    ids=["bouc_wen", "duffing", "shear3", "shear5_bouc_wen_cubic"],
)
def test_dual_state_rate_matches_finite_differences(system):
    rng = np.random.default_rng(0)
    ns = system.n_state
    y = rng.normal(size=(4, ns)) * 0.1
    p = system.true_values()
    D = ns
    yd = Dual(y, np.broadcast_to(np.eye(ns), (4, ns, ns)).copy())
    out = system.state_rate(0.3, yd, p, np.full(4, 0.7))
    h = 1e-7
    for j in range(D):
        e = np.zeros(ns)
        e[j] = h
        fd = (system.state_rate(0.3, y + e, p, 0.7) - system.state_rate(0.3, y - e, p, 0.7)) / (2 * h)
        np.testing.assert_allclose(out.d[..., j], fd, rtol=1e-5, atol=1e-6)


def test_shooting_jacobian_is_exact():
    """linearize() against central differences of residuals() over every unknown."""
    s = BoucWen()
    r = synthetic(s, "el_centro", duration=4.0, noise=0.02, data_seed=3)
    prob = _problem(s, r, 1.0)
    th = {"c": 0.35, "k": 11.0, "beta": 0.8, "gamma": 1.5, "n": 1.8}
    u = prob.pack(th, initial_states(prob, prob.pack(th, np.zeros((prob.S, 3)))[:5], "measured"))
    u = u + 0.01 * np.random.default_rng(1).normal(size=u.size)
    res, J, c, C = prob.linearize(u)
    h = 1e-6
    for k in range(u.size):
        e = np.zeros(u.size)
        e[k] = h
        rp, cp = prob.residuals(u + e)
        rm, cm = prob.residuals(u - e)
        np.testing.assert_allclose(J[:, k], (rp - rm) / (2 * h), rtol=1e-4, atol=1e-5 * np.abs(J).max())
        np.testing.assert_allclose(C[:, k], (cp - cm) / (2 * h), rtol=1e-4, atol=1e-7)


def test_the_batched_finite_difference_jacobian_matches_the_exact_one_from_a_free_state():
    """One segment with its initial state free (a window of the running period): the batched
    forward differences over parameters and state against ``linearize``."""
    s = Duffing()
    r = synthetic(s, "el_centro", duration=3.0, noise=0.02, data_seed=5)
    prob = _problem(s, r, None)
    assert prob.S == 1 and prob.free_state0
    u = prob.pack({"c": 0.45, "k1": 14.0, "k3": 110.0}, np.array([[0.01, -0.02]]))
    r_fd, J_fd = prob.residuals_and_fd_jacobian(u)
    r_ex, J_ex, _, _ = prob.linearize(u)
    np.testing.assert_allclose(r_fd, r_ex, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(J_fd, J_ex, rtol=1e-3, atol=1e-4 * np.abs(J_ex).max())
    fun, jac = prob.fd_fun_and_jac()
    np.testing.assert_array_equal(fun(u), r_fd)
    np.testing.assert_array_equal(jac(u), J_fd)
    # some columns only (a profile holds the others), or none (the residuals alone): the same bits
    cols = np.array([0, 2, 4])
    fun_c, jac_c = prob.fd_fun_and_jac(columns=cols)
    np.testing.assert_array_equal(jac_c(u), J_fd[:, cols])
    np.testing.assert_array_equal(fun_c(u), r_fd)
    r_only, J_none = prob.residuals_and_fd_jacobian(u, columns=np.array([], int))
    np.testing.assert_array_equal(r_only, r_fd)
    assert J_none.shape == (len(r_fd), 0)


@pytest.mark.parametrize(
    "system,record,start",
    [
        (Duffing(), "kobe", {"c": 0.6, "k1": 13.0, "k3": 90.0}),
        (BoucWen(), "el_centro", {"c": 0.36, "k": 10.0, "beta": 0.7, "gamma": 1.5, "n": 1.7}),
    ],
)
def test_refinement_recovers_truth_noise_free(system, record, start):
    scale = 3.0 if system.name == "bouc_wen" else 1.0
    r = synthetic(system, record, duration=15.0, eq_scale=scale)
    res = refine(system, r, {"guess": start}, RefineSettings(states="measured"))
    truth = system.true_values()
    for k, v in res.params.items():
        assert abs(v - truth[k]) / truth[k] < 1e-4, (k, v, res.params)
    assert res.converged
    assert res.max_defect < 1e-8


def test_continuity_holds_at_convergence():
    """At the solution the segments are one trajectory: each segment equals the free run."""
    s = Duffing()
    r = synthetic(s, "kobe", duration=8.0, noise=0.03, data_seed=2)
    res = refine(s, r, {"guess": {"c": 0.55, "k1": 14.0, "k3": 110.0}}, RefineSettings(states="measured"))
    assert res.max_defect < 1e-8
    prob = _problem(s, r, 1.0)
    from pidyn.params import to_theta

    theta = to_theta(prob.specs, res.params)
    Y_free, _ = prob.free_run(theta, np.array(res.initial_state))
    u = prob.pack(res.params, Y_free[prob.bounds[:-1]])
    _, c = prob.residuals(u)
    assert np.max(np.abs(c)) < 1e-8
    # and without continuity (segments restarted from the measured state) the defects are visible
    u_meas = prob.pack(res.params, initial_states(prob, theta, "measured"))
    assert np.max(np.abs(prob.residuals(u_meas)[1])) > 1e-4


def test_covariance_matches_finite_difference_hessian():
    """Gauss-Newton covariance (continuity eliminated) against the inverse of a finite-difference
    Hessian of the single-shooting cost over (theta, y0) at the same solution."""
    s = LinearSDOF()
    r = synthetic(s, "kobe", duration=6.0, noise=0.05, data_seed=4)
    res = refine(
        s,
        r,
        {"guess": {"c": 0.45, "k": 16.0}},
        RefineSettings(states="measured", reweight=False, initial_state="free"),
    )
    single = ShootingProblem(s, r.t, r.f, record_channels(r, 1), segment_bounds(r.t, None), 4)
    for ch in single.channels:
        ch.sigma = res.noise_std[ch.name]
    from pidyn.params import to_theta

    u = np.concatenate([to_theta(single.specs, res.params), np.array(res.initial_state) / single.state_scale])

    def cost(v):
        rr, _ = single.residuals(v)
        return 0.5 * float(rr @ rr)

    n = u.size
    H = np.zeros((n, n))
    h = 1e-4
    for i in range(n):
        for j in range(n):
            ei, ej = np.eye(n)[i] * h, np.eye(n)[j] * h
            H[i, j] = (cost(u + ei + ej) - cost(u + ei - ej) - cost(u - ei + ej) + cost(u - ei - ej)) / (
                4 * h * h
            )
    cov_fd = np.linalg.inv(H)[:2, :2]
    _, J, _, C = single.linearize(u)
    cov_gn, _ = covariance(single, J, C)
    np.testing.assert_allclose(cov_gn, cov_fd, rtol=0.05)
    # the multiple-shooting covariance (null space of the continuity) is the same matrix
    sd = np.sqrt(np.diag(cov_gn))
    ints = res.intervals
    for i, name in enumerate(["c", "k"]):
        rel = (ints[name]["ci95"][1] - ints[name]["ci95"][0]) / 2 / 1.96 / res.params[name]
        assert abs(rel / sd[i] - 1) < 0.05, (name, rel, sd[i])


@pytest.mark.slow
def test_interval_coverage_over_seeds():
    """Noisy Duffing (5 %, Kobe 0-20 s), 8 noise draws: the 95 % intervals cover the truth in
    most draws, and their width follows the Cramer-Rao bound."""
    s = Duffing()
    truth = {k: v for k, v in s.true_values().items() if k != "m"}  # the mass is known
    covered, ratios, crb = 0, [], None
    for seed in range(8):
        r = synthetic(s, "kobe", duration=20.0, noise=0.05, data_seed=100 + seed)
        res = refine(s, r, {"guess": {"c": 0.55, "k1": 14.0, "k3": 105.0}}, RefineSettings(states="measured"))
        for n in truth:
            lo, hi = res.intervals[n]["ci95"]
            covered += lo <= truth[n] <= hi
        if crb is None:  # the bound depends on the excitation and the noise level, not on the draw
            crb = cramer_rao(s, s.true_values(), r.t, r.f, 0.05)["std_pct"]
        ratios += [res.intervals[n]["rel_std_pct"] / crb[n] for n in truth]
    assert covered >= 20, covered  # of 24 (95 % expects 22.8)
    assert 0.7 < np.median(ratios) < 1.4, ratios


def _cut(record, t0: float, t1: float):
    """The record from its largest displacement within [t0, t1] on, its clock restarted: a
    structure already moving at its start."""
    from dataclasses import replace

    i0, i1 = np.searchsorted(record.t, [t0, t1])
    i = int(i0 + np.argmax(np.abs(record.clean.x[i0:i1, 0])))
    return replace(
        record, t=record.t[i:] - record.t[i], f=record.f[i:], x=record.x[i:], v=record.v[i:], clean=None
    )


def test_initial_state_is_held_at_rest_only_when_the_data_allow_it():
    """auto: a record that starts at rest keeps its initial state at rest (likelihood-ratio
    test passed, narrower intervals than with the state free); the same structure cut in
    mid-motion is rejected as at rest, its state estimated, and the estimate stays right."""
    s = Duffing()
    truth = {k: v for k, v in s.true_values().items() if k != "m"}
    r = synthetic(s, "kobe", duration=12.0, noise=0.02, data_seed=7)
    guess = {"c": 0.55, "k1": 14.0, "k3": 110.0}
    auto = refine(s, r, {"guess": guess}, RefineSettings(states="measured"))
    assert auto.initial_state_mode == "rest" and auto.rest_test["at_rest"], auto.rest_test
    assert auto.initial_state == [0.0] * s.n_state
    free = refine(s, r, {"guess": guess}, RefineSettings(states="measured", initial_state="free"))
    assert free.initial_state_mode == "free" and not free.rest_test
    for n in truth:
        assert auto.intervals[n]["std"] <= free.intervals[n]["std"] * 1.0001, n
    moving = _cut(r, 4.0, 8.0)
    assert abs(moving.x[0, 0]) > 5 * 0.02 * np.std(moving.x)  # plainly not at rest
    cut = refine(s, moving, {"guess": guess}, RefineSettings(states="measured"))
    assert cut.initial_state_mode == "free" and not cut.rest_test["at_rest"], cut.rest_test
    assert "not_at_rest" in codes(cut.notes), cut.notes
    for n, v in truth.items():
        lo, hi = cut.intervals[n]["ci95"]
        assert lo - 2 * (hi - lo) < v < hi + 2 * (hi - lo), (n, v, lo, hi)


def test_cramer_rao_with_an_unknown_start_is_wider_on_a_hysteretic_system():
    """The latent z remembers its start: freeing the initial state costs Bouc-Wen's beta,
    gamma and n much of their information, a linear system almost none."""
    bw = BoucWen()
    r = synthetic(bw, "el_centro", duration=20.0)
    crb = cramer_rao(bw, bw.true_values(), r.t, r.f, 0.025)
    for n in crb["names"]:
        assert crb["std_pct_unknown_start"][n] >= crb["std_pct"][n] * 0.9999, n
    assert crb["std_pct_unknown_start"]["beta"] > 1.5 * crb["std_pct"]["beta"], crb
    lin = LinearSDOF()
    r = synthetic(lin, "kobe", duration=10.0)
    crb = cramer_rao(lin, lin.true_values(), r.t, r.f, 0.025)
    assert crb["std_pct_unknown_start"]["k"] < 1.2 * crb["std_pct"]["k"], crb


def test_cramer_rao_is_the_shooting_information():
    """The bound from exact sensitivities agrees with the interval a refinement reports at the truth."""
    s = LinearSDOF()
    r = synthetic(s, "kobe", duration=10.0, noise=0.02, data_seed=5)
    crb = cramer_rao(s, s.true_values(), r.t, r.f, 0.02)
    assert all(0 < v < 5 for v in crb["std_pct"].values())
    assert abs(np.array(crb["correlation"])[0, 1]) < 1


@pytest.mark.slow
def test_a_start_where_single_shooting_fails_and_multiple_shooting_succeeds(tmp_path):
    """Start 1 of the basin study (experiments/results/basin_duffing.md): Duffing under the
    default Kobe record, the guess set in the config as a user sets it (c at 0.35x, k1 at 1.5x,
    k3 at 2.5x the truth). Output error from rest (single shooting) ends far away; the
    multiple-shooting refinement from the same start, its segment states from the measured
    x and x', finds the truth."""
    import hydra
    from helpers import make_cfg

    from pidyn.baselines import output_error
    from pidyn.runs.build import build_record

    start = {"c": 0.17283039480124285, "k1": 23.1578766613333, "k3": 297.2009298706063}
    cfg = make_cfg([f"system.params.{k}.init={v!r}" for k, v in start.items()] + ["logger=none"], tmp_path)
    system = hydra.utils.instantiate(cfg.system)
    r = build_record(cfg, system)
    truth = system.true_values()
    oe = output_error(
        r, system, init=start, max_nfev=20
    )  # in its basin's end by then (60 give the same 3 digits)
    assert max(abs(oe.params[k] - truth[k]) / truth[k] for k in start) > 0.1, oe.params
    res = refine(system, r, {"start": start}, RefineSettings(states="measured"))
    assert max(abs(res.params[k] - truth[k]) / truth[k] for k in start) < 1e-4, res.params


def test_a_noise_free_record_at_rest_is_held_at_rest_despite_correlated_residuals():
    """Without noise the residual is the integrator's smooth error, not white noise: the
    uncorrected likelihood-ratio drop exceeds the chi-square threshold, the drop corrected for
    the residuals' correlation does not, and a record that starts at rest is held there."""
    bw = BoucWen()
    r = synthetic(bw, "el_centro", eq_scale=3.0, duration=20.0)
    truth = {k: v for k, v in bw.true_values().items() if k != "m"}
    guess = {k: v * (1.05 if i % 2 else 0.95) for i, (k, v) in enumerate(truth.items())}
    res = refine(bw, r, {"guess": guess}, RefineSettings(states="measured"))
    test = res.rest_test
    assert test["residual_lag1_correlation"] > 0.9
    assert test["misfit_drop"] * test["inflation"] > test["threshold"]  # what the white-noise test would say
    assert res.initial_state_mode == "rest" and test["at_rest"], test
    for n, v in truth.items():
        assert res.params[n] == pytest.approx(v, rel=1e-4), n


def test_a_start_whose_simulation_blows_up_is_said_so():
    """A start whose free simulation diverges (a stiffness far beyond what the RK4 step can
    integrate) is no start: the stage says so instead of refining silently, and a start that
    simulates is preferred to it."""
    system = LinearSDOF()
    r = synthetic(system, "el_centro", duration=4.0)
    quick = RefineSettings(
        states="measured", segment_length=2.0, max_nfev=3, gn_steps=2, reweight=False, initial_state="free"
    )
    blown = {"c": 0.5, "k": 1e9}
    res = refine(system, r, {"pidynnet": blown}, quick)
    assert "starts_diverge" in codes(res.notes), res.notes
    good = {"c": 0.6, "k": 14.0}
    res = refine(system, r, {"pidynnet": blown, "output_error": good}, quick)
    assert res.start == "output_error"
    assert "starts_diverge" not in codes(res.notes), res.notes


def test_the_sandwich_gives_the_spread_of_an_estimate_under_correlated_residuals():
    """A slope fitted to a smooth regressor under AR(1) noise (rho 0.9), 400 draws: the inverse
    information understates the estimate's spread about fourfold; the sandwich over the plug-in
    lags gives it within 25 %. Under white noise the plug-in takes no lags."""
    from pidyn.refine.uncertainty import bandwidth, sandwich

    rng = np.random.default_rng(3)
    n, rho = 600, 0.9
    x = np.sin(2 * np.pi * np.arange(n) / 150.0)[:, None]
    slopes, white, hac = [], [], []
    for _ in range(400):
        e = np.zeros(n)
        w = rng.standard_normal(n)
        for i in range(1, n):
            e[i] = rho * e[i - 1] + w[i]
        y = 2.0 * x[:, 0] + e
        a = float(x[:, 0] @ y / (x[:, 0] @ x[:, 0]))
        r = y - a * x[:, 0]
        info = float(x[:, 0] @ x[:, 0])
        slopes.append(a)
        white.append(np.sqrt(float(r @ r) / (n - 1) / info))
        lag1 = float(r[1:] @ r[:-1] / (r @ r))
        B = sandwich(x, r, [slice(0, n)], bandwidth(lag1, n))
        hac.append(np.sqrt(float(B[0, 0]) / info**2))
    spread = float(np.std(slopes))
    assert np.median(white) < 0.4 * spread
    assert abs(np.median(hac) / spread - 1) < 0.25, (np.median(hac), spread)
    assert bandwidth(0.02, n) == 0 and bandwidth(0.9, n) > 10


def test_a_long_output_error_fit_says_how_far_it_has_come(monkeypatch, caplog):
    """A fit that runs past the progress interval logs its evaluations, cost and seconds (a
    learned force's model can take minutes on a long record); a fit within it logs nothing."""
    import logging

    from pidyn.refine import output_error

    s = LinearSDOF()
    r = synthetic(s, "kobe", duration=6.0, noise=0.02, data_seed=4)
    start = {"c": 0.5, "k": 20.0}
    with caplog.at_level(logging.INFO, logger="pidyn.refine.output_error"):
        output_error.fit_output_error(r, s, init=start, max_nfev=5)
    assert not [m for m in caplog.messages if "evaluations, cost" in m]
    monkeypatch.setattr(output_error, "PROGRESS_EVERY_S", 0.0)
    with caplog.at_level(logging.INFO, logger="pidyn.refine.output_error"):
        fit = output_error.fit_output_error(r, s, init=start, max_nfev=5)
    lines = [m for m in caplog.messages if "evaluations, cost" in m]
    assert len(lines) == fit.nfev and lines[0].startswith("output error of linear_sdof: 1 evaluations")


def test_a_preferred_start_that_blows_up_lends_no_states_to_the_others():
    """The preferred start (PIDynNet's) blows up when simulated; the segments' states and their
    scale come from the start that does not, and the refinement ends at the truth. Before, the
    diverging start's states gave the scale inf, and the refinement from the good start ended on a
    model that blows up (the stiff shake-table building's Sine 1.5 run)."""
    from pidyn.refine.setup import build_problem
    from pidyn.refine.stage import _Starts

    system = LinearSDOF()
    r = synthetic(system, "kobe", duration=10.0, channels=("x", "v"))
    truth = system.true_values()
    unstable = {**truth, "k": 2e6}  # RK4 at dt/4 grows about 4 times a substep: huge, finite states
    starts = {"pidynnet": unstable, "data": dict(truth)}
    prob = build_problem(system, r, RefineSettings())
    chosen = _Starts(prob, RefineSettings(), starts, None, "pidynnet")
    assert chosen.first == "data" and np.all(np.isfinite(prob.state_scale))
    res = refine(system, r, starts, RefineSettings(states="networks"))
    assert res.start == "data"
    for k, v in res.params.items():
        assert abs(v - truth[k]) / truth[k] < 1e-4, (k, v)


def test_a_long_record_gets_longer_segments_not_thousands():
    from pidyn.refine.setup import MAX_SEGMENTS, build_problem

    system = LinearSDOF()
    r = synthetic(system, "kobe", duration=40.0, dt=0.01, channels=("x", "v"))
    prob = build_problem(system, r, RefineSettings(segment_length=0.1))
    assert prob.S <= MAX_SEGMENTS + 1
    assert build_problem(system, r, RefineSettings(segment_length=1.0)).S == 40


def test_a_parameter_run_to_infinity_is_named_not_a_linear_algebra_complaint():
    from pidyn.refine.setup import build_problem
    from pidyn.refine.stage import RefinementDiverged, _uncertainty

    system = LinearSDOF()
    r = synthetic(system, "kobe", duration=5.0, channels=("x", "v"))
    prob = build_problem(system, r, RefineSettings(segment_length=None, initial_state="rest"))
    u = prob.pack(system.true_values(), np.zeros((prob.S, prob.ns)))
    res, J, c, C = prob.linearize(u)
    theta = u[: prob.n_theta].copy()
    theta[prob.names.index("k")] = 1e6  # exp overflows: k = inf
    with pytest.raises(RefinementDiverged, match="ran k to infinity"):
        _uncertainty(prob, res, J, C, theta)
