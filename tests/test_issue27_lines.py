"""One clear line for what issue 27's audit found worded deep inside or not naming the file.

- a JSON file given where a CSV table is expected said "missing columns 'x', 'y' (header has
  '{"a":1}')"; now it says it is JSON;
- ``model legs ... --grid`` on a robot without grid presets offered "a preset ()";
- ``displacement``'s "the fixed target moved" did not name the images it is about.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import close_two_target_poses, moved_pose, small_camera
from helpers.fuzz import run_argv

from stiffmap.camera import save_camera
from stiffmap.errors import InputError
from stiffmap.io import read_csv_columns
from stiffmap.models.presets import paper48
from stiffmap.targets import Chessboard

DELTA_TOML = "src/stiffmap/models/robots/delta.toml"


def _one_error(o) -> str:
    (line,) = o.stderr.strip().splitlines()
    assert o.code == 2 and line.startswith("error: "), o.stderr
    return line


def test_positions_written_as_json_where_a_csv_belongs_are_called_json(tmp_path):
    points = paper48()
    f = tmp_path / "points.csv"
    f.write_text(
        json.dumps({"x": points[:, 0].tolist(), "y": points[:, 1].tolist(), "z": points[:, 2].tolist()})
    )
    line = _one_error(run_argv(["model", "delta", "--points", str(f)]))
    assert line == (
        f"error: {f}: is a JSON file, not a CSV table; expected a header row with columns x, y, z "
        "and one row of numbers per line"
    )
    # The same positions as a CSV table are read (the message is about the format, not the numbers).
    f.write_text("x,y,z\n" + "".join(",".join(map(str, p)) + "\n" for p in points))
    assert run_argv(["model", "delta", "--points", str(f)]).code == 0


def test_a_truncated_json_list_is_said_to_look_like_json(tmp_path):
    f = tmp_path / "forces.csv"
    f.write_text('\ufeff [{"fx": 1.0, "fy": 2')
    with pytest.raises(InputError, match=r"looks like JSON \(it begins with '\['\), not a CSV table") as e:
        read_csv_columns(f, ["fx", "fy", "fz"])
    assert str(f) in str(e.value)


def test_a_grid_for_a_robot_without_presets_offers_no_empty_preset_list():
    line = _one_error(run_argv(["model", "legs", DELTA_TOML, "--grid", "paper"]))
    assert "preset" not in line and "--grid 'paper': expected 3 comma-separated axes" in line
    line = _one_error(run_argv(["model", "delta", "--grid", "paper"]))
    assert "expected a preset (paper48) or 3 comma-separated axes" in line


def test_the_fixed_targets_move_names_the_images(tmp_path):
    cam = small_camera()
    mobile, fixed = Chessboard(7, 6, 10.0), Chessboard(9, 4, 10.0)
    save_camera(cam, tmp_path / "camera.json")
    M0, F = close_two_target_poses(mobile, fixed)
    (tmp_path / "fixed2base.json").write_text(json.dumps({"fixed2base": np.eye(4).tolist()}))
    rng = np.random.default_rng(3)
    F1 = moved_pose(F, np.array([0.4, 0.0, 0.0, 0, 0, 0]))  # the camera (or the base) moved
    for name, fT, mT in (("ref", F, M0), ("moved", F1, moved_pose(M0, np.r_[0.2, 0, 0, 0, 0, 0]))):
        cv2.imwrite(
            str(tmp_path / f"{name}.png"), quick_board_image(cam, [(fixed, fT), (mobile, mT)], rng=rng)
        )
    argv = ["displacement", "--camera", str(tmp_path / "camera.json"), "--board", "7x6", "--square-mm", "10"]
    argv += [
        "--fixed-board",
        "9x4",
        "--fixed-square-mm",
        "10",
        "--fixed2base",
        str(tmp_path / "fixed2base.json"),
    ]
    o = run_argv([*argv, "--reference", str(tmp_path / "ref.png"), str(tmp_path / "moved.png")])
    (line,) = [ln for ln in o.stderr.splitlines() if "fixed target moved" in ln]
    assert line.startswith(f"warning: reference {tmp_path / 'ref.png'} -> {tmp_path / 'moved.png'}: "), line


def test_help_paragraphs_are_wrapped_by_rich_and_only_bullets_keep_their_lines():
    from helpers.cli_process import run_stiffmap

    from stiffmap.cli.main import _unwrapped

    doc = """Summary.

    Text wrapped at the source's width
    --points with x, y, z: an option at a line's start is no bullet.

    - a bullet whose text
      goes on here
    * another
    """
    assert _unwrapped(doc).split("\n\n")[1:] == [
        "Text wrapped at the source's width --points with x, y, z: an option at a line's start is no bullet.",
        "- a bullet whose text goes on here\n* another",
    ]
    proc = run_stiffmap("model", "--help", columns=80)
    text = proc.stdout.split("╭─ Arguments")[0]
    lines = [ln.strip() for ln in text.splitlines()]
    # rich fills each line of a paragraph; a short line is only the last of its paragraph.
    ragged = [a for a, b in zip(lines, lines[1:], strict=False) if a and b and len(a) < 50]
    assert ragged == [] and "turn), K_rot a pure moment's" in " ".join(lines), text


def test_a_long_model_map_without_a_terminal_prints_a_progress_line_every_interval(monkeypatch):
    """``model legs --grid`` of 10^6 poses ran ~25 min printing nothing when stderr was no terminal."""
    from stiffmap.cli import common
    from stiffmap.cli import model as cli_model

    argv = ["model", "legs", DELTA_TOML, "--grid=-100:100:6,-100:100:10,-300", "--json"]
    whole = run_argv(argv)  # 60 poses: one chunk, no progress
    assert whole.code == 0 and whole.stderr == "", whole.stderr
    monkeypatch.setattr(cli_model, "CHUNK_POSES", 20)
    monkeypatch.setattr(common, "PROGRESS_LINE_S", 0.0)  # a line after every chunk, not every 10 s
    o = run_argv(argv)
    assert o.code == 0 and o.stdout == whole.stdout  # the same map, chunk by chunk
    lines = o.stderr.splitlines()
    assert [ln.split(",")[0] for ln in lines] == ["poses: 20 of 60 (33 %)", "poses: 40 of 60 (67 %)"], lines
    assert all(ln.endswith(" left") for ln in lines)
