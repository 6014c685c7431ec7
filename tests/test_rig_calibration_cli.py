"""calibrate-rig on image files: matching views across cameras, the command, its bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.cli_process import assert_one_line_error, run_stiffmap
from helpers.fuzz import FuzzCase, assert_handled, run_argv, run_case
from helpers.rig_views import BOARD, rendered_rig
from hypothesis import given
from hypothesis import strategies as st

from stiffmap.errors import InputError
from stiffmap.geometry import rotvec_from_matrix
from stiffmap.rig import load_rig
from stiffmap.vision.files import calibrate_rig_files, camera_images, match_views
from stiffmap.vision.rig_calibration import NO_IMAGE

BOARD_ARGS = ("--board", "9x6", "--square-mm", "30")


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


@pytest.fixture(scope="module")
def pngs() -> dict[str, bytes]:
    """The rendered 60-degree rig of seed 1 as files: left01.png ... left14.png, right01..13, right15."""
    r = rendered_rig("60deg", 1)
    out = {}
    for k, name in enumerate(r.rig.names):
        for v, img in enumerate(r.images[k]):
            if img is not None:
                out[f"{name}{v + 1:02d}.png"] = _png(img)
    return out


@pytest.fixture
def lab(tmp_path, pngs) -> Path:
    for name, data in pngs.items():
        (tmp_path / name).write_bytes(data)
    return tmp_path


def _cameras(d: Path) -> tuple[str, ...]:
    return ("--camera", f"left={d}/left*.png", "--camera", f"right={d}/right*.png")


# ------------------------------------------------------------------------- matching views
def test_views_are_matched_by_the_number_in_the_file_names():
    left = [Path(f"img/left{i:02d}.jpg") for i in (1, 2, 3, 7, 10)]
    right = [Path(f"img/right{i}.jpg") for i in (2, 3, 7, 10, 11)]  # no 01, an 11; no zero padding
    views, table = match_views(["left", "right"], [left, right])
    assert views == ["1", "2", "3", "7", "10", "11"]
    assert table[0] == [*left[:5], None]
    assert table[1] == [None, *right]
    # The last group of digits counts (a camera number or a date before it does not).
    views, table = match_views(["a", "b"], [[Path("cam1_2024_05.png")], [Path("cam2_2024_05.png")]])
    assert views == ["5"] and table == [[Path("cam1_2024_05.png")], [Path("cam2_2024_05.png")]]


def test_views_are_matched_by_order_when_names_carry_no_numbers():
    a = [Path("a_first.png"), Path("a_second.png")]
    b = [Path("b_one.png"), Path("b_two.png")]
    assert match_views(["a", "b"], [a, b]) == (["1", "2"], [a, b])
    with pytest.raises(
        InputError,
        match=r"a_first.png \(camera a\) has no number.*different numbers of images \(a: 2, b: 3\)",
    ):
        match_views(["a", "b"], [a, [*b, Path("b_three.png")]])
    dup = [Path("x1.png"), Path("y1.png"), Path("z2.png")]
    with pytest.raises(InputError, match=r"carry the same number 1"):
        match_views(["a", "b"], [dup, a])


def test_camera_images_are_a_pattern_a_folder_or_a_file(tmp_path):
    for i in (1, 2, 10):
        (tmp_path / f"left{i}.png").write_bytes(b"x")
    (tmp_path / "notes.txt").write_text("x")
    names = [p.name for p in camera_images("left", str(tmp_path / "left*.png"))]
    assert names == ["left1.png", "left2.png", "left10.png"]  # natural order
    assert [p.name for p in camera_images("left", tmp_path)] == names  # a folder: its images
    assert camera_images("left", tmp_path / "left2.png") == [tmp_path / "left2.png"]
    with pytest.raises(InputError, match=r"camera left: no file matches the pattern '.*right\*.png'"):
        camera_images("left", str(tmp_path / "right*.png"))
    with pytest.raises(InputError, match=r"camera left: '.*nowhere' is no file, folder or file pattern"):
        camera_images("left", str(tmp_path / "nowhere"))


def test_rig_files_with_a_view_missing_and_an_image_without_the_board(lab):
    # right14.png does not exist (view 14 is the left camera's alone); a blank image has no board.
    cv2.imwrite(str(lab / "right16.png"), np.full((480, 640), 128, np.uint8))
    res = calibrate_rig_files([("left", f"{lab}/left*.png"), ("right", lab / "right*.png")], BOARD)
    assert res.view_names == tuple(str(i) for i in range(1, 17))
    assert res.views[1][13].reason == NO_IMAGE and res.views[0][13].used
    assert res.views[0][15].reason == NO_IMAGE
    assert not res.views[1][15].used and res.views[1][15].image.endswith("right16.png")
    assert "board" in res.views[1][15].reason or "not found" in res.views[1][15].reason
    assert res.n_used == (14, 14)


def test_a_camera_whose_images_differ_in_size_is_named(lab):
    cv2.imwrite(str(lab / "left20.png"), np.full((240, 320), 128, np.uint8))
    with pytest.raises(
        InputError, match=r"camera left: its images are not all of one size: .*left20.png is 320x240"
    ):
        calibrate_rig_files([("left", f"{lab}/left[02][0-3].png"), ("right", f"{lab}/right*.png")], BOARD)


# -------------------------------------------------------------------------------- command
def test_calibrate_rig_writes_rig_json_and_prints_the_stereo_result(lab):
    out = lab / "rig.json"
    p = run_stiffmap("calibrate-rig", *_cameras(lab), *BOARD_ARGS, "--out", out, columns=100)
    assert p.returncode == 0, p.stderr
    assert p.stderr.strip() == ""
    rig = load_rig(out)
    truth = rendered_rig("60deg", 1).rig
    assert rig.names == ("left", "right") and rig.cov is not None
    T, T0 = rig.cameras[1].cam2rig, truth.cameras[1].cam2rig
    s = np.sqrt(np.diag(rig.cov[rig.extrinsic_slice(1), rig.extrinsic_slice(1)]))
    e = np.r_[T[:3, 3] - T0[:3, 3], rotvec_from_matrix(T[:3, :3] @ T0[:3, :3].T)]
    assert np.all(np.abs(e) < 4 * s)
    text = p.stdout
    for needle in (
        "cameras (model k3)",
        "camera poses in the rig frame",
        "Intrinsic parameters of right camera:",
        "Extrinsic parameters (position of right camera wrt left camera):",
        "Rotation vector:             om = [",
        "Translation vector:           T = [",
        f"wrote {out}",
    ):
        assert needle in text, needle
    # The views table: view 14 is the left camera's alone, 15 the right's.
    row14 = next(line for line in text.splitlines() if line.startswith("│ 14 "))
    assert "│ -" in row14


def test_calibrate_rig_from_folders_names_the_image_it_left_out(lab):
    # Views 1-5 of each camera in a folder of its own, and an image without the board.
    for name in ("left", "right"):
        (lab / name).mkdir()
        for i in range(1, 6):
            shutil.move(str(lab / f"{name}{i:02d}.png"), lab / name)
    cv2.imwrite(str(lab / "left" / "left16.png"), np.full((480, 640), 128, np.uint8))
    out = lab / "rig.json"
    cams = ("--camera", f"left={lab}/left", "--camera", f"right={lab}/right")
    p = run_stiffmap("calibrate-rig", *cams, *BOARD_ARGS, "--out", out, "--json")
    assert p.returncode == 0, p.stderr  # a good calibration that left a view out: a note, status 0
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("note: "), p.stderr
    assert "left16.png: not used by camera left" in lines[0]
    # --json prints the object rig.json holds.
    obj = json.loads(p.stdout)
    assert obj == json.loads(out.read_text())
    assert [c["name"] for c in obj["cameras"]] == ["left", "right"]
    assert obj["cov"]["params"][-1] == "right.rz"
    assert obj["outliers"] == [] and set(obj["rms_px"]) == {"left", "right"}


def _one_line(o, *needles: str) -> None:
    """An in-process run (helpers.fuzz.run_argv) ended in exit 2 with one error line holding the needles."""
    assert o.code == 2 and o.escaped is None, (o.code, o.stderr)
    lines = [ln for ln in o.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), o.stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])


def test_bad_camera_options_give_one_line(lab):
    good = f"right={lab}/right*.png"
    p = run_stiffmap("calibrate-rig", "--camera", "left", "--camera", good, *BOARD_ARGS)
    assert p.returncode == 2
    assert_one_line_error(p, "--camera 'left': expected NAME=GLOB")
    cases = [
        (["--camera", f"={lab}/left*.png"], "the camera's name before '=' is missing"),
        (["--camera", "left="], "the images after '=' are missing"),
        (["--camera", "le\x07ft=x.png"], "cannot be printed"),
        (["--camera", f"left={lab}/nothing*.png"], "camera left: no file matches the pattern"),
        (
            ["--camera", f"left={lab}/left*.png", "--camera", f"left={lab}/right*.png"],
            "camera left is given twice",
        ),
        (["--camera", f"left={lab}/left*.png", "--model", "k9"], "--model must be one of k3, fix-k3"),
    ]
    for argv, needle in cases:
        _one_line(run_argv(["calibrate-rig", *argv, *BOARD_ARGS, "--out", str(lab / "r.json")]), needle)


def test_bad_image_sets_give_one_line(lab):
    (lab / "empty").mkdir()
    out = ["--out", str(lab / "r.json")]
    cams = ("--camera", f"left={lab}/empty", "--camera", f"right={lab}/right*.png")
    _one_line(run_argv(["calibrate-rig", *cams, *BOARD_ARGS, *out]), "empty", "holds no image files")
    # Too few views for a camera.
    cams = ("--camera", f"left={lab}/left0[1-4].png", "--camera", f"right={lab}/right0[12].png")
    _one_line(
        run_argv(["calibrate-rig", *cams, *BOARD_ARGS, *out]),
        "camera right: calibration needs at least 3 views with the board found, got 2",
    )
    # Views 1-4 for the left camera, 4-7 for the right: one shared view.
    cams = ("--camera", f"left={lab}/left0[1-4].png", "--camera", f"right={lab}/right0[4-7].png")
    p = run_stiffmap("calibrate-rig", *cams, *BOARD_ARGS, *out)
    assert p.returncode == 2
    assert_one_line_error(p, "camera right shares 1 usable view(s) with camera left", "at least 2 views")


# ----------------------------------------------------------------------------------- fuzz
_NAME = st.text(st.characters(blacklist_characters="*?[=", blacklist_categories=("Cs",)), max_size=8)
_PATTERN = st.sampled_from(
    [
        "{dir}/left*.png",
        "{dir}/right0[1-4].png",
        "{dir}",
        "{dir}/left02.png",
        "{dir}/none*.png",
        "",
        " ",
        "{dir}/[",
    ]
)
_CAMERA = st.one_of(
    st.text(st.characters(blacklist_characters="*?[", blacklist_categories=("Cs",)), max_size=16),
    st.builds(lambda n, s, p: f"{n}{s}{p}", _NAME, st.sampled_from(["=", "==", " = ", ""]), _PATTERN),
)


@pytest.mark.fuzz
def test_camera_options_end_in_a_clear_message_or_a_rig(pngs, tmp_path, monkeypatch):
    """Any --camera text: a rig (the images valid) or one clear error naming what is wrong."""
    monkeypatch.chdir(tmp_path)  # a relative pattern finds nothing of the repository's
    files = {k: v for k, v in pngs.items() if k[-6:-4] in ("01", "02", "03", "04")}

    @given(_CAMERA, _CAMERA)
    def run(a: str, b: str) -> None:
        case = FuzzCase(
            files, ("calibrate-rig", "--camera", a, "--camera", b, *BOARD_ARGS, "--out", "{dir}/r.json")
        )
        o = run_case(case)
        assert_handled(case, o)
        if o.kind == "ok":
            assert "Translation vector:" in o.stdout

    run()
