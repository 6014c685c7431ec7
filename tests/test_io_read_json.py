"""stiffmap.io.read_json: the JSON reader behind camera.json and the fixed2base transform."""

from __future__ import annotations

import json

import pytest

from stiffmap.errors import InputError
from stiffmap.io import read_json, replace_keeping_previous


def test_read_json_round_trips_a_value(tmp_path):
    value = {"fx": 3733.27, "dist": [-0.09, 0.11, 0.0], "name": "µ-camera", "ok": True, "none": None}
    p = tmp_path / "v.json"
    p.write_text(json.dumps(value, ensure_ascii=False), encoding="utf-8")
    assert read_json(p, "camera file") == value


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("missing.json", None, r"missing\.json: transform file not found"),
        ("dir", "directory", r"dir: transform file not found"),
        ("bad.json", b'{"a": 1,\n  x}', r"bad\.json: not valid JSON \(line 2, column 3: Expecting property"),
        ("latin1.json", b'{"a": "\xe9"}', r"latin1\.json: cannot read: 'utf-8' codec can't decode byte 0xe9"),
    ],
)
def test_read_json_names_the_file_and_the_problem(tmp_path, name, content, message):
    p = tmp_path / name
    if content == "directory":
        p.mkdir()
    elif content is not None:
        p.write_bytes(content)
    with pytest.raises(InputError, match=message) as e:
        read_json(p, "transform file")
    assert e.value.source == str(p)


def test_replacing_a_result_keeps_the_different_previous_one(tmp_path):
    p = tmp_path / "camera.json"
    assert replace_keeping_previous(p, "first\n") is None  # nothing to keep
    assert replace_keeping_previous(p, "first\n") is None  # same content: nothing lost
    assert not (tmp_path / "camera.json.bak").exists()
    bak = replace_keeping_previous(p, "second\n")
    assert bak == tmp_path / "camera.json.bak"
    assert bak.read_text() == "first\n" and p.read_text() == "second\n"


def test_a_result_equal_to_the_last_digits_is_not_backed_up_again(tmp_path):
    """Threaded solvers differ in the last digits between runs: not a different calibration."""
    p = tmp_path / "camera.json"
    replace_keeping_previous(p, json.dumps({"fx": 3733.27, "dist": [-0.09, 0.11]}))
    replace_keeping_previous(p, json.dumps({"fx": 3733.5, "dist": [-0.09, 0.11]}))  # kept: 3733.27
    again = {"fx": 3733.5 * (1 + 3e-14), "dist": [-0.09, 0.11]}
    assert replace_keeping_previous(p, json.dumps(again)) is None
    assert json.loads((tmp_path / "camera.json.bak").read_text())["fx"] == 3733.27
