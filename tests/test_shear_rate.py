"""The shear building's state rate on floor vectors equals the term-by-term one, for every kind of
input the integrator and the refinement pass: one plain state, a batch, dual arrays (states and
parameters), parameters that vary by trajectory, and the final call over the whole grid."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.autodiff import Dual
from pidyn.discrepancy.effects import EFFECTS
from pidyn.systems.shear_building import ShearBuilding

LOSS = {"term": "stiffness_loss", "drop": 0.25, "t_d": 8.0, "stiffness": "k1", "t_max": 40.0}


def buildings() -> dict[str, ShearBuilding]:
    hysteresis = EFFECTS["hysteresis"].term(
        {"kh": 20.0, "beta": 1.0, "gamma": 2.0, "n": 1.0}, {"stiffness": "k2"}
    )
    masses = [1.0, 1.2, 0.8]
    return {
        "linear": ShearBuilding(3, masses, 0.5, [200.0, 160.0, 120.0]),
        "gap": ShearBuilding(3, masses, 0.5, 200.0, storey_terms={2: [{"term": "gap_contact", "kg": 150.0}]}),
        "two_terms": ShearBuilding(
            3, masses, 0.5, 200.0, storey_terms={1: [LOSS, {"term": "cubic_stiffness", "k3": 4e4}]}
        ),
        "hysteresis_replaces": ShearBuilding(4, 1.0, 0.5, 200.0, storey_terms={1: [{"term": "hysteresis"}]}),
        "hysteresis_adds": ShearBuilding(
            3, 1.0, 0.5, 200.0, storey_terms={2: [hysteresis], 3: [{"term": "hysteresis"}]}
        ),
        "masses_unknown": ShearBuilding(3, "unknown", 0.5, 200.0),
    }


def inputs(b: ShearBuilding, kind: str, rng: np.random.Generator):
    ns, n_b, n_d = 2 * b.n_dof + b.n_latent, 7, 5
    p = {s.name: s.init for s in b.param_specs()}
    if kind == "one_state":
        return 9.0, 0.02 * rng.normal(size=ns), p, 0.3
    y = 0.02 * rng.normal(size=(n_b, ns))
    t, f = 9.0 + rng.random(n_b), rng.normal(size=n_b)
    if kind in ("dual", "dual_params"):
        y = Dual(y, rng.normal(size=(n_b, ns, n_d)))
    if kind == "dual_params":
        p = {k: Dual(np.array(v), rng.normal(size=n_d)) if i % 2 else v for i, (k, v) in enumerate(p.items())}
    if kind == "per_trajectory":
        p = {k: v * (1 + 0.1 * rng.random(n_b)) if i % 2 else v for i, (k, v) in enumerate(p.items())}
    if kind == "grid":
        y = Dual(0.02 * rng.normal(size=(11, n_b, ns)), rng.normal(size=(11, n_b, ns, n_d)))
        t, f = rng.random((11, n_b)), rng.normal(size=(11, n_b))
    return t, y, p, f


@pytest.mark.parametrize("name", list(buildings()))
@pytest.mark.parametrize("kind", ["one_state", "batch", "dual", "dual_params", "per_trajectory", "grid"])
def test_the_vector_rate_is_the_term_rate(name, kind):
    b = buildings()[name]
    t, y, p, f = inputs(b, kind, np.random.default_rng(0))
    fast, slow = b.state_rate(t, y, p, f), b._state_rate_by_term(t, y, p, f)
    assert type(fast) is type(slow)
    fv, sv = (fast.v, slow.v) if isinstance(fast, Dual) else (fast, slow)
    assert fv.shape == sv.shape and np.allclose(fv, sv, rtol=1e-12, atol=1e-12)
    if isinstance(fast, Dual):
        assert np.allclose(fast.d, slow.d, rtol=1e-12, atol=1e-12)


def test_new_parameter_values_are_not_served_from_the_store():
    """The parameter vectors are kept while the integrator passes the same values; a new value
    (the next iterate) must reach the rate."""
    b = buildings()["linear"]
    t, y, p, f = inputs(b, "batch", np.random.default_rng(1))
    first = b.state_rate(t, y, p, f)
    p["k2"] = 2.0 * p["k2"]
    again = b.state_rate(t, y, p, f)
    assert not np.allclose(first, again) and np.allclose(again, b._state_rate_by_term(t, y, p, f))


@pytest.mark.parametrize("name", list(buildings()))
def test_torch_tensors_take_the_vector_rate_with_their_gradients(name):
    """A learned force trained through the simulation passes torch states and parameters: the same
    rate as term by term, and the same gradient."""
    import torch

    b = buildings()[name]
    t, y, p, f = inputs(b, "per_trajectory", np.random.default_rng(2))
    p = {k: float(np.mean(v)) for k, v in p.items()}

    def rates(fn):
        pt = {k: torch.tensor(v, dtype=torch.float64, requires_grad=True) for k, v in p.items()}
        yt, ft = torch.tensor(y, requires_grad=True), torch.tensor(f)
        out = fn(torch.tensor(t), yt, pt, ft)
        out.pow(2).sum().backward()
        return out.detach().numpy(), yt.grad.numpy(), {k: float(v.grad) for k, v in pt.items()}

    (fast, gy, gp), (slow, sy, sp) = rates(b.state_rate), rates(b._state_rate_by_term)
    assert np.allclose(fast, slow, rtol=1e-12, atol=1e-12) and np.allclose(gy, sy, rtol=1e-10, atol=1e-12)
    assert all(np.isclose(gp[k], sp[k], rtol=1e-10, atol=1e-12) for k in gp)
