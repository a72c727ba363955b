"""Residuals whose scale follows the response's envelope: the test that says so, the weighted
output error, and the diagnosis's supports' fit that uses them only where the residuals ask."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pidyn.discrepancy.heteroscedastic import envelope, scale_test
from pidyn.refine.output_error import fit_output_error


def _two_supports(noise_follows: bool, seed: int = 0):
    """A 0.31 s oscillator on two supports (El Centro and 0.6 Kobe); its absolute acceleration with
    noise of 5 % of its spread, either one level or following the response's envelope."""
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.excitation.ground_motion import SupportMotions, prepare
    from pidyn.systems import LinearSDOF

    gm = SupportMotions.from_motions(
        {
            "a": prepare("el_centro", dt=0.02, duration=20.0),
            "b": prepare("kobe", dt=0.02, duration=20.0, scale=0.6),
        }
    )
    system = LinearSDOF(
        c=0.8, k=400.0, inputs=["a", "b"], params={"r_a": {"true": 0.7}, "r_b": {"true": 0.3}}
    )
    rec = synthetic_from_motion(system, gm, noise=0.0, channels=["a"])
    a = rec.a[:, 0]
    e = np.random.default_rng(seed).standard_normal(len(a))
    scale = envelope(a, rec.dt, 1.25) if noise_follows else np.ones_like(a)
    noisy = a + 0.05 * np.std(a) * e * scale / np.sqrt(np.mean(scale**2))
    return replace(rec, a=noisy[:, None], truth=None, clean=None), system


def test_the_test_tells_a_scale_that_follows_the_envelope_from_one_level():
    rng = np.random.default_rng(1)
    t = np.arange(3000) * 0.02
    w = envelope(np.sin(2 * np.pi * 3 * t) * np.exp(-(((t - 15) / 6) ** 2)), 0.02, 1.0)
    assert np.exp(np.mean(np.log(w))) == pytest.approx(1.0)
    white = rng.standard_normal(len(t))
    assert not scale_test(white, w, 1.0).follows and scale_test(white, w, 1.0).statistic < 0
    follows = scale_test(white * w, w, 1.0)
    assert follows.follows and follows.statistic > 100
    smooth = np.convolve(white * w, np.ones(25) / 25, mode="same")  # correlated: fewer independent samples
    assert scale_test(smooth, w, 1.0).independent_samples < 0.2 * len(t)


def test_weights_scale_the_cost_and_leave_an_unweighted_optimum_where_they_are_even():
    rec, system = _two_supports(False)
    init = {"c": 0.8, "k": 400.0, "r_a": 0.7, "r_b": 0.3}
    plain = fit_output_error(rec, system, init, max_nfev=30)
    even = fit_output_error(rec, system, init, max_nfev=30, weights=np.full(len(rec.t), 2.0))
    assert even.cost == pytest.approx(4.0 * plain.cost, rel=1e-6)
    for k in init:
        assert even.params[k] == pytest.approx(plain.params[k], rel=1e-6)
    with pytest.raises(ValueError, match="10 weights for a record of 1001 samples"):
        fit_output_error(rec, system, init, weights=np.ones(10))


@pytest.mark.parametrize("follows", [False, True])
def test_the_supports_fit_is_redone_only_where_the_residuals_ask(follows):
    """Noise of one level: the supports' fit is kept as least squares made it; noise that follows
    the envelope: the test says so and the fit is redone under it, near the truth."""
    from pidyn.discrepancy.accelerometers import _envelope_refit

    rec, system = _two_supports(follows)
    truth = {"m": 1.0, "c": 0.8, "k": 400.0, "r_a": 0.7, "r_b": 0.3}
    start = {**{s.name: float(s.init) for s in system.param_specs()}, **truth}
    fitted = {**start, **fit_output_error(rec, system, truth, max_nfev=30).params}
    values, test = _envelope_refit(rec, system, fitted, 1e-8)
    assert test.follows is follows
    if not follows:
        assert values == fitted
        return
    assert values != fitted
    for k in ("k", "r_a", "r_b"):
        assert values[k] == pytest.approx(truth[k], rel=0.02), k
    # the refit is the likelihood's: each residual divided by the envelope, its cost lower than the plain fit's
    w = envelope(rec.a, rec.dt, test.window_s)
    assert _cost(rec, system, values, 1.0 / w) < _cost(rec, system, fitted, 1.0 / w)
    assert _cost(rec, system, values, np.ones_like(w)) > _cost(rec, system, fitted, np.ones_like(w))


def _cost(rec, system, values: dict[str, float], weights: np.ndarray) -> float:
    from pidyn.refine.output_error import output_error_problem

    problem, theta = output_error_problem(rec, system, {k: values[k] for k in ("c", "k", "r_a", "r_b")}, 4)
    r = problem.fd_fun_and_jac()[0](theta) * weights
    return float(r @ r)
