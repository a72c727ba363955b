"""The compiled RK4 loop agrees with the Python one to round-off, for every system and term."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pidyn import cores, integrate
from pidyn.autodiff import Dual, value
from pidyn.compiled import build, kernel
from pidyn.compiled.tape import record
from pidyn.systems.deck import RigidDeck
from pidyn.systems.sdof import LinearSDOF, SDOFSystem
from pidyn.systems.shear_building import ShearBuilding
from pidyn.systems.terms import TERMS, AmplitudeSoftening, ForceTerm, LinearStiffness, ViscousDamping

pytestmark = pytest.mark.skipif(build.compiler() is None, reason="no C compiler")

N, DT = 400, 0.01


def _sdof(name: str) -> SDOFSystem:
    if name in ("stiffness_loss", "damping_change"):
        term = TERMS[name](t_d=2.0, t_max=4.0)
    elif name == "learned_force":  # a network with every weight set: a trained one
        term = TERMS[name](x_scale=0.05, v_scale=0.3, f_scale=0.5, hidden=8)
        gen = torch.Generator().manual_seed(0)
        for q in term.net.parameters():
            q.data = torch.randn(q.shape, generator=gen, dtype=q.dtype)
    else:
        term = TERMS[name]()
    return LinearSDOF(c=0.4, k=30.0).with_term(term)


class _Branching(ForceTerm):
    """A force that branches on a value in Python: no tape can follow it."""

    name = "branching"
    linear = ()

    def specs(self):
        return []

    def force(self, t, x, v, z, p):
        return 0.1 * x if float(np.max(np.abs(value(x)))) > 1.0 else 0.0 * x

    def formula(self, p):
        return "branching"


def _systems() -> dict[str, object]:
    out = {name: _sdof(name) for name in TERMS if name != "viscous_damping"}
    # the bounded amplitude law, a softening stiffness and a damping that falls: both branches
    bounded = AmplitudeSoftening(0.6, -0.4, 0.5, a_ref=0.5, w0=5.0, law="bounded")
    out["amplitude_bounded"] = LinearSDOF(c=0.4, k=30.0).with_term(bounded)
    # the curved law: a power whose exponent is a parameter, of an envelope that starts at 0
    curved = AmplitudeSoftening(0.6, 0.4, 0.5, a_ref=0.5, w0=5.0, law="curved", shape=1.7)
    out["amplitude_curved"] = LinearSDOF(c=0.4, k=30.0).with_term(curved)
    out["two_supports_sdof"] = SDOFSystem([ViscousDamping(0.4), LinearStiffness(30.0)], inputs=["a", "b"])
    out["building"] = ShearBuilding(
        n_storeys=3,
        storey_terms={1: {"term": "hysteresis", "beta": 0.5, "gamma": 0.5}, 2: {"term": "gap_contact"}},
    )
    out["deck"] = RigidDeck(
        ["a", "b", "c"],
        [0.0, 45.0, 80.0],
        80.0,
        support_terms={
            1: {"term": "amplitude_softening"},
            2: {"term": "hysteresis", "beta": 0.5, "gamma": 0.5},
        },
    )
    return out


SYSTEMS = _systems()


def _excitation(system, B: int, rng) -> np.ndarray:
    t = np.arange(N) * DT
    base = 2.0 * np.sin(2 * np.pi * 1.1 * t) + np.sin(2 * np.pi * 2.9 * t + 0.3)
    if system.n_inputs == 1:
        return base[:, None] * (1.0 + 0.2 * rng.standard_normal(B))[None, :]
    cols = [np.roll(base, 7 * j) * (1 + 0.1 * j) for j in range(system.n_inputs)]
    vel = [np.cumsum(c) * DT for c in cols]
    return np.stack(cols + vel, axis=-1)


def _params(system, B: int, rng) -> dict:
    p = {}
    for s in system.param_specs():
        v = float(s.true if s.true is not None else s.init)
        p[s.name] = v * (1.0 + 0.05 * rng.standard_normal(B)) if v else np.full(B, v)
    return p


def _both(system, p, f, y0, stages=None, t0=0.0):
    t = np.arange(N) * DT
    tt = np.asarray(t0) + t if np.ndim(t0) == 0 else np.asarray(t0)[None, :] + t[:, None]
    D = integrate._n_dir(p, y0)
    fast = kernel.steps(system, p, t, tt, f, stages, y0, 4, D)
    slow = integrate._steps(system, p, t, tt, f, stages, y0, 4, D)
    assert fast is not None, f"{system.name} was not compiled"
    return fast, slow


def _close(a, b, rtol=1e-11):
    scale = max(float(np.abs(b).max()), 1e-300)
    assert np.abs(a - b).max() <= rtol * scale, np.abs(a - b).max() / scale


@pytest.mark.parametrize("name", list(SYSTEMS))
def test_plain_batch_agrees(name):
    """Per-trajectory parameters, excitation and start times: the same states to round-off."""
    rng = np.random.default_rng(0)
    system = SYSTEMS[name]
    B = 3
    p = _params(system, B, rng)
    f = _excitation(system, B, rng)
    y0 = 0.01 * rng.standard_normal((B, system.n_state))
    (Yf, _), (Ys, _) = _both(system, p, f, y0, t0=np.array([0.0, 1.0, 2.5]))
    assert np.all(np.isfinite(Ys)) and np.abs(Ys).max() > 1e-4
    _close(Yf, Ys)


@pytest.mark.parametrize("name", list(SYSTEMS))
def test_sensitivities_agree(name):
    """Dual parameters and initial states: the same derivatives (the refinement's Jacobian)."""
    rng = np.random.default_rng(1)
    system = SYSTEMS[name]
    B = 2
    plain = _params(system, B, rng)
    names = list(plain)
    D = len(names) + system.n_state
    p = {n: Dual(v, np.broadcast_to(np.eye(D)[j], (B, D)).copy()) for j, (n, v) in enumerate(plain.items())}
    d0 = np.zeros((B, system.n_state, D))
    d0[:, np.arange(system.n_state), len(names) + np.arange(system.n_state)] = 1.0
    y0 = Dual(0.01 * rng.standard_normal((B, system.n_state)), d0)
    f = _excitation(system, 1, rng)
    f = f[:, 0] if system.n_inputs == 1 else f
    (Yf, dYf), (Ys, dYs) = _both(system, p, f, y0)
    _close(Yf, Ys)
    _close(dYf, dYs, rtol=1e-9)


@pytest.mark.parametrize("dual", [False, True])
def test_trajectories_split_over_threads_give_the_same_bits(dual, monkeypatch):
    """A batch split into ranges run in threads side by side is bitwise the batch run in one."""
    rng = np.random.default_rng(4)
    system = SYSTEMS["hysteresis"]
    B = 7
    plain = _params(system, B, rng)
    f = _excitation(system, B, rng)
    y0 = 0.01 * rng.standard_normal((B, system.n_state))
    p, D = plain, 0
    if dual:
        D = len(plain)
        p = {
            n: Dual(v, np.broadcast_to(np.eye(D)[j], (B, D)).copy()) for j, (n, v) in enumerate(plain.items())
        }
    t = np.arange(N) * DT
    monkeypatch.setattr(kernel, "MIN_SPLIT_WORK", 1)
    out = {}
    for n in (1, 3):
        monkeypatch.setenv("PIDYN_THREADS", str(n))
        calls = []
        real = kernel._in_threads
        monkeypatch.setattr(kernel, "_in_threads", lambda c, b, w: calls.append(b) or real(c, b, w))
        out[n] = kernel.steps(system, p, t, t, f, None, y0, 4, D)
        monkeypatch.setattr(kernel, "_in_threads", real)
        assert calls == [B]
    assert cores.threads() == 3
    for one, three in zip(out[1], out[3]):
        assert (one is None) == (three is None)
        if one is not None:
            assert np.array_equal(one, three)


def test_a_forked_child_starts_its_own_threads(monkeypatch):
    """A process pool's forked worker does not inherit the parent's threads (its tasks would wait
    for ever): it integrates with threads of its own, and gets the parent's bits."""
    import multiprocessing

    monkeypatch.setattr(kernel, "MIN_SPLIT_WORK", 1)
    monkeypatch.setenv("PIDYN_THREADS", "2")
    system = SYSTEMS["hysteresis"]
    rng = np.random.default_rng(5)
    p, f = _params(system, 4, rng), _excitation(system, 4, rng)
    y0, t = np.zeros((4, system.n_state)), np.arange(N) * DT
    here = kernel.steps(system, p, t, t, f, None, y0, 4, 0)[0]
    assert kernel._POOL is not None
    with multiprocessing.get_context("fork").Pool(1) as pool:
        there = pool.apply_async(kernel.steps, (system, p, t, t, f, None, y0, 4, 0)).get(timeout=60)[0]
    assert np.array_equal(here, there)


def test_threads_follow_the_environment(monkeypatch):
    """PIDYN_THREADS decides; else OMP_NUM_THREADS caps the cores (a test worker, a job of several)."""
    monkeypatch.delenv("PIDYN_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert cores.threads() == 1
    monkeypatch.setenv("PIDYN_THREADS", "2")
    assert cores.threads() == 2
    monkeypatch.delenv("PIDYN_THREADS")
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert cores.threads() == cores.cores()
    monkeypatch.setattr(cores, "cores", lambda: 4)
    cores.share_cores(2)  # two jobs side by side: two threads each
    assert cores.threads() == 2
    cores.share_cores(8)  # a value already set is kept
    assert cores.threads() == 2


def test_band_limited_stages_agree():
    """The excitation read at the stage times (a band-limited record) gives the same states."""
    rng = np.random.default_rng(2)
    system = SYSTEMS["hysteresis"]
    p = {k: v[0] for k, v in _params(system, 1, rng).items()}
    f = _excitation(system, 1, rng)[:, 0]
    stages = integrate.stage_excitation(f, 4, "bandlimited")
    (Yf, _), (Ys, _) = _both(system, p, f, np.zeros((1, system.n_state)), stages=stages)
    _close(Yf, Ys)


def test_rk4_uses_it_and_restarts_still_apply(monkeypatch):
    """``integrate.rk4`` gives the same answer with the compiled loop on and off, restarts included."""
    system = SYSTEMS["cubic_stiffness"]
    rng = np.random.default_rng(3)
    t = np.arange(N) * DT
    f = _excitation(system, 1, rng)[:, 0]
    p = system.true_values()
    on = integrate.rk4(system, p, t, f, np.zeros((1, 2)), restarts=[150])
    monkeypatch.setenv("PIDYN_COMPILED", "0")
    off = integrate.rk4(system, p, t, f, np.zeros((1, 2)), restarts=[150])
    _close(on[0], off[0])
    _close(on[1], off[1])


def test_a_fit_records_its_systems_tape_once_and_simulates_the_same_bits(monkeypatch):
    """``kernel.tapes_kept``: within a fit a system's state rate is recorded once per parameter
    list, and every simulation is what a fresh recording gives; outside the block, each call records."""
    system = SYSTEMS["cubic_stiffness"]
    rng = np.random.default_rng(4)
    t = np.arange(N) * DT
    f = _excitation(system, 1, rng)[:, 0]
    p = system.true_values()
    calls = []
    recorded = kernel._recorded
    monkeypatch.setattr(kernel, "_recorded", lambda *a: calls.append(a) or recorded(*a))
    fresh = [integrate.rk4(system, {**p, "k": k}, t, f, np.zeros((1, 2)))[0] for k in (25.0, 35.0)]
    assert len(calls) == 2
    with kernel.tapes_kept():
        kept = [integrate.rk4(system, {**p, "k": k}, t, f, np.zeros((1, 2)))[0] for k in (25.0, 35.0)]
        with kernel.tapes_kept():  # an inner block uses the outer one's
            integrate.rk4(system, p, t, f, np.zeros((1, 2)))
        other = SYSTEMS["linear_stiffness"]
        integrate.rk4(other, other.true_values(), t, f, np.zeros((1, 2)))
    assert len(calls) == 4  # the cubic system once, the linear one once
    assert all(np.array_equal(a, b) for a, b in zip(fresh, kept, strict=True))
    integrate.rk4(system, p, t, f, np.zeros((1, 2)))
    assert len(calls) == 5  # the block's tapes are gone with it


def test_untraceable_rates_fall_back():
    """A force that branches on a value in Python is not compiled, and the loop in Python runs it."""
    system = LinearSDOF().with_term(_Branching())
    with pytest.raises(TypeError):  # NotTraceable, or an operation on a traced scalar that it lacks
        record(system, [s.name for s in system.param_specs()], 1)
    t = np.arange(N) * DT
    p = system.true_values()
    assert kernel.steps(system, p, t, t, np.sin(t), None, np.zeros((1, 2)), 4, 0) is None
    Y, _ = integrate.rk4(system, p, t, np.sin(t), np.zeros((1, 2)))
    assert np.all(np.isfinite(Y))


def test_no_compiler_means_python(monkeypatch, tmp_path):
    """Without a C compiler the simulation still runs, in Python, with the same result."""
    monkeypatch.setenv("PIDYN_CACHE", str(tmp_path))
    monkeypatch.setattr(build, "compiler", lambda: None)
    monkeypatch.setattr(build, "_LOADED", {})
    monkeypatch.setattr(kernel, "_KERNELS", {})
    system = SYSTEMS["quadratic_damping"]
    t = np.arange(N) * DT
    assert kernel.steps(system, system.true_values(), t, t, np.sin(t), None, np.zeros((1, 2)), 4, 0) is None
    assert not list(tmp_path.rglob("*.so"))


@pytest.mark.parametrize("name", ["hysteresis", "deck", "building"])
def test_the_ground_truths_right_hand_side_is_the_same(name, monkeypatch):
    """LSODA's right-hand side, compiled, gives the ground truth the Python one gives (bitwise here)."""
    from pidyn.excitation import GroundMotion
    from pidyn.simulate import simulate

    system = SYSTEMS[name]
    rng = np.random.default_rng(4)
    p = {k: float(v[0]) for k, v in _params(system, 1, rng).items()}
    y = np.array([0.01 * (j + 1) for j in range(system.n_state)])
    rate = kernel.rate_function(system, p)
    f = np.linspace(0.3, 1.2, system.excitation_width) if system.n_inputs > 1 else 0.7
    assert np.allclose(rate(0.4, y, f), system.rhs(0.4, y, p, lambda t: f), rtol=1e-13, atol=1e-15)
    if system.n_inputs == 1:
        gm = GroundMotion("probe", DT, _excitation(system, 1, rng)[:300, 0])
        fast = simulate(system, p, gm, gm.t[:200], method="LSODA")
        monkeypatch.setenv("PIDYN_COMPILED", "0")
        slow = simulate(system, p, gm, gm.t[:200], method="LSODA")
        _close(fast.x, slow.x, rtol=1e-9)
        _close(fast.a, slow.a, rtol=1e-9)


@pytest.mark.parametrize(
    "name",
    [
        "hysteresis",
        "coulomb_friction",
        "gap_contact",
        "building",
        "deck",
    ],
)
def test_the_compiled_ground_truth_is_at_least_as_close_to_the_solution_as_lsoda(name):
    """The default ground truth (Dormand-Prince in C, ``pidyn.compiled.kernel.truth``) lands as
    close to a thousandfold-tighter LSODA reference as LSODA at the usual tolerance does, or closer
    (a kink at zero velocity and a friction's sign included), on an output grid off the samples too."""
    from pidyn.excitation.ground_motion import GroundMotion, SupportMotions
    from pidyn.simulate import _rate, simulate

    system = SYSTEMS[name]
    rng = np.random.default_rng(5)
    p = {k: float(v[0]) for k, v in _params(system, 1, rng).items()}
    if system.n_inputs > 1:  # each support's acceleration (the velocities are its integrals), 2 s
        gm = SupportMotions(
            "probe", DT, 3.0 * _excitation(system, 1, rng)[:200, : system.n_inputs], system.inputs
        )
    else:
        gm = GroundMotion("probe", DT, 3.0 * _excitation(system, 1, rng)[:, 0])
    for t in (gm.t, np.linspace(0.013, gm.t[-1] - 0.2, 97)):  # the samples, and times between them
        exact = simulate(system, p, gm, t, method="LSODA", rtol=1e-13, atol=1e-15)
        auto, lsoda = simulate(system, p, gm, t), simulate(system, p, gm, t, method="LSODA")
        scale = np.abs(exact.x).max()
        # no farther than LSODA, or within 5e-10 of the response (the reference's own error is near 1e-11)
        assert np.abs(auto.x - exact.x).max() <= max(np.abs(lsoda.x - exact.x).max(), 5e-10 * scale)
        # the accelerations come from C with the states: the state rate at them, to the bit
        rate = _rate(system, p, gm)
        y = np.hstack([auto.x, auto.v] + ([auto.z] if auto.z is not None else []))
        n = system.n_dof
        assert np.array_equal(auto.a, np.array([rate(ti, yi) for ti, yi in zip(t, y)])[:, n : 2 * n])


@pytest.mark.parametrize("along_x", [True, False])
def test_a_latent_path_in_c_is_the_one_in_python(along_x, monkeypatch):
    """The screening's latent states along a measured motion (``latent_path``: a grid of Bouc-Wen
    shapes at once, one amplitude-law memory) come from C with Python's operations in Python's
    order: the same to round-off, and bitwise for one parameter set."""
    from pidyn.systems.terms import AmplitudeSoftening, BoucWenHysteresis, latent_path

    t = np.arange(3000) * DT
    x = 0.3 * np.sin(2 * np.pi * 0.5 * t) * np.exp(-0.05 * t) + 0.05 * np.sin(2 * np.pi * 2.3 * t)
    v = None if along_x else np.gradient(x, t)
    grid = {
        "beta": np.linspace(0.5, 3.0, 7),
        "gamma": np.linspace(-0.5, 2.0, 7),
        "n": np.linspace(1.0, 3.0, 7),
    }
    cases = [
        (BoucWenHysteresis(1.0, param="kh"), grid),
        (BoucWenHysteresis(1.0, param="kh"), {"beta": 1.0, "gamma": 0.5, "n": 2.0}),
        (AmplitudeSoftening(0.0, 0.0, 2.0, a_ref=0.2, w0=3.0), {"tau": 2.0}),
    ]
    if build.compiler() is not None:  # the C path is the one taken here, not Python twice
        assert all(kernel.latent_path(term, t, x, v, values, 4) is not None for term, values in cases)
    fast = [latent_path(term, t, x, v, values) for term, values in cases]
    monkeypatch.setenv("PIDYN_COMPILED", "0")
    for (term, values), got in zip(cases, fast):
        want = latent_path(term, t, x, v, values)
        assert got.shape == want.shape
        if any(np.ndim(val) for val in values.values()):
            _close(got, want, rtol=1e-12)
        else:
            assert np.array_equal(got, want)
