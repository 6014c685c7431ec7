"""Exit statuses and the messages that come with them, the same for every command
(CONTRIBUTING.md, "Exit statuses"): 0 done, 1 done with warnings or flagged results, 2 the
user's input is wrong (one ``error:`` line), 3 a bug.

The newcomer's cases of issue 26, item 7, each failing on the code before it: ``calibrate``
exited 1 after a good calibration that merely left views out; ``identify`` exited 0 with
det K < 0 and no hint of a reversed axis; a rig file given to ``--camera`` was answered
"missing keys 'image_size', 'fx'..."; a misspelt folder was called an "image file";
``model delta`` evaluated z = +300 mm (above the base) as ok. (``run`` printing a warning
after "done" is checked on a sensor campaign in ``tests/test_campaign_sensor.py``.)
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from helpers.board_scenes import small_camera
from helpers.cli_process import assert_one_line_error, run_in_process, run_stiffmap
from helpers.shared_data import CALIB_DIR, REPO

from stiffmap.cli import common
from stiffmap.identify import AXES, flipped_axes, identify_stiffness, physical_flags
from stiffmap.loads import forces_matrix, paper9
from stiffmap.models.delta import DeltaRobot
from stiffmap.rig import Rig, RigCamera, save_rig

K_TRUE = np.array([[3.1, 0.4, 0.2], [0.4, 2.2, -0.3], [0.2, -0.3, 5.0]])  # N/mm, SPD


def _csv(path, header, rows):
    path.write_text(
        ",".join(header) + "\n" + "\n".join(",".join(str(float(x)) for x in r) for r in rows) + "\n"
    )
    return path


# ------------------------------------------------------------------ the statuses themselves
def test_a_warning_makes_the_status_1_and_a_note_does_not(monkeypatch, capsys, tmp_path):
    """The one rule, in cli.main: a command that printed a ``warning:`` line and would end
    with 0 ends with 1; a ``note:`` changes nothing."""
    assert (common.EXIT_OK, common.EXIT_WARNINGS, common.EXIT_INPUT, common.EXIT_BUG) == (0, 1, 2, 3)
    pts = tmp_path / "p.csv"
    pts.write_text("x,y,z\n0,0,-300\n")
    code, out, err = run_in_process(["model", "delta", "--points", pts], monkeypatch, capsys)
    assert code == 0 and not err
    common.reset_warnings()
    common.note("a note")
    assert common.warnings_printed() == 0
    common.warn("a warning")
    assert common.warnings_printed() == 1
    # A new command line starts counting again.
    code, _, _ = run_in_process(["model", "delta", "--points", pts], monkeypatch, capsys)
    assert code == 0


# ------------------------------------------------------------------ calibrate
def test_calibrate_a_good_calibration_that_left_a_view_out_exits_0(tmp_path, monkeypatch, capsys):
    """Four real views of calib_example (Bouguet) and an image without a board: the
    calibration is good, the left-out view is a note, the status 0 (it was 1)."""
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640), 90, np.uint8))
    files = [CALIB_DIR / f"Image{i}.tif" for i in (1, 2, 3, 4)]
    out = tmp_path / "camera.json"
    args = ["calibrate", *files, blank, "--board", "13x12", "--square-mm", "30", "--out", out]
    code, _, err = run_in_process(args, monkeypatch, capsys)
    assert code == 0, err
    assert "note: not used: " in err and "blank.png: no 13x12 chessboard" in err
    assert "warning:" not in err
    cam = json.loads(out.read_text())
    assert sum(v["used"] for v in cam["views"]) == 4
    assert abs(cam["fx"] - 657.46) < 10.0  # px, Bouguet's published fc(1) 657.46 (four views only)


# ------------------------------------------------------------------ identify: det K < 0
def test_flipped_axes_finds_each_reversed_axis_and_only_it():
    rng = np.random.default_rng(4)
    for m in (3, 6):
        A = rng.normal(size=(m, m))
        K = A @ A.T + m * np.eye(m)  # SPD
        assert flipped_axes(K) == ()
        for axes in [(i,) for i in range(m)] + [(0, 2)]:
            S = np.ones(m)
            S[list(axes)] = -1
            # A displacement of the wrong sign (columns negated) or a load (rows negated).
            assert flipped_axes(K * S[None, :]) == (axes,), (m, axes)
            assert flipped_axes(S[:, None] * K) == (axes,), (m, axes)
    hint = physical_flags(K_TRUE * np.array([1.0, -1.0, 1.0])[None, :])[-1]
    assert hint.startswith("axis sign:") and "the y axis" in hint and "dy or fy" in hint
    assert "K[y,y] = -2.2 < 0" in hint
    assert "every axis" in physical_flags(-K_TRUE)[-1]
    assert AXES[6][3:] == ("rx", "ry", "rz")


def test_identify_flags_a_reversed_axis_and_exits_1(tmp_path, monkeypatch, capsys):
    """dy recorded with the wrong sign (a camera axis the other way): det K < 0, flagged, the
    y axis named, status 1 (it was 0, with no hint)."""
    F = forces_matrix(paper9())
    D = np.linalg.solve(K_TRUE, F) + np.random.default_rng(2).normal(scale=1e-3, size=F.shape)
    D[1] *= -1
    fit = identify_stiffness(F, D)
    assert fit.indices.det < 0
    forces = _csv(tmp_path / "forces.csv", ["fx", "fy", "fz"], F.T)
    disp = _csv(tmp_path / "disp.csv", ["dx", "dy", "dz"], D.T)
    code, out, err = run_in_process(["identify", forces, disp], monkeypatch, capsys)
    assert code == 1, err
    line = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    assert len(line) == 1 and "forces.csv" in line[0] and "disp.csv" in line[0]
    assert "the y axis (dy or fy of the wrong sign) looks reversed" in " ".join(err.split())
    assert "det <= 0" in out and "axis sign:" in out
    # With the sign put right: no flag, status 0.
    D[1] *= -1
    _csv(disp, ["dx", "dy", "dz"], D.T)
    code, out, _ = run_in_process(["identify", forces, disp, "--json"], monkeypatch, capsys)
    assert code == 0 and json.loads(out)["flags"] == []


# ------------------------------------------------------------------ files and folders
def test_a_rig_file_given_to_camera_is_named_as_such(tmp_path):
    cam = small_camera()
    T = np.eye(4)
    T[0, 3] = 120.0
    rig = tmp_path / "rig.json"
    save_rig(Rig((RigCamera("left", cam, np.eye(4)), RigCamera("right", cam, T))), rig)
    proc = run_stiffmap("pose", tmp_path / "x.png", "--camera", rig, "--board", "7x6", "--square-mm", "10")
    assert proc.returncode == 2
    line = assert_one_line_error(proc, "--camera", "rig.json", "this is a rig file", "'left', 'right'")
    assert f"use --rig {rig}" in line and "missing key" not in line


def test_a_misspelt_folder_is_no_such_file_or_folder_with_the_closest_name(tmp_path, monkeypatch, capsys):
    (tmp_path / "calib_images").mkdir()
    code, _, err = run_in_process(
        [
            "calibrate",
            tmp_path / "calib_imgaes",
            "--board",
            "9x6",
            "--square-mm",
            "25",
            "--out",
            tmp_path / "c.json",
        ],
        monkeypatch,
        capsys,
    )
    assert code == 2
    assert "calib_imgaes: no such file or folder" in err and "image file" not in err
    assert f"did you mean {str(tmp_path / 'calib_images')!r}?" in err


# ------------------------------------------------------------------ model delta above its base
def test_the_delta_refuses_a_point_above_its_base_by_name():
    """The Delta hangs below its base (z < 0 in its frame): z = +300 mm has a mirror solution
    of the closed-form kinematics (the arms folded up through the base) that was returned as ok."""
    d = DeltaRobot()
    m = d.evaluate(np.array([[0.0, 0.0, 300.0], [0.0, 0.0, -300.0], [0.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(m.valid, [False, True, False])
    assert "z = +300 mm is at or above the base" in m.reasons[0]
    assert "leg 1 too close" in m.reasons[2]  # out of reach anyway: the legs say why
    # The mirror point is reached by every leg's closed form: only the side of the base is wrong.
    assert np.all(np.isfinite(d.legs(np.array([[0.0, 0.0, -300.0]])).theta))


def test_model_delta_at_z_plus_300_exits_1_naming_the_point(tmp_path, monkeypatch, capsys):
    pts = tmp_path / "p.csv"
    pts.write_text("x,y,z\n0,0,300\n0,0,-300\n")
    code, out, err = run_in_process(["model", "delta", "--points", pts, "--json"], monkeypatch, capsys)
    assert code == 1
    rows = json.loads(out)
    assert "above the base" in json.dumps(rows[0]) and rows[1]["z"] == -300.0 and "uz" in rows[1]
    assert "warning:" in err


@pytest.mark.parametrize("status", [0, 1, 2, 3])
def test_contributing_and_readme_document_every_status(status):
    for doc in ("CONTRIBUTING.md", "README.md"):
        text = (REPO / doc).read_text()
        assert "Exit statuses" in text or "exit status" in text.lower()
        section = text[text.lower().index("exit status") :][:2500]
        assert f"`{status}`" in section, (doc, status)
