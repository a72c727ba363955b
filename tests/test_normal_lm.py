"""Stage 1 on the sparse normal equations: the sparse Jacobian is the dense one, the solver
reaches MINPACK's minimum, and a refinement from several records ends on the same estimate by
either route."""

import numpy as np
import pytest
from scipy.optimize import least_squares

import pidyn.refine.solve as solve
from pidyn.data.multi import concatenate
from pidyn.data.sources import synthetic
from pidyn.refine import RefineSettings, refine
from pidyn.refine.normal_lm import levenberg_marquardt
from pidyn.refine.setup import build_problem
from pidyn.systems import BoucWen, LinearSDOF


def _two_records(system, duration=12.0):
    return concatenate(
        [
            synthetic(system, m, noise=0.02, channels=("a",), duration=duration, dt=0.02, data_seed=i)
            for i, m in enumerate(["el_centro", "kobe"])
        ]
    )


def test_the_sparse_jacobian_is_the_dense_one():
    system = BoucWen()
    prob = build_problem(
        system, _two_records(system, 6.0), RefineSettings(states="integrated", segment_length=1.0)
    )
    u = prob.pack({"c": 0.35, "k": 11.0, "beta": 0.8, "gamma": 1.5, "n": 1.8}, np.full((prob.S, 3), 0.01))
    r, J, c, C = prob.linearize(u)
    rs, Js, cs, Cs = prob.linearize(u, sparse=True)
    np.testing.assert_array_equal(r, rs)
    np.testing.assert_array_equal(c, cs)
    np.testing.assert_array_equal(J, Js.toarray())
    np.testing.assert_array_equal(C, Cs.toarray())
    assert Js.nnz <= J.shape[0] * (prob.n_theta + prob.ns)  # a row: the parameters and its own segment


def test_the_normal_equations_reach_minpacks_minimum():
    """A curved valley (Rosenbrock's, in least-squares form, with a third residual) from a far start."""

    def fun(x):
        return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0], 0.1 * (x[2] - 2 * x[0])])

    def jac(x):
        return np.array([[-20 * x[0], 10, 0], [-1, 0, 0], [-0.2, 0, 0.1]])

    ours = levenberg_marquardt(fun, jac, np.array([-1.2, 1.0, 5.0]), max_nfev=200)
    ref = least_squares(fun, [-1.2, 1.0, 5.0], jac=jac, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12)
    np.testing.assert_allclose(ours.x, ref.x, atol=1e-8)
    assert ours.status in ("ftol", "xtol", "gtol")


def test_a_refinement_from_two_records_ends_on_the_same_estimate_by_either_route(monkeypatch):
    system = LinearSDOF(c=0.8, k=300.0)
    record = _two_records(system, 20.0)
    settings = RefineSettings(states="integrated", segment_length=1.0, period_scan=False)
    start = {"start": {"c": 1.2, "k": 250.0}}
    monkeypatch.setattr(solve, "DENSE_QR_LIMIT", float("inf"))
    dense = refine(system, record, start, settings)
    monkeypatch.setattr(solve, "DENSE_QR_LIMIT", 0.0)
    sparse = refine(system, record, start, settings)
    for name in ("c", "k"):
        assert sparse.params[name] == pytest.approx(dense.params[name], rel=1e-8)
    assert sparse.max_defect < 1e-8
