"""The bilinear elastoplastic spring: named where it is hidden, told apart from the library's
Bouc-Wen loop both ways, and nothing named where nothing is hidden."""

import json

import numpy as np
import pytest
from helpers import make_cfg

from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Signals
from pidyn.discrepancy.hidden import hidden_case
from pidyn.discrepancy.screening import screen
from pidyn.systems import LinearSDOF
from pidyn.weak_form import WeakForm, smooth_signals, velocity_noise

NAME = "bilinear_elastoplastic"
PERIOD = 2 * np.pi / np.sqrt(15.0)
WITH_IT = {**LIBRARY, NAME: EFFECTS[NAME]}


def _screen(case):
    r = case.record
    xs, vs = smooth_signals(r.t, r.x[:, 0], r.v[:, 0], PERIOD)
    noise = velocity_noise(r.t, r.x[:, 0], r.v[:, 0], PERIOD)
    s = Signals(r.t, xs, vs, 1.0, 15.0, "k", t_fit_end=case.fit_end, v_noise=noise)
    weak = WeakForm.for_record(r.t, PERIOD)
    values = {"m": 1.0, "c": 0.5, "k": 15.0}
    return screen(LinearSDOF(), values, s, r.f, r.x[:, 0], weak, case.fit_end, effects=WITH_IT)


@pytest.mark.parametrize("seed", [0, 2, 4])
def test_a_yielding_spring_is_named_with_its_stiffness_and_yield_displacement(seed):
    case = hidden_case(NAME, seed, noise=0.02)
    sc = _screen(case)
    assert sc.verdict == "discrepancy" and sc.cause == NAME, sc.ranking[:3]
    found = sc.ranking[0].parameters
    assert found["kp"] == pytest.approx(case.truth["kp"], rel=EFFECTS[NAME].tolerance)
    assert found["x_y"] == pytest.approx(case.truth["x_y"], rel=0.1)


@pytest.mark.parametrize("hidden", ["hysteresis", None])
def test_a_bouc_wen_loop_stays_bouc_wen_and_nothing_stays_nothing(hidden):
    for seed in (1, 3):
        sc = _screen(hidden_case(hidden, seed, noise=0.02))
        assert sc.cause == hidden, (seed, sc.ranking[:3])


@pytest.mark.slow
@pytest.mark.second_proof  # the screening's tests above prove the naming; this the extension
def test_the_diagnosis_extends_the_model_with_it_and_predicts_the_held_out_part(tmp_path):
    from pidyn.tasks.diagnose import diagnose

    cfg = make_cfg(
        [
            f"data.source.effect={NAME}",
            "data_seed=3",
            "noise=0.02",
            f"diagnosis.effects=[{','.join(WITH_IT)}]",
        ],
        tmp_path,
        config_name="diagnose",
    )
    d = diagnose(cfg)
    assert d["verdict"] == "discrepancy" and d["causes"] == [NAME], d["causes"]
    assert d["parameters"]["kp"] == pytest.approx(d["hidden"]["parameters"]["kp"], rel=0.05)
    assert d["gain"]["extended"] < 0.2 * d["gain"]["nominal"]
    assert json.loads((tmp_path / "diagnosis.json").read_text())["verdict"] == "discrepancy"
