"""Fusion of window estimates: the Gaussian product where it interpolates, never an extrapolation."""

import pytest
import torch

from pidyn.models.fusion import InformationFusion


def test_well_conditioned_windows_fuse_to_the_gaussian_product():
    f = InformationFusion()
    J1, J2 = torch.diag(torch.tensor([4.0, 1.0])), torch.diag(torch.tensor([1.0, 3.0]))
    t1, t2 = torch.tensor([1.0, 2.0]), torch.tensor([2.0, 1.0])
    f.add(t1, J1)
    out = f.add(t2, J2)
    expect = torch.linalg.solve(J1 + J2, J1 @ t1 + J2 @ t2)
    assert torch.allclose(out, expect, atol=1e-6) and not f.fallback


def test_ill_conditioned_windows_never_fuse_outside_their_estimates():
    """Two windows that each pin only a combination of (beta, gamma), differently oriented,
    with nearly equal beta: the plain product puts beta far outside both (as seen on Bouc-Wen)."""
    f = InformationFusion()
    a, b = torch.tensor([1.0, 1.0]), torch.tensor([1.0, 1.2])
    J1 = 1e4 * torch.outer(a, a) + 1e-2 * torch.eye(2)
    J2 = 1e4 * torch.outer(b, b) + 1e-2 * torch.eye(2)
    t1, t2 = torch.tensor([0.513, 1.0]), torch.tensor([0.543, 0.7])
    f.add(t1, J1)
    out = f.add(t2, J2)
    plain = torch.linalg.solve(J1 + J2, J1 @ t1 + J2 @ t2)
    assert not (0.50 <= float(plain[0]) <= 0.56)  # the product extrapolates ...
    assert f.fallback
    for i in range(2):  # ... the fusion does not
        lo, hi = min(t1[i], t2[i]), max(t1[i], t2[i])
        assert lo - 1e-9 <= float(out[i]) <= hi + 1e-9, out


def test_fusion_state_round_trip():
    f = InformationFusion()
    f.add(torch.tensor([1.0]), torch.eye(1))
    g = InformationFusion()
    g.load_state_dict(f.state_dict())
    assert torch.allclose(g.add(torch.tensor([3.0]), torch.eye(1)), torch.tensor([2.0]))


def test_a_parameter_no_window_informs_keeps_the_windows_estimate():
    """A damage time before the damage: its rows and columns of J are exactly zero (float32).
    The fused value must stay at the windows' estimates, finite, not fall to raw zero."""
    f = InformationFusion()
    J1 = torch.tensor([[4.0, 0.0], [0.0, 0.0]])
    J2 = torch.tensor([[1.0, 0.0], [0.0, 0.0]])
    f.add(torch.tensor([1.0, 0.8]), J1)
    out = f.add(torch.tensor([1.2, 0.8]), J2)
    assert torch.isfinite(out).all()
    assert float(out[1]) == pytest.approx(0.8, rel=1e-5)
    assert float(out[0]) == pytest.approx((4 * 1.0 + 1 * 1.2) / 5, rel=1e-5)
    # the same when the convex fallback is taken (windows far apart in the informed parameter)
    g = InformationFusion()
    a = torch.tensor([1.0, 1.0, 0.0])
    g.add(
        torch.tensor([0.5, 1.0, 0.3]), 1e4 * torch.outer(a, a) + torch.diag(torch.tensor([1e-2, 1e-2, 0.0]))
    )
    b = torch.tensor([1.0, 1.2, 0.0])
    out = g.add(
        torch.tensor([0.55, 0.7, 0.3]), 1e4 * torch.outer(b, b) + torch.diag(torch.tensor([1e-2, 1e-2, 0.0]))
    )
    assert g.fallback and torch.isfinite(out).all()
    assert float(out[2]) == pytest.approx(0.3, rel=1e-5)


@pytest.mark.parametrize("seed", range(5))
def test_float32_information_spanning_nine_decades_fuses_finite_and_inside_the_windows(seed):
    """A 5-storey building's window information (13 parameters) spans eight decades and more,
    in float32: its inverse had negative and zero diagonals, and the marginal weights gave NaN
    (n1 = nan, then a crash in the next window's least squares)."""
    g = torch.Generator().manual_seed(seed)
    f = InformationFusion()
    n, thetas = 13, []
    for w in range(3):
        V, _ = torch.linalg.qr(torch.randn(n, n, generator=g, dtype=torch.float64))
        J = ((V * torch.logspace(-1, 8, n, dtype=torch.float64)) @ V.T).float()
        thetas.append(torch.randn(n, generator=g) * (1 + w))
        out = f.add(thetas[-1], J)
    T = torch.stack(thetas)
    assert out.dtype == torch.float32 and torch.isfinite(out).all()
    if f.fallback:
        assert ((out >= T.min(0).values - 1e-5) & (out <= T.max(0).values + 1e-5)).all()
