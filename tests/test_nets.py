import torch

from pidyn.nets import TaylorMLP


def test_taylor_mode_matches_autograd():
    torch.manual_seed(0)
    net = TaylorMLP(out_features=2, n_fourier=4).double()
    net.set_window(3.0, 6.0)
    net.set_output_scale(
        torch.tensor([0.3, 2.0], dtype=torch.float64), torch.tensor([0.1, -0.2], dtype=torch.float64)
    )
    t = torch.linspace(3.0, 6.0, 37, dtype=torch.float64, requires_grad=True)
    y, dy, ddy = net.taylor(t)
    for j in range(2):
        g = torch.autograd.grad(y[:, j].sum(), t, create_graph=True)[0]
        gg = torch.autograd.grad(g.sum(), t, retain_graph=True)[0]
        assert torch.allclose(g, dy[:, j], atol=1e-12)
        assert torch.allclose(gg, ddy[:, j], atol=1e-10)


def test_excitation_input_gives_partial_derivative_only():
    torch.manual_seed(0)
    net = TaylorMLP(use_excitation_input=True).double()
    t = torch.linspace(0, 1, 11, dtype=torch.float64)
    f1, f2 = torch.zeros_like(t), torch.ones_like(t)
    # with ag as an input the 'derivative' ignores d ag/dt: change f, d/dt stays a partial
    assert not torch.allclose(net.taylor(t, f=f1)[1], net.taylor(t, f=f2)[1])
