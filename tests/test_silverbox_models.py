"""What the Silverbox circuit does beyond a cubic spring (``experiments/silverbox_models.py``),
checked on a few seconds of its estimation part (each test able to fail)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))

import silverbox_models as sm  # noqa: E402

from pidyn.data.measured.silverbox import load_silverbox  # noqa: E402
from pidyn.refine.output_error import fit_output_error  # noqa: E402
from pidyn.simulate import simulate_response  # noqa: E402

#: the cubic model the diagnosis names, polished (experiments/results/silverbox)
CUBIC = {"m": 5.3772e-06, "c": 0.00022545, "k": 0.991, "k3": 3.9121}


def _mse(system, values, rec) -> float:
    err = simulate_response(system, values, rec)["x"][:, 0] - rec.x[:, 0]
    return float(np.mean(err[sm.SKIP :] ** 2))


def test_the_circuits_damping_is_not_linear():
    """Fitted by output error on 3 s, the cubic model with a quadratic damper leaves under 0.8 times
    the cubic model's simulation error on the next 3 s, and its damper comes out positive."""
    rec = load_silverbox()
    fit, both = rec.segment(0.0, 3.0), rec.segment(0.0, 6.0)
    later = both.t > 3.0
    scales = sm._scales(rec)
    out = {}
    for added in ([], ["quadratic_damping"]):
        system = sm._terms(CUBIC, added, scales)
        init = {s.name: s.init for s in system.param_specs()}
        values = {**init, **fit_output_error(fit, system, init=init, max_nfev=40).params}
        err = simulate_response(system, values, both)["x"][:, 0] - both.x[:, 0]
        out[tuple(added)] = (float(np.mean(err[later] ** 2)), values)
    cubic, damped = out[()], out[("quadratic_damping",)]
    assert damped[0] < 0.8 * cubic[0], (damped[0], cubic[0])
    assert damped[1]["c2"] > 0


def test_the_terms_are_built_with_their_scales_and_a_cubic_start():
    rec = load_silverbox()
    system = sm._terms(CUBIC, ["quadratic_stiffness", "x'^3"], sm._scales(rec))
    names = [s.name for s in system.param_specs()]
    assert names[:4] == ["m", "c", "k", "k3"] and "k2" in names and "p03" in names
    assert _mse(system, {**{s.name: s.init for s in system.param_specs()}, **CUBIC}, rec.segment(0, 1)) < 1e-6
