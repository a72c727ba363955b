"""The period's profile-likelihood interval: the sandwich's Wald interval where the cost is
quadratic and the residuals white, wider where the residuals are a smooth error, and written to
``modal.json`` by the refinement."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import lfilter

from pidyn.assessment import modal_summary
from pidyn.data.sources import synthetic
from pidyn.refine import RefineSettings, refine
from pidyn.refine.period_profile import CHI2_95, _connected_set, profile_period
from pidyn.systems import Duffing, LinearSDOF, ShearBuilding

K, C = 400.0, 2.0
PERIOD = 2 * np.pi / np.sqrt(K)


def _record(seed: int, rho: float = 0.0, hz: float = 0.0, level: float = 0.1, duration: float = 12.0):
    """Accelerations of a 0.314 s oscillator plus noise of ``level`` times their spread: white,
    or through an AR(2) resonance at ``hz`` of pole radius ``rho`` (a smooth, oscillating error
    such as a model's own, correlated over several periods)."""
    clean = synthetic(LinearSDOF(c=C, k=K), "el_centro", channels=("a",), duration=duration, dt=0.02)
    e = np.random.default_rng(seed).standard_normal(len(clean.t))
    if rho:
        w = 2 * np.pi * hz * clean.dt
        e = lfilter([1.0], [1.0, -2 * rho * np.cos(w), rho**2], e)
    e *= level * np.std(clean.a) / np.std(e)
    return replace(clean, a=clean.a + e[:, None], truth=None, clean=None)


def test_with_white_noise_the_set_is_the_wald_interval():
    """White noise: no adjustment, the set about the truth, as wide as the refinement's Wald
    interval of the period to 15 %."""
    rec = _record(0)
    system = LinearSDOF(c=C, k=K)
    prof = profile_period(system, rec, {"m": 1.0, "c": C, "k": K})
    assert prof.adjustment == 1.0 and prof.lags == 0 and not prof.disjoint
    lo, hi = prof.ci95
    assert lo < PERIOD < hi and lo < prof.period_min < hi
    res = refine(system, rec, {"truth": {"m": 1.0, "c": C, "k": K}}, RefineSettings(initial_state="rest"))
    assert res.period_profile["ci95"] == pytest.approx([lo, hi], rel=1e-9)
    wald = modal_summary(system, {"m": 1.0, **res.params}, res)[0]
    assert wald["period_profile_ci95"] == res.period_profile["ci95"]
    w_lo, w_hi = wald["period_ci95"]
    assert (hi - lo) == pytest.approx(w_hi - w_lo, rel=0.15)


@pytest.mark.slow
def test_a_smooth_error_widens_the_set_and_keeps_its_coverage():
    """Noise through a 3 Hz resonance (pole radius 0.97): over 40 records the plain likelihood
    ratio's set holds the true period on 12, the adjusted one on 32 (fixed seeds; 80 %: the
    Newey-West sandwich over a few hundred samples still understates a resonant error's spread)."""
    system = LinearSDOF(c=C, k=K)
    adjusted = plain = 0
    for seed in range(40):
        prof = profile_period(system, _record(seed, 0.97, 3.0), {"m": 1.0, "c": C, "k": K})
        assert prof.adjustment < 0.5 and prof.lags > 10
        lo, hi = prof.ci95
        adjusted += (lo or 0.0) <= PERIOD <= (hi or np.inf)
        stat = np.array([np.inf if s is None else s for s in prof.statistic]) / prof.adjustment
        p_lo, p_hi, _ = _connected_set(np.array(prof.periods), stat, prof.period_min)
        plain += (p_lo or 0.0) <= PERIOD <= (p_hi or np.inf)
    assert adjusted >= 30 and plain <= 20, (adjusted, plain)


def test_the_set_follows_the_cost_where_it_is_not_quadratic():
    """A statistic flat on one side: the set runs to the grid's end there (None) and is closed
    on the other; a second dip below the threshold is said to be another part of the set."""
    periods = np.linspace(0.1, 0.3, 21)
    stat = np.where(periods < 0.2, 40.0 * (periods - 0.2) ** 2 / 0.01**2, 0.5)
    lo, hi, disjoint = _connected_set(periods, stat, 0.2)
    assert hi is None and lo == pytest.approx(0.2 - 0.01 * np.sqrt(CHI2_95 / 40), abs=0.004) and not disjoint
    stat[1] = 0.0
    assert _connected_set(periods, stat, 0.2)[2]


def test_only_one_linear_mode_has_a_profile():
    rec = synthetic(Duffing(), "el_centro", duration=5.0, dt=0.02, channels=("a",))
    assert profile_period(Duffing(), rec, Duffing().true_values()) is None
    building = ShearBuilding(3)
    rec = synthetic(building, "el_centro", duration=5.0, dt=0.02, channels=("a",))
    assert profile_period(building, rec, building.true_values()) is None
