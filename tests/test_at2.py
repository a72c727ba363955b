import numpy as np
import pytest

from pidyn.excitation import SHIPPED, AT2FormatError, G, load_record, prepare, read_at2, record_index

HEADER = "PEER NGA STRONG MOTION DATABASE RECORD\nTest, 1/1/2000, Station, 000\nACCELERATION TIME SERIES IN UNITS OF G\n"


def write(tmp_path, text, name="r.AT2"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_every_shipped_record_parses(name):
    gm = load_record(name)
    row = next(r for r in record_index() if r["file"] == SHIPPED[name])
    assert gm.acc.size == int(row["npts"])
    assert gm.dt == pytest.approx(float(row["dt_s"]))
    assert gm.pga / G == pytest.approx(float(row["pga_g"]), rel=2e-3)


def test_good_file(tmp_path):
    p = write(
        tmp_path, HEADER + "NPTS=    6, DT=   .0100 SEC,\n .1E-01 -.2E-01 .3E-01\n .0 1.0E-2 -5.0E-03\n"
    )
    rec = read_at2(p)
    assert rec.dt == 0.01 and rec.acc_g.tolist() == [0.01, -0.02, 0.03, 0.0, 0.01, -0.005]


@pytest.mark.parametrize(
    "body, message",
    [
        ("1 2 3\n", "no 'NPTS=..., DT=...' line"),
        ("NPTS=    6, DT=   .0100 SEC,\n .1 .2 .3\n", "NPTS=6 but the file holds 3 values"),
        ("NPTS=    3, DT=   .0100 SEC,\n .1 abc .3\n", "'abc' is not a number"),
        ("NPTS=    3, DT=   .0100 SEC,\n .1 nan .3\n", "NaN or infinite"),
        ("NPTS=    3, DT=   0.0 SEC,\n .1 .2 .3\n", "must be positive"),
        ("NPTS=    3, DT=   .0100 SEC,\n 10 200 30\n", "cm/s^2 or m/s^2"),
    ],
)
def test_malformed_files_name_file_and_problem(tmp_path, body, message):
    p = write(tmp_path, HEADER + body)
    with pytest.raises(AT2FormatError) as exc:
        read_at2(p)
    assert str(p) in str(exc.value) and message in str(exc.value)


def test_velocity_file_rejected(tmp_path):
    p = write(tmp_path, "PEER\nX\nVELOCITY TIME SERIES IN UNITS OF CM/S\nNPTS= 3, DT= .01 SEC,\n1 2 3\n")
    with pytest.raises(AT2FormatError, match="units 'CM/S'"):
        read_at2(p)


def test_missing_file_and_unknown_name():
    with pytest.raises(AT2FormatError, match="not a shipped record name"):
        load_record("no_such_quake")


def test_transformations():
    gm = prepare("kobe", duration=40.0)
    assert gm.duration == pytest.approx(40.0)
    assert gm.scaled(2.0).pga == pytest.approx(2 * gm.pga)
    st = gm.stretched(1.5)
    assert st.dt == pytest.approx(1.5 * gm.dt) and st.acc.size == gm.acc.size
    up = gm.resampled(0.01)
    assert up.dt == 0.01 and np.allclose(up.acc[::2], gm.acc)
    down = prepare("loma_prieta").resampled(0.01)  # 0.005 -> 0.01 s with anti-aliasing
    assert down.dt == 0.01 and abs(down.acc.size - prepare("loma_prieta").acc.size / 2) <= 1
    assert gm(np.array([-1.0, 1e6])).tolist() == [0.0, 0.0]


def test_arias_onset_and_start():
    from pidyn.excitation.ground_motion import GroundMotion

    # a pulse of energy between 3 and 4 s: 5 % of the Arias intensity falls at 3.05 s, 95 % at 3.95 s
    acc = np.zeros(1001)
    acc[300:400] = 1.0
    gm = GroundMotion(name="pulse", dt=0.01, acc=acc)
    assert gm.arias_time(0.05) == pytest.approx(3.04, abs=0.011)
    assert gm.arias_time(0.95) == pytest.approx(3.94, abs=0.011)
    cut = gm.starting_at(2.5)
    assert cut.duration == pytest.approx(7.5) and cut.arias_time(0.05) == pytest.approx(
        gm.arias_time(0.05) - 2.5
    )
    with pytest.raises(ValueError, match="past its end"):
        gm.starting_at(20.0)
    # Chi-Chi TCU078 is nearly silent for its first 20 s: the strong motion starts after 20 s
    chichi = prepare("chichi", dt=0.02)
    assert chichi.arias_time(0.05) > 20.0
    seg = prepare("chichi", dt=0.02, start=22.0, duration=20.0)
    assert seg.pga > 50 * prepare("chichi", dt=0.02, duration=20.0).pga
