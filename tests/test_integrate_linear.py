"""The one-sample map of a linear time-invariant system is its RK4 scheme, sensitivities included."""

import numpy as np
import pytest

from pidyn import integrate, integrate_linear
from pidyn.autodiff import Dual
from pidyn.systems import Duffing, LinearSDOF, ShearBuilding
from pidyn.systems.modes import ModesOnSupports
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.terms import StiffnessLoss


def _supports() -> SDOFSystem:
    return SDOFSystem(LinearSDOF().terms, inputs=["a", "b", "c"])


SYSTEMS = {
    "sdof": lambda: LinearSDOF(c=0.5, k=15.0),
    "three supports": _supports,
    "building": lambda: ShearBuilding(3),
    "modes": lambda: ModesOnSupports(2, inputs=["a", "b"]),
}


def _values(system) -> dict:
    p = {s.name: float(s.init) for s in system.param_specs()}
    for name in p:  # the supports' dashpots and feedthroughs off zero, so their terms count
        if name[:2] in ("g_", "e_") or (name[0] == "g" and "_" in name):
            p[name] = 0.2
    return p


def _dual(p: dict, names: list[str], y0: np.ndarray) -> tuple[dict, Dual]:
    """Parameters ``names`` and every initial state as directions."""
    n_dir = len(names) + y0.shape[1]
    out = dict(p)
    for i, name in enumerate(names):
        v = np.asarray(p[name], float)
        out[name] = Dual(v, np.broadcast_to(np.eye(n_dir)[i], v.shape + (n_dir,)).copy())
    d = np.zeros(y0.shape + (n_dir,))
    for j in range(y0.shape[1]):
        d[:, j, len(names) + j] = 1.0
    return out, Dual(y0, d)


def _both(monkeypatch, system, p, t, f, y0):
    monkeypatch.setenv(
        "PIDYN_COMPILED", "0"
    )  # the map where no C compiler is found, against the loop in Python
    fast = integrate.rk4(system, p, t, f, y0)
    monkeypatch.setattr(integrate_linear, "applies", lambda *a, **k: False)
    slow = integrate.rk4(system, p, t, f, y0)
    monkeypatch.undo()
    return fast, slow


@pytest.mark.parametrize("name", list(SYSTEMS))
@pytest.mark.parametrize("per_trajectory", [False, True])
def test_the_linear_map_is_the_rk4_scheme_with_its_sensitivities(monkeypatch, name, per_trajectory):
    system = SYSTEMS[name]()
    assert system.linear_time_invariant
    rng = np.random.default_rng(3)
    n, batch, w = system.n_state, 3, system.excitation_width
    t = np.arange(400) * 0.01
    shape = (len(t),) + ((batch,) if per_trajectory else ()) + ((w,) if w > 1 else ())
    f = rng.standard_normal(shape)
    p = _values(system)
    p, y0 = _dual(p, list(p)[1:6], 0.01 * rng.standard_normal((batch, n)))
    (y_fast, r_fast), (y_slow, r_slow) = _both(monkeypatch, system, p, t, f, y0)
    assert integrate_linear.applies(system, p, t, y0)
    scale = np.abs(y_slow.v).max()
    assert np.abs(y_fast.v - y_slow.v).max() < 1e-11 * scale
    assert np.abs(y_fast.d - y_slow.d).max() < 1e-11 * np.abs(y_slow.d).max()
    assert np.abs(r_fast.v - r_slow.v).max() < 1e-11 * np.abs(r_slow.v).max()


def test_plain_values_and_a_plain_start_give_plain_states(monkeypatch):
    system = _supports()
    t = np.arange(300) * 0.02
    f = np.random.default_rng(1).standard_normal((len(t), system.excitation_width))
    (y_fast, _), (y_slow, _) = _both(monkeypatch, system, _values(system), t, f, np.zeros((1, 2)))
    assert type(y_fast) is np.ndarray
    assert np.abs(y_fast - y_slow).max() < 1e-11 * np.abs(y_slow).max()


def test_directions_of_the_start_alone_give_its_sensitivities(monkeypatch):
    system = _supports()
    t = np.arange(300) * 0.01
    f = np.random.default_rng(2).standard_normal((len(t), system.excitation_width))
    y0 = Dual(np.zeros((1, 2)), np.eye(2)[None])  # plain parameters, the initial state as directions
    (y_fast, _), (y_slow, _) = _both(monkeypatch, system, _values(system), t, f, y0)
    assert np.abs(y_fast.d - y_slow.d).max() < 1e-11 * np.abs(y_slow.d).max()


@pytest.mark.parametrize("name", ["three supports", "building"])
def test_one_parameter_set_per_trajectory_as_a_finite_difference_jacobian_simulates_them(monkeypatch, name):
    system = SYSTEMS[name]()
    rng = np.random.default_rng(5)
    batch, w = 4, system.excitation_width
    t = np.arange(300) * 0.01
    f = rng.standard_normal((len(t), w) if w > 1 else len(t))
    base = _values(system)
    p = {k: v * (1 + 0.1 * rng.standard_normal(batch)) for k, v in base.items()}  # one set per trajectory
    p[next(iter(p))] = base[next(iter(p))]  # and one parameter shared
    y0 = 0.01 * rng.standard_normal((batch, system.n_state))
    assert integrate_linear.applies(system, p, t, y0)
    (y_fast, _), (y_slow, _) = _both(monkeypatch, system, p, t, f, y0)
    assert np.abs(y_fast - y_slow).max() < 1e-11 * np.abs(y_slow).max()
    dual, y0d = _dual(p, list(p)[1:4], y0)
    (y_fast, _), (y_slow, _) = _both(monkeypatch, system, dual, t, f, y0d)
    assert np.abs(y_fast.d - y_slow.d).max() < 1e-11 * np.abs(y_slow.d).max()


def test_what_the_map_does_not_stand_for_takes_the_general_scheme():
    t = np.arange(50) * 0.01
    y0 = np.zeros((1, 2))
    linear = LinearSDOF()
    p = _values(linear)
    assert integrate_linear.applies(linear, p, t, y0)
    assert not integrate_linear.applies(Duffing(), _values(Duffing()), t, y0)  # nonlinear
    loss = linear.with_term(StiffnessLoss(t_d=0.2, t_min=0.0, t_max=0.5, tau=0.05))
    assert not loss.linear_time_invariant  # a change in time
    two = {**p, "k": np.array([15.0, 16.0])}  # two values of k for one state
    assert not integrate_linear.applies(linear, two, t, y0)
    uneven = t.copy()
    uneven[10] += 0.002
    assert not integrate_linear.applies(linear, p, uneven, y0)
