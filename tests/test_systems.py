import numpy as np
import pytest
import torch

from pidyn.excitation import prepare
from pidyn.params import ParamSpec, PhysicalParameters, from_raw, to_raw
from pidyn.simulate import add_noise, simulate
from pidyn.systems import BoucWen, Duffing, LinearSDOF, ShearBuilding
from pidyn.systems.base import Kinematics

torch.set_default_dtype(torch.float64)


def residuals_of(system, gm, params=None):
    p = params or system.true_values()
    tr = simulate(system, p, gm, gm.t)
    T = lambda a: torch.tensor(a, dtype=torch.float64)  # noqa: E731
    zd = None
    if tr.z is not None:
        zd = np.array(
            [
                system.rhs(t, np.r_[tr.x[i], tr.v[i], tr.z[i]], p, lambda _: 0.0)[2 * system.n_dof :]
                for i, t in enumerate(tr.t)
            ]
        )
    k = Kinematics(
        T(tr.t), T(tr.x), T(tr.v), T(tr.a), None if tr.z is None else T(tr.z), None if zd is None else T(zd)
    )
    res = system.residual(k, T(tr.f), {n: torch.tensor(v, dtype=torch.float64) for n, v in p.items()})
    scale = np.abs(tr.f).max() * max(p.get("m", 1.0), 1.0)
    return {n: float(r.abs().max()) / scale for n, r in res.items()}, tr


@pytest.mark.parametrize(
    "system",
    [LinearSDOF(), Duffing(), BoucWen(), ShearBuilding(), Duffing(mass=2.5), BoucWen(mass=3.0)],
    ids=["linear", "duffing", "bouc_wen", "shear3", "duffing_m2.5", "bouc_wen_m3"],
)
def test_residual_vanishes_on_simulated_trajectory(system):
    gm = prepare("el_centro", duration=6.0, dt=0.01)
    res, tr = residuals_of(system, gm)
    assert np.abs(tr.x).max() > 1e-4  # the structure moved
    for name, r in res.items():
        assert r < 1e-9, (name, r)


def test_residual_detects_wrong_parameters():
    gm = prepare("el_centro", duration=6.0, dt=0.01)
    s = Duffing()
    tr = simulate(s, s.true_values(), gm, gm.t)
    T = lambda a: torch.tensor(a)  # noqa: E731
    k = Kinematics(T(tr.t), T(tr.x), T(tr.v), T(tr.a))
    wrong = {n: torch.tensor(v) for n, v in s.true_values().items()} | {"k3": torch.tensor(150.0)}
    assert float(s.residual(k, T(tr.f), wrong)["motion"].abs().max()) > 1e-3


def test_linear_sdof_matches_closed_form_free_vibration():
    m, c, k, x0 = 1.0, 0.5, 15.0, 0.1
    s = LinearSDOF(c=c, k=k)
    t = np.linspace(0, 10, 1001)
    tr = simulate(
        s, s.true_values(), lambda tt: np.zeros_like(np.asarray(tt, float)), t, y0=np.array([x0, 0.0])
    )
    wn = np.sqrt(k / m)
    zeta = c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta**2)
    exact = x0 * np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))
    assert np.max(np.abs(tr.x[:, 0] - exact)) < 1e-8


def test_linear_sdof_matches_duhamel_under_ramp_force():
    # m x'' + c x' + k x = -m a0 t: particular solution + homogeneous part, closed form
    c, k, a0 = 0.5, 15.0, 0.3
    s = LinearSDOF(c=c, k=k)
    t = np.linspace(0, 8, 801)
    tr = simulate(s, s.true_values(), lambda tt: a0 * np.asarray(tt, float), t)
    A, B = -a0 / k, a0 * c / k**2  # x_p = A t + B
    wn, zeta = np.sqrt(k), c / (2 * np.sqrt(k))
    wd = wn * np.sqrt(1 - zeta**2)
    C1 = -B
    C2 = (-A + zeta * wn * C1) / wd
    exact = A * t + B + np.exp(-zeta * wn * t) * (C1 * np.cos(wd * t) + C2 * np.sin(wd * t))
    assert np.max(np.abs(tr.x[:, 0] - exact)) < 1e-9


def test_bouc_wen_m_not_one_needs_mass_on_the_right():
    """With m != 1 the paper's literal '-ag' right-hand side leaves a residual; ours does not."""
    gm = prepare("el_centro", duration=6.0, dt=0.01)
    res, _ = residuals_of(BoucWen(mass=3.0), gm)
    assert res["motion"] < 1e-9


def test_noise_level_and_seed():
    ch = {"x": np.sin(np.linspace(0, 50, 20000))[:, None]}
    a = add_noise(ch, 0.05, seed=1)["x"]
    b = add_noise(ch, 0.05, seed=1)["x"]
    c = add_noise(ch, 0.05, seed=2)["x"]
    rms = np.sqrt(np.mean(ch["x"] ** 2))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.std(a - ch["x"]) == pytest.approx(0.05 * rms, rel=0.03)


def test_param_transforms_round_trip_and_bounds():
    for spec, v in [
        (ParamSpec("k", 15.0, scale=15.0), 120.0),
        (ParamSpec("n", 2.0, transform="box", lower=0.5, upper=6.0), 4.2),
        (ParamSpec("g", 2.0, transform="identity", scale=2.0), -3.0),
    ]:
        assert float(from_raw(spec, torch.tensor(to_raw(spec, v), dtype=torch.float64))) == pytest.approx(
            v, rel=1e-9
        )
    p = PhysicalParameters([ParamSpec("n", 2.0, transform="box", lower=0.5, upper=6.0), ParamSpec("c", 0.5)])
    p.set_values({"n": 100.0, "c": -1.0})
    v = p.as_floats()
    assert 0.5 < v["n"] <= 6.0 and v["c"] > 0


def test_config_typos_in_parameter_overrides_fail():
    with pytest.raises(ValueError, match="unknown parameter"):
        Duffing(params={"k4": {"init": 1.0}})
    with pytest.raises(ValueError, match="unknown field"):
        Duffing(params={"k3": {"intit": 1.0}})
    with pytest.raises(ValueError, match="cannot be identified under ground excitation"):
        Duffing(identify_mass=True)


def test_least_squares_standard_errors_see_a_weak_column():
    """A cubic term in a window of small motion: x^3 is 1e-4 of x. Its standard error must
    come out large (the window does not determine k3), not dropped by a float32 inverse."""
    import torch

    from pidyn.systems import Duffing
    from pidyn.systems.base import Kinematics
    from pidyn.systems.lstsq import solve_linear_params

    system = Duffing()
    t = torch.linspace(0, 3, 1000)
    x = 0.03 * torch.sin(4 * t)
    v = 0.12 * torch.cos(4 * t)
    a = -0.48 * torch.sin(4 * t)
    g = torch.Generator().manual_seed(0)
    f = -(a + 0.3 * v + 25 * x + 400 * x**3) + 0.05 * torch.randn(
        1000, generator=g
    )  # ag from the motion, noisy
    k = Kinematics(t=t[:, None], x=x[:, None], v=v[:, None], a=a[:, None])
    std: dict = {}
    est = solve_linear_params(
        system,
        k,
        f,
        {"m": torch.tensor(1.0), "c": torch.tensor(0.5), "k1": torch.tensor(15.0), "k3": torch.tensor(120.0)},
        ["c", "k1", "k3"],
        std=std,
    )
    assert abs(est["k1"] - 25) < 1.0
    assert std["k3"] > 0.5 * abs(est["k3"]) and std["k3"] > 100, (est, std)


def test_the_least_squares_start_does_not_depend_on_where_its_matrix_lies_in_memory():
    """The same problem gives the same bits wherever its matrix is allocated (torch's default
    driver did not: the same run's estimates changed from run to run)."""
    from pidyn.systems.lstsq import lstsq

    gen = torch.Generator().manual_seed(0)
    J = torch.randn(1500, 3, generator=gen) * torch.tensor([1.0, 10.0, 1e3])
    b = torch.randn(1500, generator=gen)
    ref = lstsq(J, b)
    for offset in range(1, 32):
        moved = torch.empty(J.numel() + offset)[offset:].view(J.shape)
        moved.copy_(J)
        assert torch.equal(lstsq(moved, b), ref), offset
