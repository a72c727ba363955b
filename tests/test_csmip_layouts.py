"""Every CESMD archive layout reads: per-channel V2 files, one combined V2 file of every channel
(each ended by a ``/&`` line), or both side by side; the station named in the headers is checked
against the one the user names."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import ROOT

from pidyn.data.csmip import CsmipFormatError, read_archive
from pidyn.data.sources import DataError
from pidyn.data.strong_motion import csmip_record

ARCHIVE = ROOT / "data" / "painter_street" / "records" / "nc73821046_ce89324p.zip"


def _v2_members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist() if n.lower().endswith(".v2")}


def _write(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _combined(members: dict[str, bytes]) -> bytes:
    return b"\n".join(data.rstrip(b"\r\n") for data in members.values()) + b"\n"


def test_a_combined_v2_file_reads_as_its_channels(tmp_path):
    members = _v2_members(ARCHIVE)
    per_channel = read_archive(ARCHIVE)
    combined = read_archive(_write(tmp_path / "combined.zip", {"ce89324p.v2": _combined(members)}))
    assert sorted(combined.channels) == sorted(per_channel.channels) and len(combined.channels) == len(
        members
    )
    for n, ch in per_channel.channels.items():
        other = combined.channels[n]
        assert other.dt == ch.dt and np.array_equal(other.acc, ch.acc) and other.orientation == ch.orientation


def test_an_archive_with_both_layouts_reads_and_a_disagreement_is_named(tmp_path):
    members = _v2_members(ARCHIVE)
    both = read_archive(_write(tmp_path / "both.zip", {**members, "ce89324p.v2": _combined(members)}))
    assert sorted(both.channels) == sorted(read_archive(ARCHIVE).channels)
    first = next(iter(members))
    text = members[first].decode("latin-1").split("\n")
    # one sample of the combined copy altered: the two layouts disagree on that channel
    k = next(i for i, line in enumerate(text) if "points of accel data" in line) + 1
    text[k] = text[k][:2] + "9" + text[k][3:]
    bad = {**members, first: "\n".join(text).encode("latin-1")}
    with pytest.raises(CsmipFormatError, match="differs between"):
        read_archive(_write(tmp_path / "bad.zip", {**members, "ce89324p.v2": _combined(bad)}))


def test_the_record_is_the_same_from_either_layout(tmp_path):
    combined = _write(tmp_path / "combined.zip", {"ce89324p.v2": _combined(_v2_members(ARCHIVE))})
    a = csmip_record(ARCHIVE, station="CE89324", direction="transverse", max_outputs=1)
    b = csmip_record(combined, station="CE89324", direction="transverse", max_outputs=1)
    assert np.array_equal(a.f, b.f) and np.array_equal(a.a, b.a)


def test_the_station_in_the_headers_must_be_the_one_named(tmp_path):
    members = {
        n: d.replace(b"Station No. 89324", b"Station No. 58658") for n, d in _v2_members(ARCHIVE).items()
    }
    other = _write(tmp_path / "other.zip", members)
    with pytest.raises(DataError, match="station CE58658, not data.station=CE89324"):
        csmip_record(other, station="CE89324", direction="transverse", max_outputs=1)
    # the same station spelled without its network code is the same station
    assert (
        csmip_record(
            ARCHIVE, station="89324", direction="transverse", max_outputs=1, inputs=[3], outputs=[7]
        ).a
        is not None
    )
