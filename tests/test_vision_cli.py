"""The vision commands end to end: real calibration photographs and rendered images with ground truth.

Also every bad input the issue lists: unreadable and truncated images, no board, the
wrong board size, a partly hidden board, an image whose size differs from camera.json,
a malformed camera.json. Each gives one clear line naming the file; the other images
are still processed; the exit status is non-zero only when something failed.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import close_two_target_poses, moved_pose, small_camera
from helpers.cli_process import run_here
from helpers.shared_data import CALIB_DIR

from stiffmap.camera import CameraModel, save_camera
from stiffmap.geometry import displacement_from_poses, matrix_from_rotvec
from stiffmap.targets import Chessboard

MOBILE = Chessboard(7, 6, 10.0)
FIXED = Chessboard(9, 4, 10.0)
CAM = small_camera()


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("vision_cli")
    save_camera(CAM, d / "camera.json")
    M0, F = close_two_target_poses(MOBILE, FIXED)
    B = np.eye(4)
    B[:3, :3] = matrix_from_rotvec([0.1, -0.2, 0.3])
    B[:3, 3] = [150.0, -20.0, 35.0]
    (d / "fixed2base.json").write_text(json.dumps({"fixed2base": B.tolist()}))
    delta = np.array([0.5, -0.2, 0.3, 1e-3, -2e-3, 5e-4])
    axis = np.array([0.8, 0.1, 0.59])
    axis /= np.linalg.norm(axis)
    rng = np.random.default_rng(5)
    truth = {"F": F, "M0": M0, "B": B, "delta": delta, "axis": axis}
    shots = {"ref0": M0, "ref1": M0, "moved0": moved_pose(M0, delta), "moved1": moved_pose(M0, delta)}
    for step in (2.0, 5.0):
        for k in range(2):
            shots[f"stage{step:g}_{k}"] = moved_pose(M0, np.r_[step * axis, 0, 0, 0])
    for name, T in shots.items():
        cv2.imwrite(str(d / f"{name}.png"), quick_board_image(CAM, [(FIXED, F), (MOBILE, T)], rng=rng))
    # Bad inputs.
    data = (d / "moved0.png").read_bytes()
    (d / "truncated.png").write_bytes(data[: len(data) // 2])
    (d / "notimage.png").write_text("not pixels")
    cv2.imwrite(str(d / "blank.png"), np.full((480, 640), 90, np.uint8))
    cv2.imwrite(str(d / "big.png"), np.full((600, 800), 90, np.uint8))
    cv2.imwrite(
        str(d / "hidden.png"),
        quick_board_image(CAM, [(FIXED, F), (MOBILE, M0)], rng=rng, occluder=(450, 0, 640, 480)),
    )
    (d / "stage.csv").write_text(
        "image,nominal_mm\nref0.png,0\nref1.png,0\n"
        + "".join(f"stage{s:g}_{k}.png,{s:g}\n" for s in (2.0, 5.0) for k in range(2))
    )
    (d / "bad_json.json").write_text("{not json")
    (d / "no_fx.json").write_text(json.dumps({k: v for k, v in CAM.to_dict().items() if k != "fx"}))
    return d, truth


def _invoke(args, columns: int = 200):
    return run_here(*args, columns=columns)


def _measure(command, d, board="7x6", camera="camera.json"):
    """``COMMAND --camera D/CAMERA --board BOARD --square-mm 10``, as every measuring command starts."""
    return [command, "--camera", d / camera, "--board", board, "--square-mm", "10"]


def test_calibrate_the_real_photographs(tmp_path):
    files = sorted(CALIB_DIR.glob("Image*.tif"))
    out = tmp_path / "camera.json"
    r = _invoke(["calibrate", *files, "--board", "13x12", "--square-mm", "30", "--out", out, "--json"])
    assert r.returncode == 0, r.stderr
    cam = json.loads(r.stdout)
    assert json.loads(out.read_text()) == cam
    assert set(cam) >= {
        "image_size",
        "fx",
        "fy",
        "cx",
        "cy",
        "dist",
        "std",
        "rms_px",
        "residual_std_px",
        "views",
    }
    assert cam["image_size"] == [640, 480] and len(cam["dist"]) == 5
    assert sum(v["used"] for v in cam["views"]) >= 19
    assert abs(cam["fx"] - 657.46) <= 0.6 and abs(cam["fy"] - 657.95) <= 0.6  # px
    assert abs(cam["cx"] - 303.14) <= 1.5 and abs(cam["cy"] - 242.57) <= 1.5
    assert max(cam["residual_std_px"]) <= 0.13
    assert set(cam["std"]) == {"fx", "fy", "cx", "cy", "dist"}
    r = _invoke(
        ["calibrate", *files[:5], "--board", "13x12", "--square-mm", "30", "--out", out, "--fix-k3"],
        columns=80,
    )
    assert r.returncode == 0
    assert "Focal Length:          fc = [ 6" in r.stdout and "Pixel error:" in r.stdout
    # The second calibration replaced camera.json; the first is kept beside it, not lost.
    assert json.loads((tmp_path / "camera.json.bak").read_text()) == cam
    assert "previous calibration is kept as" in r.stderr


def test_calibrate_with_nothing_usable_fails_cleanly(data, tmp_path):
    d, _ = data
    r = _invoke(
        [
            "calibrate",
            d / "blank.png",
            d / "notimage.png",
            "--board",
            "7x6",
            "--square-mm",
            "10",
            "--out",
            tmp_path / "c.json",
        ]
    )
    assert r.returncode == 2
    assert r.stderr.startswith("error:") and "blank.png" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "c.json").exists()


def test_pose_json_and_every_bad_input(data):
    d, t = data
    files = [
        "ref0.png",
        "truncated.png",
        "notimage.png",
        "blank.png",
        "big.png",
        "hidden.png",
        "missing.png",
        "moved0.png",
    ]
    r = _invoke([*_measure("pose", d), "--json", *[d / f for f in files]])
    assert r.returncode == 1  # some images failed, others measured
    rows = json.loads(r.stdout)
    assert [row["image"] for row in rows] == [str(d / f) for f in files]
    by = {f: row for f, row in zip(files, rows, strict=True)}
    for f in ("ref0.png", "moved0.png"):
        T = np.array(by[f]["board2cam"])
        truth = t["M0"] if f == "ref0.png" else moved_pose(t["M0"], t["delta"])
        np.testing.assert_allclose(T[:3, 3], truth[:3, 3], atol=0.05)  # mm
        assert np.array(by[f]["cov"]).shape == (6, 6) and by[f]["rms_px"] < 0.1
    assert "truncated PNG" in by["truncated.png"]["error"]
    assert "not an image file" in by["notimage.png"]["error"]
    assert "no 7x6 chessboard found" in by["blank.png"]["error"]
    assert "800x600" in by["big.png"]["error"] and "640x480" in by["big.png"]["error"]
    assert "camera.json" in by["big.png"]["error"]
    assert "no complete 7x6 chessboard" in by["hidden.png"]["error"]
    assert "no such file or folder" in by["missing.png"]["error"]
    for f in files[1:-1]:
        assert by[f]["error"].startswith(str(d / f) + ":")
    # One warning line per failed image on stderr, no traceback.
    assert r.stderr.count("warning:") == 6 and "Traceback" not in r.stderr


def test_pose_table_wrong_board_size_and_all_failed(data):
    d, _ = data
    r = _invoke([*_measure("pose", d, "6x5"), d / "ref0.png"])
    assert r.returncode == 2  # nothing could be done, and one error line says so
    # The rendered board is 7x6: its size is named (the test-bed's truth).
    assert "the image shows a 7x6 chessboard (inner corners), not 6x5: did you mean --board 7x6?" in r.stderr
    assert "error: none of the 1 image(s) could be measured" in r.stderr
    r = _invoke([*_measure("pose", d), d / "ref0.png"], columns=80)
    assert r.returncode == 0 and "board2cam of the 7x6 board" in r.stdout and "failed" not in r.stdout


@pytest.mark.parametrize(
    ("camera", "message"),
    [("bad_json.json", "not valid JSON"), ("no_fx.json", "missing key 'fx'"), ("nope.json", "not found")],
)
def test_malformed_camera_json(data, camera, message):
    d, _ = data
    r = _invoke([*_measure("pose", d, camera=camera), d / "ref0.png"])
    assert r.returncode == 2
    assert camera in r.stderr and message in r.stderr and r.stderr.count("\n") == 1


def test_displacement_camera_and_base_frames(data):
    d, t = data
    args = [
        *_measure("displacement", d),
        "--reference",
        d / "ref0.png",
        "--reference",
        d / "ref1.png",
        d / "moved0.png",
        d / "moved1.png",
        d / "blank.png",
        "--json",
    ]
    r = _invoke(args)
    assert r.returncode == 1  # blank.png failed
    # A reference that cannot be read is a failure too, not a silent exit 0.
    refs = ["--reference", d / "ref0.png", "--reference", d / "nope.png"]
    r2 = _invoke([*_measure("displacement", d), *refs, d / "moved0.png"], columns=100)
    assert r2.returncode == 1 and "nope.png" in r2.stderr
    rows = json.loads(r.stdout)
    truth = displacement_from_poses(t["M0"], moved_pose(t["M0"], t["delta"]))
    for row in rows[:2]:
        assert row["frame"] == "cam"
        assert np.all(np.abs(np.array(row["d"]) - truth[:3]) < [0.01, 0.01, 0.08])  # mm
        np.testing.assert_allclose(row["r"], truth[3:], atol=5e-4)  # rad
        assert len(row["d_std"]) == 3
    assert "no 7x6 chessboard" in rows[2]["error"]
    summary = rows[3]
    assert summary["summary"] and summary["n"] == 2 and summary["image"] is None
    # In the robot base frame through the fixed target, at a tool point.
    q = [30.0, 25.0, -40.0]
    r = _invoke(
        [
            *args[:-2],
            "--fixed-board",
            "9x4",
            "--fixed-square-mm",
            "10",
            "--fixed2base",
            d / "fixed2base.json",
            "--point",
            ",".join(map(str, q)),
            "--json",
        ]
    )
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    G = t["B"] @ np.linalg.inv(t["F"])
    truth_b = displacement_from_poses(G @ t["M0"], G @ moved_pose(t["M0"], t["delta"]), q)
    assert rows[-1]["frame"] == "base"
    err = np.array(rows[-1]["d"]) - truth_b[:3]
    assert np.linalg.norm(err) < 0.08, err  # mm (the depth error, turned into base axes)
    np.testing.assert_allclose(rows[-1]["r"], truth_b[3:], atol=5e-4)


def test_displacement_option_errors(data):
    d, _ = data
    base = [*_measure("displacement", d), "--reference", d / "ref0.png", d / "moved0.png"]
    r = _invoke([*base, "--point", "1,2"])
    assert r.returncode == 2 and "--point" in r.stderr
    r = _invoke([*base, "--fixed-board", "9x4"])
    assert r.returncode == 2 and "--fixed-square-mm" in r.stderr
    # A fixed board without its pose on the base would silently leave the camera frame in use.
    r = _invoke([*base, "--fixed-board", "9x4", "--fixed-square-mm", "10"])
    assert r.returncode == 2 and "--fixed2base" in r.stderr
    (d / "notrigid.json").write_text(json.dumps((2 * np.eye(4)).tolist()))
    r = _invoke(
        [*base, "--fixed-board", "9x4", "--fixed-square-mm", "10", "--fixed2base", d / "notrigid.json"]
    )
    assert r.returncode == 2 and "notrigid.json" in r.stderr and "rigid" in r.stderr
    r = _invoke([*_measure("displacement", d), "--reference", d / "blank.png", d / "moved0.png"])
    assert r.returncode == 2 and "no reference image" in r.stderr


def test_validate_table_json_and_plot(data):
    d, _ = data
    plot = d / "stage.svg"
    r = _invoke([*_measure("validate", d), d / "stage.csv", "--plot", plot, "--json"])
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert [s["nominal_mm"] for s in res["steps"]] == [2.0, 5.0]
    for s in res["steps"]:
        assert s["n"] == 2
        assert abs(s["error_mm"]) < 0.06  # mm, 640x480 camera at 300 mm
        assert abs(s["along_mean_mm"] - s["nominal_mm"]) < 0.06
    assert res["n_reference"] == 2
    root = ET.fromstring(plot.read_text())
    assert root.tag.endswith("svg") and len(root.findall(".//{http://www.w3.org/2000/svg}circle")) == 4
    r = _invoke([*_measure("validate", d), d / "stage.csv"], columns=80)
    assert r.returncode == 0 and "nominal" in r.stdout and "RMS error" in r.stdout


def test_pose_and_displacement_say_how_much_comes_from_the_calibration(data):
    d, _ = data
    # The test camera with a calibration covariance (fx, fy 0.5 px correlated +0.9, cx, cy 0.3 px, k1 1e-3).
    C = np.zeros((9, 9))
    C[:2, :2] = [[0.25, 0.225], [0.225, 0.25]]
    C[2, 2] = C[3, 3] = 0.09
    C[4, 4] = 1e-6
    cam = CameraModel(CAM.image_size, CAM.fx, CAM.fy, CAM.cx, CAM.cy, CAM.dist, cov=C)
    save_camera(cam, d / "camera_cov.json")
    refs = ["--reference", d / "ref0.png", "--reference", d / "ref1.png"]
    base = ["--fixed-board", "9x4", "--fixed-square-mm", "10", "--fixed2base", d / "fixed2base.json"]
    rows = {}
    for name in ("camera.json", "camera_cov.json"):
        r = _invoke([*_measure("displacement", d, camera=name), *refs, d / "moved0.png", *base, "--json"])
        assert r.returncode == 0, r.stderr
        rows[name] = json.loads(r.stdout)
    plain, with_cov = rows["camera.json"][0], rows["camera_cov.json"][0]
    assert plain["d_std_calibration"] is None and plain["calibration_share"] is None
    share = np.array(with_cov["calibration_share"])
    assert share.shape == (6,) and np.all((share > 0) & (share < 1))
    assert np.all(np.array(with_cov["d_std_calibration"]) < np.array(with_cov["d_std"]))
    # The total is the noise (the plain camera's) plus the calibration's share.
    np.testing.assert_allclose(
        np.square(with_cov["d_std"]),
        np.square(plain["d_std"]) + np.square(with_cov["d_std_calibration"]),
        rtol=1e-3,
    )
    summary = rows["camera_cov.json"][-1]
    assert summary["summary"] and len(summary["calibration_share"]) == 6
    r = _invoke([*_measure("displacement", d, camera="camera_cov.json"), *refs, d / "moved0.png"])
    assert "of which calibration" in r.stdout and "full covariance" in r.stdout
    r = _invoke([*_measure("pose", d, camera="camera_cov.json"), "--json", d / "ref0.png"])
    row = json.loads(r.stdout)[0]
    assert np.array(row["cov_calibration"]).shape == (6, 6) and len(row["t_std_calibration_mm"]) == 3
