"""Modes as the model responds: the undamped modes where the damping is classical, the
state-space eigenvalues where it is not (``pidyn.systems.modal.modal_properties``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import freqresp

from pidyn.systems.modal import modal_properties

M = np.diag([1.0, 0.76, 1.28])
K = np.array([[13336 + 9398, -9398, 0], [-9398, 9398 + 26916, -26916], [0, -26916, 26916]], float)


def _peak_hz(c: np.ndarray, lo: float, hi: float) -> float:
    """Where floor 3's response to a ground acceleration peaks between lo and hi Hz."""
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-Minv @ K, -Minv @ c]])
    B = np.concatenate([np.zeros(3), -np.ones(3)])[:, None]
    Cx = np.zeros((1, 6))
    Cx[0, 2] = 1.0
    f = np.linspace(lo, hi, 20001)
    _, h = freqresp((A, B, Cx, np.zeros((1, 1))), 2 * np.pi * f)
    return float(f[np.argmax(np.abs(h))])


def test_classical_damping_keeps_the_undamped_modes_and_their_modal_damping():
    c = 0.002 * K + 0.5 * M  # Rayleigh: classical
    out = modal_properties(M, c, K)
    w2, _ = np.linalg.eig(np.linalg.solve(M, K))
    assert np.allclose(sorted(np.sqrt(w2.real) / 2 / np.pi), out["frequency_hz"], rtol=1e-12)
    w = 2 * np.pi * np.array(out["frequency_hz"])
    assert np.allclose(out["damping_ratio"], 0.002 * w / 2 + 0.5 / (2 * w), rtol=1e-9)


def test_a_storey_dashpot_overdamped_on_its_own_is_read_from_the_poles_where_the_model_responds():
    c = np.array([[0, 0, 0], [0, 661.55, -661.55], [0, -661.55, 661.55]], float)  # storey 3 only
    out = modal_properties(M, c, K)
    f1, f2, f3 = out["frequency_hz"]
    z1, z2, z3 = out["damping_ratio"]
    assert f1 == pytest.approx(_peak_hz(c, 5, 10), rel=0.005)  # 7.80 Hz; the undamped modes' 7.64
    assert f2 == pytest.approx(_peak_hz(c, 20, 30), rel=0.005)
    assert 0.01 < z1 < 0.03 and 0.005 < z2 < 0.015  # the projection said 4 % and 24 %
    assert z3 > 1  # two real rates: an overdamped mode, not a resonance
    assert all(abs(s[-1] - 1) < 1e-12 for s in out["mode_shapes"])
