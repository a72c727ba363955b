"""The latent least-squares start: beta, gamma, n by variable projection on a given motion,
for an SDOF Bouc-Wen and a hysteretic storey of a shear building; and that one short window
does not pass for determined."""

import numpy as np
import pytest
import torch

from pidyn.data.sources import synthetic
from pidyn.models.latent_start import LatentStart, integrate_latent, join_motions, latent_shape_params
from pidyn.params import PhysicalParameters
from pidyn.systems import BoucWen, Duffing, ShearBuilding


def _start(system, clean, start_values, z0=True):
    """The problem on the noise-free motion ``clean`` (a Trajectory)."""
    params = PhysicalParameters(system.param_specs())
    params.set_values(start_values)
    T = torch.from_numpy
    return LatentStart(
        system,
        params,
        T(clean.t),
        T(clean.x),
        T(clean.v),
        T(clean.f),
        np.zeros(system.n_latent) if z0 else None,
    )


def test_latent_path_matches_the_simulation():
    s = BoucWen()
    r = synthetic(s, "el_centro", duration=6.0)
    c = r.clean
    z, _ = integrate_latent(s, c.t, c.x, c.v, np.zeros((1, 1)), s.true_values())
    np.testing.assert_allclose(z[0, :, 0], c.z[:, 0], atol=2e-3 * np.abs(c.z).max())


@pytest.mark.slow
def test_bouc_wen_shape_recovered_from_a_far_start():
    """From beta, gamma, n at half, half and 0.75 of the truth (PIDynNet's usual start), the
    motion of 10 s of El Centro gives them back; c and k come with them."""
    s = BoucWen()
    r = synthetic(s, "el_centro", duration=10.0)
    prob = _start(s, r.clean, {"beta": 0.5, "gamma": 1.0, "n": 1.5, "c": 0.5, "k": 10.0})
    out = prob.solve()
    truth = s.true_values()
    for n in ("c", "k", "beta", "gamma", "n"):
        assert abs(out["params"][n] / truth[n] - 1) < 0.03, (n, out["params"][n])
    assert out["cost"] < 1e-3 * out["cost_start"]
    assert out["std"]["beta"] < 0.1
    assert out["at_edge"] == []


@pytest.mark.slow
def test_unknown_initial_latent_state_is_estimated():
    """Cut in mid-motion, z0 is an unknown of the problem and comes out right."""
    s = BoucWen()
    c = synthetic(s, "el_centro", duration=8.0).clean
    i0 = 300  # 3 s in
    cut = type(c)(t=c.t[i0:], x=c.x[i0:], v=c.v[i0:], a=c.a[i0:], f=c.f[i0:], z=c.z[i0:])
    prob = _start(s, cut, {"beta": 0.7, "gamma": 1.5, "n": 1.7}, z0=False)
    out = prob.solve()
    for n in ("beta", "gamma", "n"):
        assert abs(out["params"][n] / s.true_values()[n] - 1) < 0.05, (n, out["params"][n])
    assert abs(out["z"][0, 0] - c.z[i0, 0]) < 0.05 * np.abs(c.z).max()


def _hysteretic_building() -> ShearBuilding:
    return ShearBuilding(
        n_storeys=3,
        storey_terms={
            1: [{"term": "hysteresis", "beta": 20.0, "gamma": 40.0, "n": 2.0, "shape_scale": 20.0}]
        },
    )


def test_a_hysteretic_storeys_shape_parameters_are_the_latent_starts_unknowns():
    assert latent_shape_params(_hysteretic_building()) == ["beta1", "gamma1", "n1"]


@pytest.mark.second_proof  # the latent solve is proven by test_bouc_wen_shape_recovered_from_a_far_start
def test_shear_building_hysteretic_storey():
    s = _hysteretic_building()
    r = synthetic(s, "el_centro", eq_scale=3.0, duration=6.0)
    truth = s.true_values()
    prob = _start(s, r.clean, {"beta1": 10.0, "gamma1": 25.0, "n1": 1.6})
    out = prob.solve()
    for n in ("beta1", "gamma1", "n1"):
        assert abs(out["params"][n] / truth[n] - 1) < 0.05, (n, out["params"][n])


def test_no_latent_state_no_problem():
    assert latent_shape_params(Duffing()) == []


def test_motions_join_without_repeating_an_edge():
    a = {
        "t": torch.tensor([0.0, 1.0, 2.0]),
        "x": torch.zeros(3, 1),
        "v": torch.zeros(3, 1),
        "f": torch.zeros(3),
    }
    b = {"t": torch.tensor([2.0, 3.0]), "x": torch.ones(2, 1), "v": torch.ones(2, 1), "f": torch.ones(2)}
    m = join_motions([a, b])
    assert m["t"].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert m["x"][2, 0] == 1.0  # the later window's value at the shared edge
