"""The shake-table reach study's measures (``experiments/shake_table_reach.py``), on signals whose
answers are known."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))

import shake_table_reach as reach  # noqa: E402


def _signals(n=6000, step=1 / 120, seed=0):
    rng = np.random.default_rng(seed)
    table = rng.normal(size=n)
    fir = np.exp(-np.arange(40) / 8.0) * np.cos(2 * np.pi * 5.0 * np.arange(40) * step)
    return table, np.convolve(table, fir)[:n], step


def test_own_linear_recovers_a_filtered_floor_and_fails_on_noise():
    table, floor, _ = _signals()
    noise = np.random.default_rng(1).normal(size=len(table))
    fit, none = reach.own_linear(table, np.stack([floor, noise], axis=1), taps=60, fit_share=0.65)
    assert fit < 0.05 and none > 0.95


def test_the_gain_matched_floor_is_zero_for_the_same_system_and_not_for_another():
    table, floor, step = _signals()
    h_f, h = reach.gain(table, floor, step, nperseg=512)
    other, floor2, _ = _signals(seed=2)
    assert reach.gain_matched_floor(h_f, h, other, floor2, step) < 0.15
    assert reach.gain_matched_floor(h_f, 3 * h, other, floor2, step) > 1.5  # three times the gain


def test_share_above_reads_where_the_energy_is():
    t = np.arange(12000) / 120
    low, high = np.sin(2 * np.pi * 3 * t), 2 * np.sin(2 * np.pi * 40 * t)
    share = reach.share_above(low + high, 1 / 120, 30.0)
    assert abs(share - 2 / np.sqrt(5)) < 0.01
