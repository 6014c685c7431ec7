"""Measuring with a rig of cameras: fused poses from rendered images, one camera as before, bad input.

Two 1280x960 cameras 60 degrees apart (``helpers.rig_scenes``) see an 8x6 mobile board and a
9x7 fixed board rendered by the virtual test-bed; the truth is the poses they were rendered
at. The command line is run as a user would (``run_stiffmap``) on files of such images.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.board_images import testbed_board_image as render_board
from helpers.board_scenes import close_two_target_poses, moved_pose, small_camera
from helpers.cli_process import assert_one_line_error, run_stiffmap
from helpers.fuzz import run_argv
from helpers.rig_scenes import board2cams, board_in_rig, rig_camera, stereo_rig

from stiffmap.camera import CameraModel
from stiffmap.errors import InputError
from stiffmap.geometry import displacement_from_poses, rotvec_from_matrix
from stiffmap.rig import Rig, save_rig
from stiffmap.targets import Chessboard
from stiffmap.vision import PoseTracker, detect_boards, estimate_pose
from stiffmap.vision.board_plane import detection_mask
from stiffmap.vision.files import match_views, rig_image_sets
from stiffmap.vision.fuse import FusedPose

MOBILE = Chessboard(8, 6, 10.0)
FIXED = Chessboard(9, 7, 8.0)
FIXED2BASE = np.array([[0.0, -1, 0, 100], [1, 0, 0, -50], [0, 0, 1, 20], [0, 0, 0, 1]])


def _truth_frame(T_true, T_meas):
    """The 8x6 board's numbering is not fixed by its colours: the true pose in the measured one."""
    if T_true[:3, 0] @ T_meas[:3, 0] > 0:
        return T_true
    S = np.diag([-1.0, -1.0, 1.0, 1.0])
    S[:2, 3] = [(MOBILE.cols - 1) * MOBILE.square_mm, (MOBILE.rows - 1) * MOBILE.square_mm]
    return T_true @ S


def _error(T_meas, T_true):
    T = _truth_frame(T_true, T_meas)
    return np.r_[T_meas[:3, 3] - T[:3, 3], rotvec_from_matrix(T_meas[:3, :3] @ T[:3, :3].T)]


@pytest.fixture(scope="module")
def scene():
    """Rendered image sets: [unloaded, loaded, loaded without the fixed board in camera 1]."""
    rng = np.random.default_rng(12)
    rig = stereo_rig(rig_camera())
    M0 = board_in_rig(MOBILE, tilt_deg=(5, -4, 12), offset_mm=(8, -5))
    M1 = moved_pose(M0, [0.02, -0.01, 0.03, 2e-5, 0, -1e-5])
    F = board_in_rig(FIXED, tilt_deg=(-3, 6, -2), offset_mm=(-95, 45))
    sets = []
    for M, fixed_in in ((M0, (True, True)), (M1, (True, True)), (M1, (False, True))):
        ims = []
        for k, (Mc, Fc) in enumerate(zip(board2cams(rig, M), board2cams(rig, F), strict=True)):
            boards = [(MOBILE, Mc)] + ([(FIXED, Fc)] if fixed_in[k] else [])
            ims.append(render_board(rig.cameras[k].camera, boards, rng))
        sets.append(ims)
    return rig, (M0, M1, F), sets


# ------------------------------------------------------------------------ one camera
def test_one_camera_measures_as_before_and_as_a_rig_of_it():
    """PoseTracker(camera) gives what detection and estimate_pose give for that camera (the
    single-camera path as it was: exactly on the first image, well within a sigma once its
    photometric fit starts warm from the previous image's), and a rig of that one camera gives
    the same as the camera, to 1e-12."""
    rng = np.random.default_rng(3)
    d = small_camera().to_dict()
    d["std"] = {"fx": 0.8, "fy": 0.8, "cx": 0.5, "cy": 0.5, "dist": [2e-3, 5e-3, 1e-4, 1e-4, 0.0]}
    cam = CameraModel.from_dict(d)
    mob, fix = Chessboard(8, 6, 4.0), Chessboard(9, 7, 4.0)
    M, F = close_two_target_poses(mob, fix)
    ims = [
        render_board(cam, [(mob, moved_pose(M, [0.01 * i, 0, 0, 0, 0, 0])), (fix, F)], rng) for i in range(2)
    ]
    # The single-camera path, step by step.
    expected, prev = [], None
    for im in ims:
        dets = detect_boards(im, [mob, fix], previous=prev, reference=prev, camera=cam, source="x")
        poses = []
        for j, (dt, b) in enumerate(zip(dets, (mob, fix), strict=True)):
            other = [detection_mask(dets[1 - j], margin_sq=2.2)]
            init = expected[-1][j].board2cam if (dt.tracked and expected) else None
            poses.append(estimate_pose(dt, b, cam, initial=init, source="x", image=im, exclude=other))
        expected.append(poses)
        prev = dets
    got_by = {}
    for camera in (cam, Rig.single(cam)):
        tracker = PoseTracker(camera, mob, fix, FIXED2BASE)
        got_by[type(camera).__name__] = ms = [tracker.measure(im, "x") for im in ims]
        for i, (m, (pm, pf)) in enumerate(zip(ms, expected, strict=True)):
            assert m.ok and len(m.views) == 1 and isinstance(m.mobile, FusedPose)
            for got, want in ((m.mobile, pm), (m.fixed, pf)):
                assert got.method == want.method == "photometric"
                if i == 0:  # a full detection and a cold fit: the step-by-step path exactly
                    np.testing.assert_allclose(got.board2rig, want.board2cam, rtol=0, atol=1e-12)
                    np.testing.assert_allclose(got.cov, want.cov, rtol=1e-12, atol=0)
                    np.testing.assert_allclose(
                        got.calibration_jacobian, want.calibration_jacobian, rtol=1e-12, atol=0
                    )
                else:  # the tracker's fit starts warm from the previous image's: the same pose
                    e = _error(got.board2rig, want.board2cam)
                    # Two fits of one image, each stopped within 0.1 sigma of its optimum: the
                    # same pose well within one sigma (chi2 of the difference 0.41 measured).
                    assert e @ np.linalg.solve(want.cov, e) < 1.0
                    sg, sw = np.sqrt(np.diag(got.cov)), np.sqrt(np.diag(want.cov))
                    np.testing.assert_allclose(sg, sw, rtol=0.05)  # standard deviations
                    np.testing.assert_allclose(
                        got.cov / np.outer(sg, sg), want.cov / np.outer(sw, sw), atol=0.05
                    )
            np.testing.assert_allclose(m.calibration_cov, cam.calibration_cov, rtol=0, atol=0)
            assert m.mobile2base is not None and m.mobile2base_calibration_jacobian.shape == (6, 9)
    # A rig of one camera measures as that camera, to rounding.
    for a, b in zip(got_by["CameraModel"], got_by["Rig"], strict=True):
        for p, q in ((a.mobile, b.mobile), (a.fixed, b.fixed)):
            np.testing.assert_allclose(p.board2rig, q.board2rig, rtol=0, atol=1e-12)
            np.testing.assert_allclose(p.cov, q.cov, rtol=1e-12, atol=0)


# ----------------------------------------------------------------------- two cameras
def test_two_cameras_fuse_within_their_sigma_and_beat_camera_1_along_its_line_of_sight(scene):
    rig, (M0, M1, F), sets = scene
    tracker = PoseTracker(rig, MOBILE, FIXED, FIXED2BASE)
    alone = PoseTracker(rig.cameras[0].camera, MOBILE, FIXED, FIXED2BASE)
    ms = [tracker.measure(s, f"set{i}") for i, s in enumerate(sets[:2])]
    ma = [alone.measure(s[0], f"set{i}") for i, s in enumerate(sets[:2])]
    for m, a, T in zip(ms, ma, (M0, M1), strict=True):
        assert m.ok and m.mobile.cameras == ("left", "right") and m.fixed.cameras == ("left", "right")
        assert [v.method for v in m.mobile.views] == ["photometric", "photometric"]
        assert m.mobile.consistency_warning is None and m.fixed.consistency_warning is None
        e = _error(m.mobile.board2rig, T)
        # Within its stated sigma: chi2 over the 6 pose parameters below its 99.9 % quantile.
        assert e @ np.linalg.solve(m.mobile.cov, e) < 22.5
        ef = _error(m.fixed.board2rig, F)
        assert ef @ np.linalg.solve(m.fixed.cov, ef) < 22.5
        # Along camera 1's line of sight (the rig's z): far better than camera 1 alone.
        ea = _error(a.mobile.board2rig, T)
        assert abs(e[2]) < abs(ea[2])
        assert np.sqrt(m.mobile.cov[2, 2]) < 0.2 * np.sqrt(a.mobile.cov[2, 2])
        assert m.calibration_cov is None and m.mobile.cov_calibration is None  # exact cameras
        assert m.mobile2base_calibration_jacobian.shape == (6, len(rig.param_names))
    # The displacement between the two sets, rig frame, within 3 sigma per axis.
    d = displacement_from_poses(ms[0].mobile2cam, ms[1].mobile2cam)
    truth = displacement_from_poses(_truth_frame(M0, ms[0].mobile2cam), _truth_frame(M1, ms[1].mobile2cam))
    sig = np.sqrt(np.diag(ms[0].mobile.cov) + np.diag(ms[1].mobile.cov))
    assert np.all(np.abs(d - truth) < 3 * sig), (d - truth) / sig
    np.testing.assert_allclose(
        ms[1].rig2base, FIXED2BASE @ np.linalg.inv(_truth_frame(F, ms[1].fixed2cam)), atol=0.02
    )


def test_a_board_seen_by_one_camera_still_gets_its_pose(scene):
    rig, (_, M1, F), sets = scene
    tracker = PoseTracker(rig, MOBILE, FIXED, FIXED2BASE)
    m = tracker.measure({"left": sets[2][0], "right": sets[2][1]}, "half")
    assert m.ok and m.mobile.cameras == ("left", "right")
    assert m.fixed.cameras == ("right",) and m.fixed.method == "photometric"
    left = m.views[0]
    assert left.mobile is not None and left.fixed is None
    assert "9x7 chessboard" in left.error
    ef = _error(m.fixed.board2rig, F)
    assert ef @ np.linalg.solve(m.fixed.cov, ef) < 22.5
    assert m.mobile2base is not None


def test_bad_cameras_are_named_and_the_others_go_on(scene):
    rig, _, sets = scene
    small = np.zeros((480, 640), np.uint8)
    blank = np.full((960, 1280), 90, np.uint8)
    tracker = PoseTracker(rig, MOBILE, camera_source="rig.json")
    m = tracker.measure({"left": sets[0][0], "right": small}, "wrong size")
    assert m.ok and m.mobile.cameras == ("left",)
    assert "640x480" in m.views[1].error and "rig.json (camera 'right')" in m.views[1].error
    assert "1280x960" in m.views[1].error
    m = tracker.measure({"left": sets[0][0]}, "only left")
    assert m.ok and "no image of camera 'right'" in m.views[1].error
    m = tracker.measure([blank, blank], "blank")
    assert not m.ok and m.mobile is None
    assert "no camera saw the mobile target (8x6 chessboard)" in m.error
    assert "left: blank (left)" in m.error and "right: blank (right)" in m.error
    m = tracker.measure({"left": "no/such/file.png", "right": sets[1][1]}, "missing file")
    assert m.ok and "no/such/file.png" in m.views[0].error and m.mobile.cameras == ("right",)
    with pytest.raises(ValueError, match="not in the rig"):
        tracker.measure({"middle": blank})
    with pytest.raises(ValueError, match="one image per camera"):
        tracker.measure(blank)


# ------------------------------------------------------------------ image sets of files
def test_views_are_matched_by_the_number_in_their_names(tmp_path):
    views, table = match_views(
        ["left", "right"],
        [
            [Path("a/left07.png"), Path("a/left08.png"), Path("a/left10.png")],
            [Path("b/img07_cam2.png"), Path("b/img10_cam2.png")],
        ],
    )
    assert views == ["7", "8", "10"]
    assert [[p and p.name for p in row] for row in table] == [
        ["left07.png", "left08.png", "left10.png"],
        ["img07_cam2.png", None, "img10_cam2.png"],
    ]
    # No usable numbers: in order, with as many images per camera.
    P = [Path("x.png"), Path("y.png")]
    assert len(match_views(["l", "r"], [P, [Path("u.png"), Path("v.png")]])[0]) == 2
    with pytest.raises(InputError, match="l: 2, r: 1"):
        match_views(["l", "r"], [P, [Path("u.png")]])
    rig = stereo_rig(rig_camera())
    for name in ("left_01.png", "right_01.png", "left_02.png", "right_02.png"):
        (tmp_path / name).write_bytes(b"")
    got = rig_image_sets(rig, [str(tmp_path / "{camera}_01.png"), str(tmp_path / "{camera}_0*.png")])
    assert got[0][0].endswith("{camera}_01.png") and len(got) == 3
    with pytest.raises(InputError, match=r"pattern holding \{camera\}"):
        rig_image_sets(rig, [str(tmp_path / "left_01.png")])
    with pytest.raises(InputError, match=r"no images given for camera\(s\) 'right'"):
        rig_image_sets(rig, per_camera=[f"left={tmp_path}/left_0*.png"])
    with pytest.raises(InputError, match=r"nothing\*.png' \(camera 'left'\) matches no file"):
        rig_image_sets(rig, per_camera=[f"left={tmp_path}/nothing*.png", "right=x.png"])


# ------------------------------------------------------------------------ command line
@pytest.fixture(scope="module")
def files(scene, tmp_path_factory):
    """rig.json, a rig whose right camera has another size, and the image files of the sets."""
    rig, _, sets = scene
    root = tmp_path_factory.mktemp("rig")
    save_rig(rig, root / "rig.json")
    d = rig.to_dict()
    d["cameras"][1]["image_size"] = [1024, 960]
    (root / "rig_wrong.json").write_text(json.dumps(d))
    for i, ims in enumerate(sets[:2]):
        for c, im in zip(rig.names, ims, strict=True):
            if (i, c) != (1, "right"):  # right_01.png is missing
                cv2.imwrite(str(root / f"{c}_0{i}.png"), im)
    for c in rig.names:  # set 2 shows no board to any camera
        cv2.imwrite(str(root / f"{c}_02.png"), np.full((960, 1280), 90, np.uint8))
    return root


BOARD_ARGS = ("--board", "8x6", "--square-mm", "10", "--refine", "corners")


def test_pose_with_a_rig_names_each_bad_image_and_goes_on(files):
    p = run_stiffmap(
        "pose",
        "--rig",
        "rig.json",
        "{camera}_00.png",
        "{camera}_01.png",
        "{camera}_02.png",
        *BOARD_ARGS,
        "--json",
        cwd=files,
    )
    assert p.returncode == 1, p.stderr
    rows = json.loads(p.stdout)
    assert [r["frame"] if "error" not in r else "error" for r in rows] == ["rig", "rig", "error"]
    assert rows[0]["consistency"]["cameras"] == ["left", "right"]
    assert [c["name"] for c in rows[1]["cameras"]] == ["left", "right"]
    assert rows[1]["cameras"][1]["error"] and rows[1]["cameras"][0]["mobile"]["method"] == "corners"
    warnings = p.stderr.strip().splitlines()
    assert any("right_01.png" in w and "no such file or folder" in w for w in warnings)  # missing: named
    assert any("{camera}_02.png: no camera saw the mobile target" in w for w in warnings)  # no board
    assert "Traceback" not in p.stderr


def test_a_rig_file_that_does_not_match_the_images_is_named(files):
    p = run_stiffmap("pose", "--rig", "rig_wrong.json", "{camera}_00.png", *BOARD_ARGS, cwd=files, columns=80)
    assert p.returncode == 1, p.stderr
    line = next(w for w in p.stderr.splitlines() if "right_00.png" in w)
    for needle in ("camera right", "1280x960", "1024x960", "rig_wrong.json (camera 'right')"):
        assert needle in line, line
    # The left camera's pose goes on, from the left camera alone.
    assert "board2rig" in p.stdout
    p = run_stiffmap("pose", "--rig", "rig_wrong.json", "{camera}_00.png", *BOARD_ARGS, "--json", cwd=files)
    (row,) = json.loads(p.stdout)
    assert row["consistency"]["cameras"] == ["left"] and row["frame"] == "rig" and "board2cam" not in row
    assert np.isfinite(np.asarray(row["board2rig"], dtype=float)).all()


def test_a_rig_file_with_its_cameras_swapped_is_named_where_they_disagree(files):
    """Issue 27: the cameras' disagreement named the image set but not the rig file to check."""
    d = json.loads((files / "rig.json").read_text())
    d["cameras"][0]["name"], d["cameras"][1]["name"] = d["cameras"][1]["name"], d["cameras"][0]["name"]
    rig, images = files / "rig_swapped.json", str(files / "{camera}_00.png")
    rig.write_text(json.dumps(d))
    o = run_argv(["pose", "--rig", str(rig), images, *BOARD_ARGS])
    disagree = [w for w in o.stderr.splitlines() if "the cameras disagree" in w]
    assert o.code == 1 and disagree, o.stderr
    assert all(w.startswith(f"warning: {rig}: {images}: the cameras disagree") for w in disagree), disagree


def test_displacement_with_a_rig_per_camera_lists(files):
    p = run_stiffmap(
        "displacement", "--rig", "rig.json", "--reference", "{camera}_00.png",
        "--images", "left=left_01.png", "--images", "right=right_0[1-9].png", *BOARD_ARGS, "--json",
        cwd=files,
    )  # fmt: skip
    # right_0[1-9].png matches only right_02.png (right_01.png is missing): matched by number,
    # set 01 has the left image only, set 02 the right (blank) image only.
    rows = json.loads(p.stdout)
    assert rows[0]["reference"] is True and rows[1]["frame"] == "rig"
    assert [c["error"] is None for c in rows[1]["cameras"]] == [True, False]
    assert "no camera saw" in rows[2]["error"]
    assert p.returncode == 1


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (("--rig", "rig.json", "left_00.png"), ("left_00.png", "{camera}")),
        (("--camera", "rig.json", "--rig", "rig.json", "{camera}_00.png"), ("--camera and --rig",)),
        (("--rig", "rig.json", "--images", "middle=x.png"), ("no camera 'middle'", "left, right")),
    ],
)
def test_rig_option_errors_are_one_line(files, args, needles):
    assert_one_line_error(run_stiffmap("pose", *args, *BOARD_ARGS, cwd=files), *needles)
