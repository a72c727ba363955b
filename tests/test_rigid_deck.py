"""The bridge deck rigid in plan on its supports (``pidyn.systems.deck``): its equations against the
linear algebra they stand for, its layout read from a station file, and its support stiffnesses
recovered from a simulated record of three supports that move differently."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.data.errors import DataError
from pidyn.systems.deck import RigidDeck

TRUTH = {"c1": 1.5, "k1": 150.0, "c2": 1.0, "k2": 400.0, "c3": 2.0, "k3": 250.0}
LAYOUT = {"length": 80.0, "positions": {1: 0.0, 2: 45.0, 3: 80.0, 4: 0.0, 5: 80.0}}


def _deck(**kw) -> RigidDeck:
    return RigidDeck(["ch1", "ch2", "ch3"], [0.0, 45.0, 80.0], 80.0, **kw)


def test_the_state_rate_is_the_linear_model_it_stands_for():
    deck = _deck()
    p = {"m": 1.0, **TRUTH}
    M, C, K = deck.linear_matrices(p)
    R = np.array(deck.influence(p))
    B = np.array([[1 - x, x] for x in deck.xi])
    assert np.allclose(R.sum(axis=1), 1.0)  # the supports moving together move the deck with them
    assert np.allclose(K @ R, B.T * np.array([150.0, 400.0, 250.0]))  # K R = K_s
    rng = np.random.default_rng(0)
    y, f = rng.normal(size=(7, 4)), rng.normal(size=(7, 6))
    ag, vg = f[:, :3], f[:, 3:]
    c = np.array([1.5, 1.0, 2.0])
    dashpots = ((y[:, 2:] + vg @ R.T) @ B.T - vg) * c  # each support's whole deformation rate
    acc = -(dashpots @ B + y[:, :2] @ K) @ np.linalg.inv(M).T - ag @ R.T
    rate = deck.state_rate(0.0, y, p, f)
    assert np.allclose(rate[:, :2], y[:, 2:]) and np.allclose(rate[:, 2:], acc, atol=1e-12)


def test_a_uniform_deck_has_the_consistent_mass_of_a_bar_and_its_supports_must_hold_it():
    assert np.allclose(_deck().mass_matrix, [[1 / 3, 1 / 6], [1 / 6, 1 / 3]])
    with pytest.raises(ValueError, match="one position"):
        RigidDeck(["a", "b"], [10.0, 10.0], 80.0)
    with pytest.raises(ValueError, match="outside the deck"):
        RigidDeck(["a", "b"], [0.0, 90.0], 80.0)


def test_the_station_layout_places_every_channel_and_a_station_without_one_is_named():
    from pidyn.data.layout import observation, station_deck

    deck = station_deck("CE89324", "transverse")
    assert deck.inputs == ("ch3", "ch17", "ch20") and set(deck.sensors) == {"ch7", "ch9", "ch4"}
    H = observation(deck, [7, 9, 4])
    assert np.allclose(H.sum(axis=1), 1.0) and np.allclose(H[1:], [[0, 1], [1, 0]])
    with pytest.raises(DataError, match="no positions"):
        station_deck("CE58658", "transverse")
    along = station_deck("CE89324", "longitudinal")  # along the deck: one translation on the supports
    assert along.n_dof == 1 and along.inputs == ("ch15", "ch1", "ch18")
    with pytest.raises(DataError, match=r"channel\(s\) \[99\]"):
        station_deck("CE89324", "transverse", inputs=[3, 17, 99])


def test_a_record_read_through_the_layout_keeps_its_channels_for_scoring():
    from helpers import ROOT

    from pidyn.data.layout import sensor_view, station_deck
    from pidyn.data.strong_motion import csmip_record

    path = ROOT / "data" / "painter_street" / "records" / "nc73821046_ce89324p.zip"
    rec = csmip_record(path, station="CE89324", system=station_deck("CE89324", "transverse"))
    assert rec.a.shape[1] == 2 and rec.meta.sensor_channels == [7, 9, 4]
    H = np.asarray(rec.meta.observation)
    raw = rec.meta.sensor_a
    # least squares: what is left of the channels is orthogonal to what a rigid deck can move
    assert np.allclose(H.T @ (raw - rec.a @ H.T).T, 0.0, atol=1e-8)
    view, sim = sensor_view(rec, {"a": rec.a})
    assert np.array_equal(view.a, raw) and view.meta.output_channels == [7, 9, 4]
    assert np.allclose(sim["a"], rec.a @ H.T)


def _three_support_record(noise: float):
    from pidyn.data.sources import synthetic_from_motion
    from pidyn.excitation.ground_motion import SupportMotions, prepare

    gm = SupportMotions.from_motions(
        {
            "ch1": prepare("el_centro", dt=0.02, duration=20.0),
            "ch2": prepare("kobe", dt=0.02, duration=20.0, scale=0.6),
            "ch3": prepare("northridge", dt=0.02, duration=20.0, scale=0.8),
        }
    )
    params = {n: {"true": v} for n, v in TRUTH.items()}
    return synthetic_from_motion(_deck(params=params), gm, noise=noise, channels=["a"])


@pytest.mark.slow
def test_the_support_stiffnesses_are_recovered_within_their_intervals(tmp_path):
    import pidyn

    rec = _three_support_record(noise=0.01)
    res = pidyn.identify(
        rec,
        "rigid_deck",
        baselines="none",
        out_dir=tmp_path,
        model__schedule__max_windows=1,
        # a short PIDynNet stage: the data's start and the refinement after it are under test
        model__schedule__pretrain_iters=200,
        model__schedule__max_iters=300,
        overrides=[
            "system.inputs=[1,2,3]",
            "system.outputs=[4,5]",
            "+system.layout.length=80.0",
            "+system.layout.positions={1: 0.0, 2: 45.0, 3: 80.0, 4: 0.0, 5: 80.0}",
        ],
    )
    for n, t in TRUTH.items():
        lo, hi = res.ci95[n]
        assert lo <= t <= hi or abs(res.params[n] - t) <= 0.75 * (hi - lo), (n, res.params[n], lo, hi)
    for n in ("k1", "k2", "k3"):
        assert res.params[n] == pytest.approx(TRUTH[n], rel=0.01), n
    import json

    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert [r["input"] for r in metrics["supports"]] == ["ch1", "ch2", "ch3"]
    assert all(
        r["k_determined"] and r["k_ci95"][0] < TRUTH[f"k{r['support']}"] < r["k_ci95"][1]
        for r in metrics["supports"]
    )
    assert "## Supports" in (tmp_path / "report.md").read_text()
    assert (tmp_path / "figures" / "support_loops.png").stat().st_size > 10_000  # each support's loop


def test_supports_the_data_cannot_tell_apart_are_said_so_and_their_values_not_reported():
    from types import SimpleNamespace

    from pidyn.notes import codes
    from pidyn.runs.supports import support_lines, support_table

    deck = _deck()
    names = ["c1", "k1", "c2", "k2", "c3", "k3"]
    corr = np.eye(6)
    corr[1, 3] = corr[3, 1] = -0.97  # supports 1 and 2: only their combination is determined
    ci = {n: {"ci95": [0.9 * v, 1.1 * v]} for n, v in TRUTH.items()} | {"k2": {"ci95": [40.0, 900.0]}}
    refined = SimpleNamespace(names=names, correlation=corr.tolist(), intervals=ci)
    rows, notes = support_table(deck, {"m": 1.0, **TRUTH}, refined)
    assert codes(notes) == {"supports_not_distinguished", "support_undetermined"}
    assert "-0.97" in notes[0] and "support 1 (ch1)" in notes[0] and "support 2 (ch2)" in notes[0]
    assert [r["k_determined"] for r in rows] == [True, False, True]
    table = "\n".join(support_lines(rows))
    assert "not determined" in table and "400" not in table.split("\n")[3].split("|")[4]


def test_a_support_takes_any_force_term_and_its_sensitivities_are_exact():
    """An abutment that softens with amplitude and a hysteretic bent: the model simulates, and the
    dual numbers the refinement uses give the finite differences' derivatives."""
    from pidyn.autodiff import deriv, seed, value
    from pidyn.systems.terms import AmplitudeSoftening, BoucWenHysteresis

    deck = _deck(
        support_terms={
            1: [{"term": "amplitude_softening", "soft": 0.3, "gain": 0.5, "a_ref": 0.005, "w0": 25.0}],
            2: [{"term": "hysteresis"}],
        }
    )
    assert isinstance(deck.supports[0][-1].term, AmplitudeSoftening) and deck.supports[0][-1].reads == (
        "k1",
        "c1",
    )
    assert isinstance(deck.supports[1][-1].term, BoucWenHysteresis) and "k2" in {
        s.name for s in deck.param_specs()
    }
    assert deck.n_latent == 2 and deck.n_state == 6 and not deck.linear_time_invariant
    p = {s.name: float(s.init) for s in deck.param_specs()}
    rng = np.random.default_rng(1)
    y, f = 0.01 * rng.normal(size=6), rng.normal(size=6)
    y[4] = 0.5
    base = deck.state_rate(0.0, y, p, f)
    assert base.shape == (6,) and np.all(np.isfinite(base))
    for name in ("k1", "soft1", "c3"):
        dual = deck.state_rate(0.0, y, {**p, name: seed(p[name], np.array([1.0]))}, f)
        h = 1e-6 * max(abs(p[name]), 1.0)
        fd = (deck.state_rate(0.0, y, {**p, name: p[name] + h}, f) - base) / h
        assert np.allclose(value(dual), base) and np.abs(fd).max() > 0
        assert np.allclose(deriv(dual, 1)[..., 0], fd, rtol=1e-4, atol=1e-6), name


def test_each_kind_of_data_gets_its_default_model_and_a_named_system_wins():
    from pidyn.config import compose

    assert compose("train").system._target_ == "pidyn.systems.Duffing"  # the paper's default
    bridge = compose("train", groups={"data": "csmip"})
    assert bridge.system._target_ == "pidyn.systems.LinearSDOF" and bridge.system.inputs is None
    deck = compose("train", groups={"data": "csmip", "system": "rigid_deck"})
    assert deck.system._target_ == "pidyn.data.layout.station_deck"
    assert compose("train", groups={"system": "shear_building"}).system._target_.endswith("ShearBuilding")


def test_the_diagnosis_of_a_deck_support_by_support_is_refused_by_name(tmp_path):
    from pidyn.config import compose
    from pidyn.tasks.diagnose import _diagnose

    cfg = compose(
        "diagnose",
        groups={"data": "csmip", "system": "rigid_deck"},
        values={"data.station": "CE89324"},
        output_dir=tmp_path,
    )
    with pytest.raises(ValueError, match="diagnosis support by support"):  # no subject takes a deck
        _diagnose(cfg, None)
