"""Calibration: the real calibration example against its published results, and synthetic truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.board_scenes import exact_corners
from helpers.random_matrices import random_rotation
from helpers.shared_data import CALIB_DIR

from stiffmap.camera import CameraModel
from stiffmap.errors import InputError
from stiffmap.targets import Chessboard
from stiffmap.vision import BoardDetection, calibrate_camera, calibrate_files

# Bouguet's results on these images after per-image corner windows, 5-coefficient model
# with k3 = 0 (../shared/data/calib_example/README.md); the +/- are about 3 sigma.
PUBLISHED = {
    "fx": (657.4629, 0.3182),
    "fy": (657.9467, 0.3405),
    "cx": (303.1366, 0.6468),
    "cy": (242.5693, 0.5922),
}
PUBLISHED_DIST_3SIGMA = [0.00248, 0.00986, 0.00013, 0.00013]
BOARD = Chessboard(13, 12, 30.0)


@pytest.fixture(scope="module")
def calib_images():
    files = sorted(CALIB_DIR.glob("Image*.tif"), key=lambda p: int(p.stem[5:]))
    assert len(files) == 20
    return files


@pytest.mark.parametrize("model", ["k3", "fix-k3"])
def test_real_photographs_match_the_published_calibration(calib_images, model):
    res = calibrate_files(calib_images, BOARD, model=model)
    cam = res.camera
    assert res.n_used >= 19
    assert abs(cam.fx - PUBLISHED["fx"][0]) <= 0.6  # px
    assert abs(cam.fy - PUBLISHED["fy"][0]) <= 0.6
    assert abs(cam.cx - PUBLISHED["cx"][0]) <= 1.5
    assert abs(cam.cy - PUBLISHED["cy"][0]) <= 1.5
    assert max(cam.residual_std_px) <= 0.13  # px per axis (published 0.117, 0.115)
    for k, (_, three_sigma) in PUBLISHED.items():
        assert 0.5 <= cam.std[k] / (three_sigma / 3) <= 2.0, (k, cam.std[k])
    if model == "fix-k3":
        # Same model as the published one: the distortion's uncertainties compare too.
        for sd, pub in zip(cam.std["dist"][:4], PUBLISHED_DIST_3SIGMA, strict=True):
            assert 0.5 <= sd / (pub / 3) <= 2.0
        assert cam.dist[4] == 0.0 and cam.std["dist"][4] == 0.0
        assert cam.dist[0] == pytest.approx(-0.25403, abs=0.01)
        assert cam.dist[1] == pytest.approx(0.12143, abs=0.03)
    # The full covariance (Schur complement of the views' poses): its diagonal is OpenCV's
    # stdDeviationsIntrinsics squared (agreement seen: 2e-8 relative).
    sd = np.array([cam.std[k] for k in ("fx", "fy", "cx", "cy")] + cam.std["dist"])
    assert cam.cov.shape == (9, 9)
    np.testing.assert_allclose(np.sqrt(np.diag(cam.cov)), sd, rtol=1e-5, atol=0)
    assert np.linalg.eigvalsh(cam.cov).min() >= -1e-12 * np.trace(cam.cov)
    corr = cam.cov[0, 1] / np.sqrt(cam.cov[0, 0] * cam.cov[1, 1])
    assert corr > 0.5  # fx and fy move together (the board's known size fixes their ratio)
    text = res.matlab_text()
    assert f"fc = [ {cam.fx:.5f}   {cam.fy:.5f} ] +/- [ {3 * cam.std['fx']:.5f}" in text
    assert "Pixel error:          err = [ " in text


def _synthetic_views(cam, board, n, sigma_px, rng):
    dets, truth = [], []
    while len(dets) < n:
        R = random_rotation(rng)
        if R[2, 2] < 0.6:  # board facing the camera, tilted up to ~53 degrees
            continue
        T = np.eye(4)
        T[:3, :3] = R
        centre = np.array([(board.cols - 1) / 2, (board.rows - 1) / 2, 0.0]) * board.square_mm
        T[:3, 3] = np.array([rng.uniform(-40, 40), rng.uniform(-30, 30), rng.uniform(350, 550)]) - R @ centre
        uv = exact_corners(cam, board, T)
        w, h = cam.image_size
        if uv.min() < 5 or uv[:, 0].max() > w - 5 or uv[:, 1].max() > h - 5:
            continue
        uv = uv + rng.normal(scale=sigma_px, size=uv.shape)
        ids = np.arange(board.n_corners)
        dets.append(BoardDetection(board=board, corners=uv, ids=ids, residual_px=np.zeros(len(uv))))
        truth.append(T)
    return dets, truth


def test_synthetic_calibration_recovers_the_camera_within_its_uncertainty(rng):
    cam = CameraModel((1280, 960), 1500.0, 1498.0, 652.3, 471.8, (-0.18, 0.09, 4e-4, -3e-4, 0.0))
    board = Chessboard(11, 8, 15.0)
    dets, truth = _synthetic_views(cam, board, 15, 0.1, rng)
    res = calibrate_camera(dets, board, cam.image_size, model="fix-k3")
    c = res.camera
    for k in ("fx", "fy", "cx", "cy"):
        assert abs(getattr(c, k) - getattr(cam, k)) < 4 * c.std[k], k
    for j in range(4):
        assert abs(c.dist[j] - cam.dist[j]) < 4 * c.std["dist"][j]
    assert c.residual_std_px[0] == pytest.approx(0.1, rel=0.1)  # px: the noise put in
    assert c.rms_px == pytest.approx(0.1 * np.sqrt(2), rel=0.1)
    # Poses of the views, within a few mm/mrad of the truth.
    for v, T in zip(res.views, truth, strict=True):
        assert v.used
        np.testing.assert_allclose(v.board2cam[:3, 3], T[:3, 3], atol=0.5)


def test_the_same_views_give_the_same_camera_bit_for_bit_whatever_the_threads(rng):
    # OpenCV's calibration sums in parallel, in an order that changes from run to run (fx
    # differed in its 10th digit); it runs on one thread, so camera.json is reproducible.
    cam = CameraModel((1280, 960), 1500.0, 1498.0, 652.3, 471.8, (-0.18, 0.09, 4e-4, -3e-4, 0.0))
    board = Chessboard(11, 8, 15.0)
    dets, _ = _synthetic_views(cam, board, 12, 0.1, rng)
    threads = cv2.getNumThreads()
    try:
        runs = []
        for n in (4, 1, 4, 4):
            cv2.setNumThreads(n)
            runs.append(calibrate_camera(dets, board, cam.image_size).camera)
            assert cv2.getNumThreads() == n  # left as it was
    finally:
        cv2.setNumThreads(threads)
    for c in runs[1:]:
        assert c.to_dict() == runs[0].to_dict()
        assert np.array_equal(c.cov, runs[0].cov)


def test_an_outlier_view_is_left_out_with_its_reason(rng):
    cam = CameraModel((1280, 960), 1500.0, 1498.0, 652.3, 471.8, (-0.18, 0.09, 0.0, 0.0, 0.0))
    board = Chessboard(11, 8, 15.0)
    dets, _ = _synthetic_views(cam, board, 10, 0.1, rng)
    bad = dets[4]
    dets[4] = BoardDetection(
        board=board,
        corners=bad.corners + rng.normal(scale=2.0, size=bad.corners.shape),
        ids=bad.ids,
        residual_px=bad.residual_px,
    )
    dets.insert(2, "no 11x8 chessboard found in the image")
    names = [f"im{k}.png" for k in range(len(dets))]
    res = calibrate_camera(dets, board, cam.image_size, names=names)
    assert res.n_used == 9
    v = {x.image: x for x in res.views}
    assert not v["im5.png"].used and v["im5.png"].reason.startswith("outlier: view RMS")
    assert v["im5.png"].rms_px > 2.0  # px, still reported
    assert not v["im2.png"].used and "no 11x8 chessboard" in v["im2.png"].reason
    assert np.isnan(v["im2.png"].rms_px)
    assert abs(res.camera.fx - cam.fx) < 4 * res.camera.std["fx"]
    views_json = res.to_dict()["views"]
    assert views_json[2] == {"image": "im2.png", "used": False, "rms_px": None, "reason": v["im2.png"].reason}


def test_too_few_views_lists_why(rng):
    board = Chessboard(11, 8, 15.0)
    with pytest.raises(InputError, match=r"at least 3 views.*a\.png: truncated.*b\.png: no board"):
        calibrate_camera(["truncated PNG file", "no board"], board, (640, 480), names=["a.png", "b.png"])


def test_unreadable_and_missing_images_do_not_stop_calibration(calib_images, tmp_path):
    bad = tmp_path / "broken.tif"
    bad.write_bytes(calib_images[0].read_bytes()[:5000])
    # A stray image of another camera first on the command line: it is the one left out.
    stray = tmp_path / "other_camera.png"
    big = cv2.resize(cv2.imread(str(calib_images[0]), cv2.IMREAD_GRAYSCALE), (1280, 960))
    cv2.imwrite(str(stray), big)
    paths = [stray, *calib_images[:6], bad, tmp_path / "missing.tif"]
    res = calibrate_files(paths, BOARD, model="fix-k3")
    v = {x.image: x for x in res.views}
    assert res.n_used == 6 and res.camera.image_size == (640, 480)
    assert (
        not v[str(stray)].used
        and "1280x960" in v[str(stray)].reason
        and "6 of the views" in v[str(stray)].reason
    )
    assert not v[str(bad)].used and "cannot decode" in v[str(bad)].reason
    assert "no such file or folder" in v[str(tmp_path / "missing.tif")].reason


def test_covariance_from_information_is_the_inverse_when_well_posed_and_psd_when_not(rng):
    """Well conditioned: s^2 S^-1 (numpy's inverse). An information matrix whose rounding made
    it indefinite (two nearly collinear columns, as the rational model's k's): finite, positive
    variances, positive semi-definite, the undetermined direction the largest variance."""
    from stiffmap.vision.calibrate import covariance_from_information

    J = rng.normal(size=(200, 4)) * [1.0, 50.0, 1e-3, 7.0]  # mixed units
    S = J.T @ J
    C = covariance_from_information(S, 0.04, range(4))
    np.testing.assert_allclose(C, 0.04 * np.linalg.inv(S), rtol=1e-9)
    # Column 3 a combination of 1 and 2 up to 1e-9: S's smallest eigenvalue is rounding noise.
    J[:, 3] = J[:, 1] - 2.0 * J[:, 2] + 1e-9 * rng.normal(size=200)
    S = J.T @ J
    v = np.array([0.0, 1.0, -2.0, -1.0]) / np.sqrt(6.0)
    S -= 1e-6 * np.trace(S) * 1e-9 * np.outer(v, v)  # pushed below zero along it
    assert np.linalg.eigvalsh(S).min() < 0
    C = covariance_from_information(S, 0.04, [0, 1, 2, 3])
    assert np.all(np.isfinite(C)) and np.all(np.diag(C) > 0)
    w = np.linalg.eigvalsh(C)
    assert w.min() >= -1e-12 * w.max()
    # The well-determined parameter 0 keeps its variance (J's column 0 is independent of the rest).
    assert C[0, 0] == pytest.approx(0.04 / (J[:, 0] @ J[:, 0]), rel=0.05)


@pytest.mark.slow
def test_the_rational_model_on_real_photographs_has_positive_finite_variances(calib_images):
    """calibrate --rational on Bouguet's views: k1..k6 determined only in combination (its
    information matrix had an eigenvalue -4e-12 of 8.3 after scaling, and variances of -1.15
    and -0.95); the covariance is finite, positive semi-definite, with the intrinsics' 1-sigma
    near the k3 model's (more coefficients cannot make fx much surer)."""
    rational = calibrate_files(calib_images, BOARD, model="rational").camera
    k3 = calibrate_files(calib_images, BOARD, model="k3").camera
    C = rational.cov
    assert C.shape == (12, 12) and np.all(np.isfinite(C))
    free = np.diag(C)[np.r_[0:6, 8:12]]  # k3, k4..k6 free; p1, p2 too
    assert np.all(free > 0) and np.all(np.diag(C)[6:8] > 0)
    w = np.linalg.eigvalsh(C)
    assert w.min() >= -1e-12 * w.max()
    ratio = np.sqrt(np.diag(C)[:4] / np.diag(k3.cov)[:4])
    assert np.all((ratio > 0.9) & (ratio < 3.0)), ratio
