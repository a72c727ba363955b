"""A record's metadata is typed: facts by name, unknown keys refused where the record is made."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest

from pidyn import Record
from pidyn.data.errors import DataError
from pidyn.data.meta import Piece, RecordMeta, Split
from pidyn.data.multi import concatenate

ROOT = Path(__file__).resolve().parents[1]


def _record(name: str = "r", meta=None) -> Record:
    t = np.arange(200) * 0.01
    return Record(name=name, t=t, f=np.sin(t), x=np.cos(t), meta=meta)


def test_a_mapping_is_typed_where_the_record_is_made():
    rec = _record(meta={"split": {"fit": [0, 1.2], "heldout": [1.2, 1.99]}, "input_hold": "bandlimited"})
    assert isinstance(rec.meta, RecordMeta) and rec.meta.split == Split((0.0, 1.2), (1.2, 1.99))
    assert rec.meta.input_hold == "bandlimited" and rec.meta.pga is None and rec.meta.notes == []


def test_an_unknown_key_is_refused_with_the_record_named():
    with pytest.raises(DataError, match=r"record 'bad': unknown metadata \['spilt'\]"):
        _record("bad", {"spilt": {"fit": [0, 1], "heldout": [1, 2]}})


def test_to_dict_is_json_and_reads_back_the_same():
    meta = RecordMeta(
        path="a.zip",
        pga=1.5,
        split=Split.at(1.0, 1.99),
        sensor_a=np.ones((3, 2)),
        pieces=[Piece("a", 0, 100, 0.0, RecordMeta(path="a.zip", pga=1.5))],
        notes=["resampled"],
    )
    d = json.loads(json.dumps(meta.to_dict()))
    assert d["split"] == {"fit": [0.0, 1.0], "heldout": [1.0, 1.99]} and d["sensor_a"] == [[1.0, 1.0]] * 3
    back = RecordMeta.of(d)
    assert back.split == meta.split and back.pieces[0].origin.pga == 1.5 and back.notes == ["resampled"]
    assert "event" not in d  # unset facts are left out
    assert meta.to_dict(["path", "event"]) == {"path": "a.zip", "event": None}


def test_joined_records_keep_each_ones_origin_and_the_last_ones_held_out_part():
    a = _record("a", {"path": "a.zip", "pga": 1.0, "split": Split.at(1.5, 1.99), "notes": ["one"]})
    b = _record("b", {"path": "b.zip", "pga": 2.0, "split": Split.at(1.5, 1.99), "notes": ["two"]})
    both = concatenate([a, b])
    assert [p.origin.path for p in both.meta.pieces] == ["a.zip", "b.zip"]
    assert both.meta.paths == ["a.zip", "b.zip"] and both.meta.pga == 2.0 and both.meta.path is None
    assert both.meta.notes == ["a: one", "b: two"]
    assert both.meta.split.fit == (0.0, pytest.approx(2.0 + 1.5)) and both.meta.split.heldout[1] == both.t[-1]


def test_the_package_reads_metadata_by_name_only():
    """No ``meta["key"]``, ``meta.get("key")`` or ``meta.update`` on a record in the package."""
    found = []
    for f in (ROOT / "src" / "pidyn").rglob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            target = None
            if isinstance(node, ast.Subscript):
                target = node.value
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                if node.func.attr in ("get", "update", "items"):
                    target = node.func.value
            if isinstance(target, ast.Attribute) and target.attr == "meta":
                found.append(f"{f.relative_to(ROOT)}:{node.lineno}")
    assert not found, found
