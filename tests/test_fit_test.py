"""The fit test: the noise floor read above the structural band, and when a fitting part fails."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.discrepancy.fit_test import fit_test, noise_floor

DT, N = 0.02, 1000  # 20 s at 50 Hz, as the building benchmark's records


def structural(rng: np.random.Generator, f_hz: float = 1.0) -> np.ndarray:
    """A response in the structural band: two damped-looking sinusoids with drifting phase."""
    t = np.arange(N) * DT
    return np.sin(2 * np.pi * f_hz * t + 0.3 * np.sin(0.2 * t)) + 0.5 * np.sin(
        2 * np.pi * 2.6 * f_hz * t + 1.0
    )


@pytest.mark.parametrize("sd", [0.01, 0.3])
def test_the_noise_floor_of_white_noise_under_a_structural_error_is_its_level(sd):
    rng = np.random.default_rng(1)
    residual = 0.5 * structural(rng) + rng.normal(0.0, sd, N)  # a model error below the band, and noise
    floor = noise_floor(residual, DT, f_top=3.0)
    assert floor.method == "spectrum" and floor.band_hz == pytest.approx((7.5, 20.0))
    assert floor.sd == pytest.approx(sd, rel=0.15)


def test_without_a_band_above_the_modes_the_second_difference_bounds_the_noise():
    rng = np.random.default_rng(2)
    residual = 0.2 * structural(rng, 0.5) + rng.normal(0.0, 0.05, N)
    floor = noise_floor(residual, DT, f_top=12.0)  # 2.5 x 12 Hz lies above the Nyquist frequency
    assert floor.method == "second_difference" and floor.band_hz is None
    assert 0.05 <= floor.sd <= 0.06


def run_test(error: float, noise: float, seed: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    clean = structural(rng)
    measured = clean + rng.normal(0.0, noise * np.std(clean), N)
    simulated = clean * (1.0 + error)  # a model off by ``error`` of the signal in the structural band
    return fit_test({"a1": measured}, {"a1": simulated}, {"a1": float(np.std(measured))}, DT, 3.0, 2.0, 0.02)


def test_a_model_off_far_beyond_the_noise_fails_and_a_correct_one_passes():
    wrong = run_test(error=0.15, noise=0.02)
    assert wrong["failed"] and wrong["failed_channels"] == ["a1"], wrong
    assert wrong["channels"]["a1"]["noise"] == pytest.approx(0.02, rel=0.2)
    assert wrong["channels"]["a1"]["excess"] == pytest.approx(0.15, rel=0.1)
    right = run_test(error=0.0, noise=0.05)
    assert not right["failed"] and right["channels"]["a1"]["ratio"] < 1.3, right


def test_a_noise_free_record_is_not_failed_for_a_negligible_error():
    """Without noise any error is many times the floor; the excess guard keeps a part in ten
    thousand from failing, and a real error still fails."""
    tiny = run_test(error=1e-4, noise=0.0)
    assert tiny["channels"]["a1"]["ratio"] > 2.0 and not tiny["failed"], tiny
    assert run_test(error=0.05, noise=0.0)["failed"]


def test_a_blown_up_simulation_fails():
    out = fit_test({"a1": np.ones(N)}, {"a1": np.full(N, np.inf)}, {"a1": 1.0}, DT, 3.0, 2.0, 0.02)
    assert out["failed"] and out["channels"]["a1"]["nrmse"] == float("inf")
