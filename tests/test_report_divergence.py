"""An identified model that diverges over the record (parameters run to their bounds from a bad
start) still gets its report: figures drawn with the blown-up part left out, and a note saying
the simulation diverged, instead of a crash after metrics.json."""

import json

import numpy as np

from pidyn.data.sources import synthetic
from pidyn.reporting import plot_convergence, plot_response, plottable
from pidyn.runs.building_report import write_building_report
from pidyn.systems import ShearBuilding


def test_plottable_blanks_what_a_plot_cannot_scale():
    a = np.array([1.0, np.inf, -np.inf, np.nan, 1e300, -2.0])
    out = plottable(a)
    assert np.isnan(out[1:5]).all() and out[0] == 1.0 and out[5] == -2.0


def test_figures_of_a_diverged_run_are_drawn(tmp_path):
    t = np.arange(200) * 0.01
    blown = np.concatenate([np.sin(t[:100]), np.geomspace(1.0, 1.7e308, 100)])
    blown[150:] = np.inf
    plot_response(tmp_path / "r.png", t, {"measured": np.sin(t), "identified model (simulated)": blown * -1})
    traj = [{"iteration": i, "t": float(i), "k": 10.0 + i} for i in range(5)]
    final = {"k": {"value": 1e12, "ci95": [-np.inf, np.inf]}}
    plot_convergence(tmp_path / "c.png", traj, {"k": 12.0}, [{"t1": 2.0}], final=final)
    assert (tmp_path / "r.png").stat().st_size > 0 and (tmp_path / "c.png").stat().st_size > 0


def test_building_report_of_a_model_that_blows_up(tmp_path):
    sb = ShearBuilding()
    r = synthetic(sb, "el_centro", eq_scale=3.0, duration=6.0, channels=("a",))
    bad = {**sb.true_values(), "k1": 1e9, "c2": 1e-9}  # RK4 at dt/4 is unstable at this stiffness
    modes = write_building_report(sb, r, bad, sb.true_values(), None, tmp_path)
    assert (tmp_path / "figures" / "storey_loops.png").exists()
    assert json.loads((tmp_path / "modal.json").read_text())["identified"]["frequency_hz"]
    assert "diverges" in (tmp_path / "building.md").read_text()
    assert modes["diverged"]


def test_storey_residuals_point_at_the_storey_the_model_gets_wrong():
    """The storey force the floors' accelerations give against the model's: small everywhere for
    the true model, largest in the storey whose stiffness the model halves."""
    from pidyn.runs.building_report import storey_residuals

    sb = ShearBuilding()
    r = synthetic(sb, "el_centro", duration=12.0, channels=("a",))
    r = type(r)(**{**r.__dict__, "truth": None})  # as a measured building: no truth to compare with
    truth = sb.true_values()
    good = storey_residuals(sb, truth, r)
    assert len(good) == sb.n_dof and max(row["residual_share"] for row in good) < 0.1, good
    wrong = storey_residuals(sb, {**truth, "k2": 0.5 * truth["k2"]}, r)
    shares = [row["residual_share"] for row in wrong]
    assert int(np.argmax(shares)) == 1 and shares[1] > 0.3, shares
    assert wrong[1]["explained_by"]["stiffness (d)"] > 0.8, wrong[1]
