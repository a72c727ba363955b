import numpy as np
import pytest

from pidyn.baselines import cramer_rao, equation_error, output_error, simulate_batch, unscented_kalman_filter
from pidyn.data.sources import synthetic
from pidyn.systems import BoucWen, Duffing

START = {"c": {"init": 1.0}, "k1": {"init": 10.0}, "k3": {"init": 50.0}}


@pytest.fixture(scope="module")
def duffing_record():
    s = Duffing(params=START)
    return s, synthetic(s, "kobe", duration=14.0, dt=0.01)


def errors(res, truth):
    return {k: 100 * abs(v - truth[k]) / truth[k] for k, v in res.params.items()}


def test_fast_simulator_matches_solve_ivp():
    for s, rec in [(Duffing(), "kobe"), (BoucWen(), "el_centro")]:
        r = synthetic(s, rec, duration=10.0, dt=0.01)
        out = simulate_batch(
            s, {k: np.array([v, v]) for k, v in s.true_values().items()}, r.t, r.f, substeps=4
        )
        assert np.abs(out["x"][:, 1] - r.x[:, 0]).max() < 1e-5 * np.abs(r.x).max()
        if s.n_latent:
            assert np.abs(out["z"][:, 1, 0] - r.clean.z[:, 0]).max() < 1e-5 * np.abs(r.clean.z).max()


def test_equation_error_exact_on_clean_data(duffing_record):
    s, rec = duffing_record
    assert max(errors(equation_error(rec, s), s.true_values()).values()) < 1.0
    assert equation_error(rec, BoucWen()).params == {}  # latent state: not applicable


def test_output_error_recovers_duffing(duffing_record):
    s, rec = duffing_record
    res = output_error(rec, s, substeps=2)
    assert max(errors(res, s.true_values()).values()) < 0.05


def test_ukf_converges_on_duffing(duffing_record):
    s, rec = duffing_record
    res = unscented_kalman_filter(rec, s, q_param=1e-5)
    assert max(errors(res, s.true_values()).values()) < 1.0
    assert len(res.trajectory) > 10 and res.trajectory[0]["k3"] != res.trajectory[-1]["k3"]


def test_cramer_rao_scales_with_noise_and_ranks_bouc_wen_parameters():
    s = Duffing()
    r = synthetic(s, "kobe", duration=14.0, dt=0.01)
    b1 = cramer_rao(s, s.true_values(), r.t, r.f, 0.01)
    b5 = cramer_rao(s, s.true_values(), r.t, r.f, 0.05)
    for k in b1["std_pct"]:
        assert b5["std_pct"][k] == pytest.approx(5 * b1["std_pct"][k], rel=1e-6)
    bw = BoucWen()
    rb = synthetic(bw, "el_centro", duration=20.0, dt=0.01)
    cb = cramer_rao(bw, bw.true_values(), rb.t, rb.f, 0.05)["std_pct"]
    assert cb["beta"] > 10 * cb["k"] and cb["gamma"] > 10 * cb["k"]  # beta, gamma poorly determined
    corr = np.array(cramer_rao(bw, bw.true_values(), rb.t, rb.f, 0.05)["correlation"])
    assert np.allclose(np.diag(corr), 1.0)


def test_weak_sindy_selects_the_duffing_terms_under_noise():
    from pidyn.baselines import weak_sindy

    s = Duffing()
    rec = synthetic(s, "kobe", duration=40.0, dt=0.01, noise=0.05, data_seed=1)
    res = weak_sindy(rec, s)
    assert max(errors(res, s.true_values()).values()) < 1.0
    assert res.note.startswith("selected: x=") and "outside the model" not in res.note
    assert weak_sindy(rec, BoucWen()).params == {}  # latent state: not applicable


def test_ukf_tuned_by_innovation_likelihood_beats_a_loose_random_walk():
    """On noisy Duffing the likelihood picks a small parameter random walk, and the tuned filter
    is several times more accurate than the loose 1e-5 (no truth used in the choice)."""
    s = Duffing(params=START)
    r = synthetic(s, "kobe", duration=30.0, noise=0.05, data_seed=1)
    loose = unscented_kalman_filter(r, s, noise_level=0.05, q_param=1e-5)
    tuned = unscented_kalman_filter(r, s, noise_level=0.05, tune=[1e-9, 1e-7, 1e-5])
    assert "q_param=1e-09" in tuned.note and tuned.loglik > loose.loglik
    assert max(errors(tuned, s.true_values()).values()) < 0.5 * max(errors(loose, s.true_values()).values())


def test_cramer_rao_matches_relative_finite_difference_sensitivities():
    """The bound from the shooting problem's exact Jacobian (log and logit coordinates mapped to
    relative ones) equals one built from central differences in ln(value), box parameters included."""
    bw = BoucWen()
    truth = bw.true_values()
    r = synthetic(bw, "el_centro", duration=10.0, dt=0.01, eq_scale=3.0)
    got = cramer_rao(bw, truth, r.t, r.f, 0.03)["std_pct"]
    names = list(got)
    h = 1e-5
    batch = {k: np.full(2 * len(names) + 1, v) for k, v in truth.items()}
    for i, k in enumerate(names):
        batch[k][1 + 2 * i] *= 1 + h
        batch[k][2 + 2 * i] *= 1 - h
    out = simulate_batch(bw, batch, r.t, r.f, substeps=4)
    F = np.zeros((len(names), len(names)))
    for c in ("x", "v"):
        y = out[c]
        sigma = 0.03 * np.sqrt(np.mean(y[:, 0] ** 2))
        S = np.stack([(y[:, 1 + 2 * i] - y[:, 2 + 2 * i]) / (2 * h) for i in range(len(names))], axis=1)
        F += S.T @ S / sigma**2
    expect = 100 * np.sqrt(np.diag(np.linalg.inv(F)))
    for i, k in enumerate(names):
        assert got[k] == pytest.approx(expect[i], rel=0.02), (k, got, expect)


def test_a_realization_is_simulated_as_its_recursion():
    """The peers' realizations (SRIM, OKID-ERA) are run by scipy.signal.dlsim: the recursion
    y_k = C x_k + D u_k, x_k+1 = A x_k + B u_k from rest, for several inputs and outputs."""
    from pidyn.baselines.peers import simulate_realization

    rng = np.random.default_rng(0)
    A = rng.normal(size=(4, 4))
    A /= 1.1 * np.max(np.abs(np.linalg.eigvals(A)))
    B, C, D, U = (
        rng.normal(size=(4, 3)),
        rng.normal(size=(2, 4)),
        rng.normal(size=(2, 3)),
        rng.normal(size=(3, 200)),
    )
    x, expected = np.zeros(4), np.empty((2, 200))
    for k in range(200):
        expected[:, k] = C @ x + D @ U[:, k]
        x = A @ x + B @ U[:, k]
    assert np.allclose(simulate_realization(A, B, C, D, U), expected, rtol=1e-12, atol=1e-12)
    assert np.abs(simulate_realization(3.0 * A, B, C, D, U)).max() > 1e50  # unstable: it grows without bound
