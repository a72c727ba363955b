"""A film record's recorders put on one clock from the supports' ground motions (each test able to fail)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import pidyn.data.strong_motion as strong_motion
from pidyn.data.clocks import recorder_offsets, shifted
from pidyn.data.csmip import read_archive
from pidyn.data.strong_motion import _clock_groups, csmip_record
from pidyn.notes import codes

RECORDS = Path(__file__).resolve().parents[1] / "data" / "painter_street" / "records"
DIGITAL = RECORDS / "nc73201181_ce89324p.zip"  # one GPS-timed recorder: the truth is no offset
LATE = 0.05  # s: what the test puts on channels 1-8


def _two_clocks(path: Path, late: float):
    """The digital archive as if channels 1-8 were on a second recorder whose clock reads ``late`` s late."""
    a = read_archive(path)
    moved = {
        c: replace(ch, recorder="LATE", acc=shifted(ch.acc, late, ch.dt), vel=shifted(ch.vel, late, ch.dt))
        if c <= 8
        else ch
        for c, ch in a.channels.items()
    }
    return replace(a, channels=moved)


def test_shift_is_a_delay_to_a_fraction_of_a_sample_and_undoes_itself():
    dt = 0.01
    t = np.arange(2000) * dt
    y = np.sin(2 * np.pi * 1.3 * t) * np.exp(-(((t - 10) / 3) ** 2))
    late = shifted(y, 0.037, dt)
    expect = np.sin(2 * np.pi * 1.3 * (t - 0.037)) * np.exp(-(((t - 0.037 - 10) / 3) ** 2))
    assert np.max(np.abs(late - expect)) < 1e-3
    assert np.max(np.abs(shifted(late, -0.037, dt) - y)) < 1e-3


def test_a_recorder_offset_put_into_a_digital_record_is_found_from_the_ground_channels():
    groups = _clock_groups("CE89324", [3, 17, 20])
    offsets, notes = recorder_offsets(_two_clocks(DIGITAL, LATE), groups)
    assert [o.recorder for o in offsets] == ["LATE"]
    assert offsets[0].seconds == pytest.approx(LATE, abs=0.01)  # the wave's passage is a few ms here
    assert set(offsets[0].pairs) == {(3, 17), (3, 20), (1, 15), (1, 18)}
    assert codes(notes) == {"recorders_aligned"}
    assert recorder_offsets(read_archive(DIGITAL), groups) == ([], [])  # one recorder: nothing to do


def test_the_record_read_from_two_clocks_is_the_one_clock_record(monkeypatch):
    """End to end: the record of the archive with a recorder put late equals the true record once
    the clocks are aligned, and not without."""
    truth = csmip_record(DIGITAL, station="CE89324", max_outputs=3)
    monkeypatch.setattr(strong_motion, "read_archive", lambda path: _two_clocks(path, LATE))
    aligned = csmip_record(DIGITAL, station="CE89324", max_outputs=3)
    raw = csmip_record(DIGITAL, station="CE89324", max_outputs=3, one_clock=False)
    assert "recorders_aligned" in codes(aligned.meta.notes) and "recorders_aligned" not in codes(
        raw.meta.notes
    )

    def err(rec):
        n = min(len(rec.t), len(truth.t)) - 50  # the last samples moved in from outside the record
        scale = np.max(np.abs(truth.a))
        return np.max(np.abs(rec.a[:n] - truth.a[:n])) / scale, np.max(np.abs(rec.f[:n] - truth.f[:n]))

    # deck channels 4 and 7 are on the late clock; what is left is the record's own 0.005 s of
    # the wave's passage, read as clock (0.055 s found for 0.05)
    assert err(aligned)[0] < 0.15 and err(raw)[0] > 0.6
    assert err(aligned)[1] < 0.2 * err(raw)[1]


def test_film_records_say_what_was_done_to_their_clocks():
    rec = csmip_record(RECORDS / "capemendocino_31jul1987_ce89324p.zip", station="CE89324", max_outputs=3)
    said = [n for n in rec.meta.notes if n.endswith("[recorders_aligned]")]
    assert len(said) == 1 and "C0161 reads 0.04" in said[0] and "early against C0138" in said[0]
    # Petrolia's second 1992 aftershock: +0.006 s, less than a sample, is not a clock the data determine
    rec = csmip_record(
        RECORDS / "petroliaaftershock2_26apr1992_ce89324p.zip", station="CE89324", max_outputs=3
    )
    kept = [n for n in rec.meta.notes if n.endswith("[recorders_not_aligned]")]
    assert "recorders_aligned" not in codes(rec.meta.notes) and "less than a sample" in kept[0]
    # Eureka 1983: its first recorder holds deck channels only, so its clock cannot be read
    rec = csmip_record(
        RECORDS / "eureka_24aug1983_ce89324p.zip", station="CE89324", on_missing="drop", max_outputs=3
    )
    assert "recorders_not_aligned" in codes(rec.meta.notes)
