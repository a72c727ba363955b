"""The paper's physics-only prediction (Eq. 14) from a finished run folder, beside the plain
simulation: fresh networks on the physics alone, the run's parameters held."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from pidyn.runs.physics_only import applies


def test_a_model_on_several_supports_is_said_to_be_outside_its_reach():
    from pidyn.data.sources import synthetic
    from pidyn.systems import LinearSDOF

    rec = synthetic(LinearSDOF(c=0.8, k=400.0), "el_centro", channels=("a",), duration=4.0, dt=0.02)
    assert applies(LinearSDOF(c=0.8, k=400.0), rec) is None
    assert "2 supports" in applies(LinearSDOF(inputs=["a", "b"]), rec)


@pytest.mark.slow
@pytest.mark.second_proof  # Eq. 14 itself: test_generalize; here, from a run folder
def test_the_networks_trained_on_the_physics_alone_predict_an_unseen_record(tmp_path):
    import pidyn
    from pidyn.data.sources import synthetic
    from pidyn.runs.physics_only import physics_only
    from pidyn.runs.prediction import Identified, score
    from pidyn.systems import LinearSDOF

    truth = LinearSDOF(c=0.8, k=400.0)
    seen = synthetic(truth, "el_centro", noise=0.01, channels=("a",), duration=10.0, dt=0.02)
    res = pidyn.identify(
        seen, "linear", baselines="none", out_dir=tmp_path / "run", model__schedule__max_windows=1
    )
    unseen = synthetic(truth, "kobe", noise=0.01, channels=("a",), duration=4.0, dt=0.02)
    run = Identified.load(res.run_dir)
    system, record, values = run.for_record(record=unseen)
    plain = score(system, values, record)
    settings = OmegaConf.create({"iterations": 300, "lbfgs_steps": 20, "split_tol": 1e-3, "min_window": 0.75})
    out = physics_only(run.cfg, system, values, record, plain["sim"], settings)
    assert out["applies"] and out["seconds"] > 0
    # the networks follow the physics of the run's model (its simulation), and so the record; the
    # accelerations, differentiated twice from the networks' displacement, less closely
    assert out["nrmse_x_against_simulation"] < 0.1 and out["mean_nrmse_a"] < 0.3, out
    assert plain["mean_nrmse_a"] < 0.05
