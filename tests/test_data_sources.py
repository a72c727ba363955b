import numpy as np
import pandas as pd
import pytest

from pidyn.data.sources import DataError, from_csv


def write(tmp_path, text):
    p = tmp_path / "m.csv"
    p.write_text(text)
    return p


def good_rows(n=20, dt=0.01):
    t = np.arange(n) * dt
    return (
        "t,x,v,ag\n" + "\n".join(f"{a:.4f},{np.sin(a):.6f},{np.cos(a):.6f},{0.1 * a:.6f}" for a in t) + "\n"
    )


def test_good_csv(tmp_path):
    r = from_csv(write(tmp_path, good_rows()))
    assert r.excitation == "ground" and r.x.shape == (20, 1) and r.dt == pytest.approx(0.01)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda s: s.replace("0.0500,", "0.0550,"), "non-uniform time step"),
        (lambda s: s.replace(",ag\n", ",u\n").replace("t,x,v,u", "t,x,v,ag,u"), "exactly one excitation"),
        (lambda s: s.replace("t,x,v,ag", "t,y,v,ag"), "unknown column(s) ['y']"),
        (lambda s: s.replace("t,x,v,ag", "t,y,w,ag"), "unknown column(s) ['y', 'w']"),
        (lambda s: s.replace(s.splitlines()[5], s.splitlines()[5].rsplit(",", 1)[0] + ",nan"), "NaN"),
        (lambda s: s + "0.2000,0.1\n", "NaN"),  # a short row: mismatched column lengths
        (lambda s: s.replace("0.0300,", "0.0100,"), "not strictly increasing"),
    ],
)
def test_bad_csv_names_file_and_problem(tmp_path, mutate, message):
    p = write(tmp_path, mutate(good_rows()))
    with pytest.raises(DataError) as exc:
        from_csv(p)
    assert str(p) in str(exc.value) and message in str(exc.value)


def test_csv_response_with_an_at2_record(tmp_path):
    from pidyn.excitation import prepare

    gm = prepare("el_centro", duration=5.0)
    t = gm.t
    p = tmp_path / "resp.csv"
    pd.DataFrame({"t": t, "x": 0.01 * np.sin(t)}).to_csv(p, index=False)
    r = from_csv(p, at2="el_centro")
    assert r.excitation == "ground"
    np.testing.assert_allclose(r.f, gm.acc, rtol=1e-12)
    with pytest.raises(DataError, match="longer than the AT2"):
        long = tmp_path / "long.csv"
        tt = np.arange(0, 60, 0.01)
        pd.DataFrame({"t": tt, "x": np.sin(tt)}).to_csv(long, index=False)
        from_csv(long, at2="el_centro")


def test_floor_columns_give_a_building_record_with_absolute_accelerations_made_relative(tmp_path):
    t = np.arange(30) * 0.01
    ag = 0.3 * np.sin(5 * t)
    a1, a3 = np.cos(3 * t), np.sin(2 * t)
    df = pd.DataFrame({"t": t, "ag": ag, "a1": a1 + ag, "a3": a3 + ag, "x3": 0.01 * t})
    p = tmp_path / "building.csv"
    df.to_csv(p, index=False)
    r = from_csv(p)
    assert r.a.shape == (30, 3) and r.x.shape == (30, 3)
    assert np.allclose(r.a[:, 0], a1) and np.allclose(r.a[:, 2], a3) and np.all(np.isnan(r.a[:, 1]))
    assert r.sensors() == {"x": [3], "a": [1, 3]}
    rel = from_csv(p, acceleration="relative")
    assert np.allclose(rel.a[:, 0], a1 + ag)
    df.drop(columns=["a1", "a3", "x3"]).to_csv(p, index=False)
    with pytest.raises(DataError, match="no response column"):
        from_csv(p)
