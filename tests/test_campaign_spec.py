"""campaign.toml: the example parses, dumps round-trip, and every mistake names key and line."""

from __future__ import annotations

import numpy as np
import pytest

from stiffmap.campaign.sensor_runner import sensor_config
from stiffmap.campaign.spec import load_spec, parse_spec
from stiffmap.campaign.spec_writer import EXAMPLE_TOML, dump_spec
from stiffmap.errors import InputError


def test_example_parses_and_round_trips():
    spec = parse_spec(EXAMPLE_TOML)
    assert spec.kind == "vision" and spec.repeats == 10
    assert spec.targets.fixed.board == "9x6" and spec.targets.mobile.square_mm == 10.0
    assert spec.images.path("loaded", 3, 2, 10) == "images/p03/l02_r10_loaded.png"
    again = parse_spec(dump_spec(spec))
    assert again == spec


def test_loads_resolve_with_friction():
    spec = parse_spec(EXAMPLE_TOML)
    loads = spec.loads.resolve(9.81)
    assert len(loads) == 9
    # +y 0.5 kg through a pulley: 0.5 - 0.028 kg; -z loads hang directly: no friction.
    np.testing.assert_allclose(loads[0].force, [0, (0.5 - 0.028) * 9.81, 0], rtol=1e-12)
    np.testing.assert_allclose(loads[2].force, [0, 0, -0.5 * 9.81], rtol=1e-12)
    assert loads[0].cov[1, 1] == pytest.approx((0.008 * 9.81) ** 2)


def test_explicit_positions_and_grid():
    text = EXAMPLE_TOML.replace('preset = "paper48"', "list = [[0, 0, -300], [10, 20, -310]]")
    np.testing.assert_allclose(parse_spec(text).positions.resolve(), [[0, 0, -300], [10, 20, -310]])
    text = EXAMPLE_TOML.replace('preset = "paper48"', "grid = {x = [-100, 100], y = [0], z = [-200, -400]}")
    assert parse_spec(text).positions.resolve().shape == (4, 3)


def _line_of(text: str, needle: str) -> int:
    return next(i for i, ln in enumerate(text.splitlines(), 1) if needle in ln)


@pytest.mark.parametrize(
    "old, new, key, message",
    [
        (
            "square_mm = 10.0\n# its pose",
            "square_mm = -10.0\n# its pose",
            "targets.fixed.square_mm",
            "between 0.01 and 1000 mm",
        ),
        (
            'preset = "paper9"          #',
            'preest = "paper9"          #',
            "loads.preest",
            "did you mean 'preset'",
        ),
        ("repeats = 10 ", 'repeats = "ten" ', "repeats", "valid integer"),
        (  # found by the fuzz tests: as_transform overflowed (R @ R.T) on such an entry
            "fixed2base = [[1.0, 0.0",
            "fixed2base = [[1e300, 0.0",
            "targets.fixed.fixed2base",
            "not a rotation matrix",
        ),
        ('board = "5x4"', 'board = "5by4"', "targets.mobile.board", "COLSxROWS"),
        ('model = "delta"', 'model = "scara"', "robot.model", "'delta', '3prr', 'urdf', 'legs' or 'none'"),
        ("[0.0, -1.0, 0.0, 31.00]", "[0.0, -1.0, 0.5, 31.00]", "targets.fixed.fixed2base", "rotation"),
    ],
)
def test_mistakes_name_key_and_line(old, new, key, message):
    assert old in EXAMPLE_TOML
    text = EXAMPLE_TOML.replace(old, new, 1)
    with pytest.raises(InputError) as info:
        parse_spec(text, source="c/campaign.toml")
    msg = str(info.value)
    assert msg.startswith("c/campaign.toml: ")
    assert f"key {key!r}" in msg and message in msg
    line = (
        _line_of(text, new.split("\n")[0].strip())
        if key != "targets.fixed.fixed2base"
        else _line_of(text, "fixed2base =")
    )
    assert f"line {line}," in msg


def test_missing_section_and_key():
    text = EXAMPLE_TOML.split("[targets.fixed]")[0]
    with pytest.raises(InputError, match=r"needs the section\(s\) \[targets\], \[positions\], \[loads\]"):
        parse_spec(text)
    text = EXAMPLE_TOML.replace("square_mm = 10.0\npoint_mm", "point_mm")
    with pytest.raises(InputError, match=r"key 'targets.mobile.square_mm': missing key"):
        parse_spec(text)


def test_toml_syntax_error_and_missing_file(tmp_path):
    with pytest.raises(InputError, match="not valid TOML"):
        parse_spec("name = ")
    with pytest.raises(InputError, match="no campaign.toml found"):
        load_spec(tmp_path)


def test_pattern_placeholders_are_checked():
    text = EXAMPLE_TOML.replace(
        'loaded = "images/p{position:02d}/l{load:02d}', 'loaded = "images/p{pos:02d}/l{load:02d}'
    )
    with pytest.raises(InputError, match=r"unknown placeholder"):
        parse_spec(text)


def test_position_presets_resolve():
    spec = parse_spec(EXAMPLE_TOML)
    pts = spec.positions.resolve()
    assert pts.shape == (48, 3)
    assert sorted(set(pts[:, 2])) == [-400.0, -310.0, -200.0]
    text = EXAMPLE_TOML.replace('preset = "paper48"', 'preset = "paper50"')
    with pytest.raises(ValueError, match="unknown position preset"):
        parse_spec(text).positions.resolve()


SENSOR_TOML = """\
kind = "sensor"
[sensor]
load_unit = "V"
load_n_per_v = 98.1
window_s = 0.2
recordings = [
  {point = [300.0, 420.0], direction = "x", file = "a.csv", sign = -1, step_times = [[0.5, 2.0], [3.0, 4.5]]},
]
"""


def test_sensor_section_takes_the_step_detector_and_hand_plateaus():

    spec = parse_spec(SENSOR_TOML)
    cfg, _ = sensor_config(spec)
    assert cfg.load_unit == "V" and cfg.load_n_per_v == 98.1 and cfg.window_s == 0.2
    assert spec.sensor.recordings[0].step_times == [(0.5, 2.0), (3.0, 4.5)]
    assert parse_spec(dump_spec(spec)) == spec
    with pytest.raises(InputError, match=r"key 'sensor'.*load_n_per_v"):
        parse_spec(SENSOR_TOML.replace("load_n_per_v = 98.1\n", ""))
    with pytest.raises(InputError, match=r"line 6, key 'sensor.recordings.0.step_times'.*end > start"):
        parse_spec(SENSOR_TOML.replace("[3.0, 4.5]", "[4.5, 3.0]"))


def _rig_spec_text() -> str:
    """The example with [cameras] and {camera} in the image patterns."""
    text = "\n".join(
        ln for ln in EXAMPLE_TOML.splitlines() if not ln.startswith("# ") or "{camera}" not in ln
    )
    text = "\n".join(
        ln for ln in text.splitlines() if not ln.startswith(("#   [cameras]", "#   rig", "# Several"))
    )
    text = text.replace('[camera]\nfile = "camera.json"', '[cameras]\nrig = "rig.json"')
    for state in ("unloaded", "loaded"):
        text = text.replace(f"_{state}.png", f"_{state}_{{camera}}.png")
    return text


def test_cameras_section_takes_a_rig_and_patterns_with_camera():
    spec = parse_spec(_rig_spec_text())
    assert spec.camera is None and spec.cameras.rig == "rig.json"
    assert spec.images.per_camera
    # The image set's name keeps {camera}; stiffmap.rig.camera_path gives each camera's file.
    from stiffmap.rig import camera_path

    rel = spec.images.path("loaded", 3, 2, 1)
    assert "{camera}" in rel and camera_path(rel, "left").endswith("_loaded_left.png")
    spec = parse_spec(_rig_spec_text().replace('rig = "rig.json"', 'rig = "rig.json"\nnames = ["l", "r"]'))
    assert spec.cameras.names == ["l", "r"]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("[cameras]", '[camera]\nfile = "camera.json"\n\n[cameras]'), "not both"),
        (lambda t: t.replace("_loaded_{camera}.png", "_loaded.png"), "must hold {camera}"),
        (lambda t: t.replace("{camera}", "{camera:>4}", 1), "without a format"),
        (
            lambda t: t.replace('rig = "rig.json"', 'rig = "rig.json"\nnames = ["a/b"]'),
            "usable in a file name",
        ),
        (lambda t: t.replace('rig = "rig.json"', 'rig = "rig.json"\nnames = ["a", "a"]'), "listed twice"),
        (lambda t: t.replace('rig = "rig.json"', 'rig = "rig.json"\nnames = []'), "at least one camera"),
    ],
)
def test_cameras_mistakes_are_named(edit, message):
    with pytest.raises(InputError, match=message):
        parse_spec(edit(_rig_spec_text()))


def test_camera_placeholder_needs_a_cameras_section():
    text = EXAMPLE_TOML.replace("_loaded.png", "_loaded_{camera}.png")
    with pytest.raises(InputError, match=r"needs a \[cameras\] section"):
        parse_spec(text)


def test_plan_names_each_cameras_file_and_misses_only_empty_sets(tmp_path):
    from stiffmap.campaign.positions import plan

    text = _rig_spec_text().replace('preset = "paper48"', "list = [[0, 0, -300]]")
    spec = parse_spec(text)
    tasks = plan(spec, tmp_path, cameras=("left", "right"))
    (t,) = tasks
    assert len(t.missing) == len(t.images)  # nothing on disk
    first = t.images[0]
    files = t.files(first)
    assert [f.rsplit("_", 1)[1] for f in files] == ["left.png", "right.png"]
    (tmp_path / files[1]).parent.mkdir(parents=True, exist_ok=True)
    (tmp_path / files[1]).write_bytes(b"x")  # one camera's file: the set is there, measured with it
    (t,) = plan(spec, tmp_path, cameras=("left", "right"))
    assert first not in t.missing and len(t.missing) == len(t.images) - 1
