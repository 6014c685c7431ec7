"""The fisheye lens model through the vision path: calibration, covariance, poses, rigs, the CLI.

No public fisheye set ships in a PyPI or Debian package (docs/vision.md, "Fisheye and
wide-angle lenses", says what was searched): the fisheye views here are the test-bed's, a
150-degree lens rendered with its noise, blur and vignetting, whose true camera and poses are
known; the real wide-angle camera is the udacity set (../shared/data/real, strong barrel).
"""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from helpers.cli_process import run_in_process, run_stiffmap
from helpers.rig_views import BOARD as RIG_BOARD
from helpers.rig_views import MARGIN_MM as RIG_MARGIN_MM
from helpers.rig_views import noisy_detections
from helpers.shared_data import REAL_SETS

from stiffmap.camera import CameraModel, invertible_field, load_camera
from stiffmap.campaign.demo import QUICK_POSITIONS
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.truth import load_truth
from stiffmap.errors import InputError
from stiffmap.geometry import rotvec_from_matrix
from stiffmap.loads import paper9
from stiffmap.models.presets import paper48
from stiffmap.sim.calibration_views import (
    CALIBRATION_BOARD,
    CALIBRATION_MARGIN_MM,
    careful_poses,
    rig_calibration_views,
)
from stiffmap.sim.photometry import Photometry
from stiffmap.sim.render import Target, encode_image, render
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import demo_scene, two_camera_rig
from stiffmap.sim.testbed import SimConfig
from stiffmap.targets import Chessboard
from stiffmap.vision import detect_board, estimate_pose
from stiffmap.vision.calibrate import calibrate_camera, calibration_covariance, model_calibration_covariance
from stiffmap.vision.files import calibrate_files, image_files
from stiffmap.vision.rig_calibration import calibrate_rig

#: A 150-degree fisheye (the image corner 74 degrees off axis), 640x480 px.
TRUE = CameraModel((640, 480), 300.0, 300.5, 322.4, 238.7, (0.03, -0.01, 0.002, -0.0003), model="fisheye")
N_VIEWS = 10


@pytest.fixture(scope="module")
def views():
    """Careful calibration views of the test-bed's A3 board through the fisheye, and their detections."""
    poses = careful_poses(TRUE, N_VIEWS, rng=np.random.default_rng(1))
    out = []
    for k, T in enumerate(poses):
        tg = Target(CALIBRATION_BOARD, T, name="calibration", margin_mm=CALIBRATION_MARGIN_MM)
        r = render(TRUE, [tg], photometry=Photometry(), seed=np.random.default_rng(100 + k))
        try:
            det = detect_board(r.image, CALIBRATION_BOARD)
        except InputError as e:
            det = e.detail
        out.append((r.image, T, det))
    return out


@pytest.fixture(scope="module")
def calibrated(views):
    """The views calibrated with the fisheye and the k3 models, and the detections."""
    dets = [d for _, _, d in views]
    fits = {m: calibrate_camera(dets, CALIBRATION_BOARD, TRUE.image_size, model=m) for m in ("fisheye", "k3")}
    return fits, dets


def _fisheye_flags() -> int:
    """OpenCV's fisheye flags RECOMPUTE_EXTRINSIC | FIX_SKEW (cv2.fisheye.X before OpenCV 5, cv2.X since)."""
    names = ("CALIB_RECOMPUTE_EXTRINSIC", "CALIB_FIX_SKEW")
    return sum(int(getattr(cv2.fisheye, n, None) or getattr(cv2, n)) for n in names)


def test_rendered_fisheye_views_calibrate_to_the_true_camera_over_the_whole_image(calibrated):
    res = calibrated[0]["fisheye"]
    cam = res.camera
    assert res.n_used >= N_VIEWS - 2 and cam.model == "fisheye" and res.model == "fisheye"
    assert cam.rms_px < 0.06  # px: the corners' noise on these renders
    # The true intrinsics within 4 sigma of the calibration's own covariance (and within 0.1 px).
    err = cam.params[:4] - TRUE.params[:4]
    sd = np.sqrt(np.diag(cam.cov))[:4]
    assert np.all(np.abs(err) < 4 * sd) and np.all(np.abs(err) < 0.1), (err, sd)
    # The whole image is usable: the fitted model is one to one over every pixel.
    assert invertible_field(cam).image_share() == 1.0
    # The polynomial model cannot follow this lens: 10 times the RMS, folding inside the image,
    # and the calibration says which model would serve.
    k3 = calibrated[0]["k3"]
    assert k3.camera.rms_px > 2 * cam.rms_px
    assert invertible_field(k3.camera).image_share() < 0.95
    assert "fisheye model (calibrate --fisheye)" in k3.lens_advice and "whole image" in k3.lens_advice


def test_the_numpy_covariance_is_opencvs_for_the_pinhole_model(calibrated):
    # stiffmap's own Jacobians of the camera model against cv2.projectPoints' (the k3 fit of
    # the same views): the same Schur complement, two independent computations.
    fits, dets = calibrated
    res = fits["k3"]
    cam = res.camera
    grid = CALIBRATION_BOARD.object_points()
    used = [(v, d) for v, d in zip(res.views, dets, strict=True) if v.used]
    obj = [grid[d.ids] for _, d in used]
    img = [d.corners for _, d in used]
    poses = [v.board2cam for v, _ in used]
    rv = [cv2.Rodrigues(T[:3, :3])[0] for T in poses]
    tv = [T[:3, 3] for T in poses]
    ref = calibration_covariance(obj, img, cam.matrix, cam.dist_array, rv, tv)
    ours = model_calibration_covariance(cam, obj, img, poses)
    s = np.sqrt(np.diag(ref))
    np.testing.assert_allclose(np.sqrt(np.diag(ours)), s, rtol=1e-6)
    np.testing.assert_allclose(ours / np.outer(s, s), ref / np.outer(s, s), rtol=0, atol=1e-6)  # correlations
    # The fisheye calibration's covariance is this computation through the fisheye model.
    fish = fits["fisheye"]
    used = [(v, d) for v, d in zip(fish.views, dets, strict=True) if v.used]
    again = model_calibration_covariance(
        fish.camera,
        [grid[d.ids] for _, d in used],
        [d.corners for _, d in used],
        [v.board2cam for v, _ in used],
    )
    np.testing.assert_allclose(again, fish.camera.cov, rtol=1e-9, atol=0)
    np.testing.assert_allclose(fish.camera.std["dist"], np.sqrt(np.diag(again))[4:], rtol=1e-9)


def test_photometric_pose_through_the_fisheye_model_is_on_the_truth():
    # A noise-free render (the optics blur stays): the corner pose is biased along the line of
    # sight by the corner estimator (several um), the photometric fit of the blurred board,
    # which uses the fisheye rays of every pixel, is within 3 um.
    T = careful_poses(TRUE, 5, rng=np.random.default_rng(1))[3]  # towards an image corner
    tg = Target(CALIBRATION_BOARD, T, name="calibration", margin_mm=CALIBRATION_MARGIN_MM)
    img = render(TRUE, [tg], photometry=Photometry.noise_free(), seed=np.random.default_rng(0)).image
    det = detect_board(img, CALIBRATION_BOARD, camera=TRUE)
    corner = estimate_pose(det, CALIBRATION_BOARD, TRUE, refine="corners")
    photo = estimate_pose(det, CALIBRATION_BOARD, TRUE, image=img, refine="photometric", max_shift_sigma=1e9)
    assert photo.method == "photometric" and not photo.fallback
    line = T[:3, 3] / np.linalg.norm(T[:3, 3])  # the line of sight to the board's origin
    # Measured: photometric 1.2 um along, 1.5 um across, 6e-7 rad; corners 8.9 um, 8.6 um, 2e-5 rad.
    for pose, along_um, across_um, rad in ((photo, 3.0, 3.0, 1e-5), (corner, 25.0, 20.0, 1e-4)):
        dt = pose.board2cam[:3, 3] - T[:3, 3]
        assert abs(dt @ line) * 1e3 < along_um
        assert np.linalg.norm(dt - (dt @ line) * line) * 1e3 < across_um
        assert np.linalg.norm(rotvec_from_matrix(pose.board2cam[:3, :3] @ T[:3, :3].T)) < rad


def test_a_rig_of_two_fisheye_cameras_calibrates_to_the_truth():
    left = TRUE
    right = CameraModel((640, 480), 305.0, 304.6, 318.0, 236.0, (0.02, -0.005, 0.001, 0.0), model="fisheye")
    rig = two_camera_rig(left, 400.0, 60.0, right_camera=right)
    views = rig_calibration_views(
        rig, 12, board=RIG_BOARD, margin_mm=RIG_MARGIN_MM, rng=np.random.default_rng(0)
    )
    dets = noisy_detections(rig, views, 0.05, np.random.default_rng(1))
    res = calibrate_rig(dets, RIG_BOARD, [(640, 480)] * 2, camera_names=["left", "right"], model="fisheye")
    sd = np.sqrt(np.diag(res.rig.cov))
    for k in range(2):
        cam, true = res.rig.cameras[k].camera, rig.cameras[k].camera
        assert cam.model == "fisheye"
        s = res.rig.intrinsic_slice(k)
        assert np.all(np.abs(cam.params - true.params) < 4.5 * sd[s]), (cam.params - true.params) / sd[s]
    s = res.rig.extrinsic_slice(1)
    dt = res.rig.cameras[1].cam2rig[:3, 3] - rig.cameras[1].cam2rig[:3, 3]
    assert np.all(np.abs(dt) < 4.5 * sd[s][:3]), dt / sd[s][:3]
    saved = json.loads(json.dumps(res.to_dict()))
    assert [c["model"] for c in saved["cameras"]] == ["fisheye", "fisheye"]


def test_calibrate_fisheye_and_pose_from_the_command_line(views, tmp_path, monkeypatch, capsys):
    for k, (img, _, _) in enumerate(views[:8]):
        (tmp_path / f"view{k:02d}.png").write_bytes(encode_image(img, "png"))
    board = ("--board", "11x8", "--square-mm", "25")
    code, out, err = run_in_process(
        ["calibrate", tmp_path, *board, "--fisheye", "--out", tmp_path / "camera.json"], monkeypatch, capsys
    )
    assert code == 0, err
    assert "model fisheye" in out and "one to one over the whole field of view" in out
    assert "│ k4 " in out and "│ p1 " not in out  # the fisheye model's coefficients, named
    cam = load_camera(tmp_path / "camera.json")
    assert cam.model == "fisheye" and cam.cov is not None
    assert json.loads((tmp_path / "camera.json").read_text())["model"] == "fisheye"
    np.testing.assert_allclose(cam.params[:4], TRUE.params[:4], atol=0.15)  # px
    code, out, err = run_in_process(
        ["pose", tmp_path / "view03.png", "--camera", tmp_path / "camera.json", *board, "--json"],
        monkeypatch,
        capsys,
    )
    assert code == 0, err
    (row,) = json.loads(out)
    T = np.array(row["board2cam"])
    assert np.linalg.norm(T[:3, 3] - views[3][1][:3, 3]) < 0.5  # mm, with the calibration's own error
    assert row["cov_calibration"] is not None
    code, _, err = run_in_process(
        ["calibrate", tmp_path, *board, "--fisheye", "--rational"], monkeypatch, capsys
    )
    assert code == 2 and "choose at most one of --fix-k3, --rational, --thin-prism, --fisheye" in err


@pytest.mark.slow  # 4-7 s: detection in 20 photographs of 1280x720
@pytest.mark.parametrize("name", ["udacity"])
def test_a_real_wide_angle_set_calibrates_with_the_fisheye_model_over_the_whole_image(name):
    """The udacity set (../shared/data/real/README.md): 20 photographs, strong barrel distortion."""
    folder = REAL_SETS[name][0]
    fish = calibrate_files(image_files([folder]), Chessboard(9, 6, 25.0), model="fisheye")
    cam = fish.camera
    assert fish.n_used >= 16 and cam.model == "fisheye"
    # One to one over every pixel, where the default model folds before the corners.
    assert invertible_field(cam).image_share() == 1.0
    # The same views, with OpenCV's own fisheye calibration on OpenCV's corners (its documented
    # pipeline): stiffmap's RMS is no worse (benchmarks/results/fisheye.md).
    obj, img = [], []
    for v in fish.views:
        if not v.used:
            continue
        grey = cv2.imread(v.image, cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(grey, (9, 6))
        if ok:
            crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
            img.append(
                cv2.cornerSubPix(grey, c, (11, 11), (-1, -1), crit).reshape(1, -1, 2).astype(np.float64)
            )
            obj.append(Chessboard(9, 6, 25.0).object_points().reshape(1, -1, 3))
    rms_cv, *_ = cv2.fisheye.calibrate(
        obj, img, cam.image_size, np.eye(3), np.zeros(4), flags=_fisheye_flags()
    )
    assert len(img) >= 14
    assert cam.rms_px <= 1.05 * rms_cv, (cam.rms_px, rms_cv)
    assert math.isfinite(cam.std["fx"]) and cam.std["fx"] < 20.0  # px


@pytest.mark.long
def test_a_fisheye_test_bed_campaign_is_measured_to_the_true_stiffness(tmp_path):
    """The demo's scene seen through a 104-degree fisheye (2592x1944 px, f = 1800 px), quick positions.

    The campaign's camera.json is calibrated from 20 rendered views with the fisheye model (as
    ``stiffmap calibrate --fisheye``), and ``stiffmap run`` measures every image through it
    (poses, the photometric refinement, displacements). Measured: every K within 0.6-2.0 % of
    the truth (the reference camera's quick demo: 0.6 %; f is half the reference's 3733 px),
    about 75 s to simulate and 30 s to run on 2 idle processes (200 s on a loaded machine).
    """
    cam = CameraModel(
        (2592, 1944), 1800.0, 1800.54, 1301.2, 968.4, (0.02, -0.01, 0.003, -0.0005), model="fisheye"
    )
    cfg = SimConfig(
        scene=demo_scene(cam),
        robot=delta_robot(),
        positions=paper48()[np.asarray(QUICK_POSITIONS) - 1],
        loads=tuple(paper9()),
        repeats=1,
        seed=1,
        robot_stays=True,
        calibration_views=20,
        name="fisheye campaign",
    )
    out = tmp_path / "fisheye"
    write_campaign(out, cfg, workers=2)
    calibrated = load_camera(out / "camera.json")
    assert calibrated.model == "fisheye" and calibrated.cov is not None
    assert load_truth(out).camera == cam and load_truth(out).calibrated_camera == calibrated
    np.testing.assert_allclose(calibrated.params[:4], cam.params[:4], atol=0.5)  # px
    proc = run_stiffmap("run", out)
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr
    K = np.array([p["K"] for p in json.loads((out / "exports" / "summary.json").read_text())["positions"]])
    Kt = np.array([p["K"] for p in json.loads((out / "truth.json").read_text())["positions"]])
    rel = np.linalg.norm(K - Kt, axis=(1, 2)) / np.linalg.norm(Kt, axis=(1, 2))
    assert len(rel) == len(QUICK_POSITIONS) and rel.max() < 0.03, rel
