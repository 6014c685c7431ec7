"""The camera calibration's uncertainty in poses and displacements (issue 17, build item 4).

Finite-difference checks of the sensitivities (camera parameters -> pixels -> pose), Monte-Carlo
checks on the virtual test-bed (cameras drawn from their covariance, fixed detections, so the
spread is the calibration's alone), and Bouguet's real calibration example.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import exact_corners, look_at_pose, moved_pose, small_camera
from helpers.finite_difference import central_jacobian
from helpers.random_matrices import random_rotation
from helpers.shared_data import CALIB_DIR

from stiffmap.camera import CameraModel, reference_camera
from stiffmap.geometry import rotvec_from_matrix
from stiffmap.targets import Chessboard
from stiffmap.vision import (
    BoardDetection,
    ImageMeasurement,
    calibrate_camera,
    calibrate_files,
    compliant_displacement,
    detect_board,
    estimate_pose,
)

BOARD = Chessboard(8, 6, 10.0)
CALIB_BOARD = Chessboard(13, 12, 20.0)


def _detection(board, uv):
    n = len(uv)
    return BoardDetection(board=board, corners=uv, ids=np.arange(n), residual_px=np.zeros(n))


def _pose_delta(T, T0):
    """(t - t0, rotvec(R R0^T)): the left perturbation taking T0 to T."""
    return np.concatenate([T[:3, 3] - T0[:3, 3], rotvec_from_matrix(T[:3, :3] @ T0[:3, :3].T)])


def _calibrated(cam: CameraModel, rng, *, n_views=15, sigma_px=0.1, distance=(500, 800)) -> CameraModel:
    """``cam`` calibrated from synthetic views (noise ``sigma_px``): the camera with its ``cov``."""
    dets = []
    w, h = cam.image_size
    centre = np.array([(CALIB_BOARD.cols - 1) / 2, (CALIB_BOARD.rows - 1) / 2, 0.0]) * CALIB_BOARD.square_mm
    while len(dets) < n_views:
        R = random_rotation(rng)
        if R[2, 2] < 0.7:
            continue
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [rng.uniform(-60, 60), rng.uniform(-40, 40), rng.uniform(*distance)] - R @ centre
        uv = exact_corners(cam, CALIB_BOARD, T)
        if uv.min() < 5 or uv[:, 0].max() > w - 5 or uv[:, 1].max() > h - 5:
            continue
        dets.append(_detection(CALIB_BOARD, uv + rng.normal(scale=sigma_px, size=uv.shape)))
    return calibrate_camera(dets, CALIB_BOARD, cam.image_size).camera


# ----------------------------------------------------------------------------- sensitivities
def test_projection_param_jacobian_matches_finite_differences(rng):
    cam = CameraModel(
        (1280, 960),
        1500.0,
        1490.0,
        650.0,
        470.0,
        (-0.2, 0.1, 1e-3, -2e-3, -0.03, 0.05, 0.02, 0.01, 1e-3, -2e-3, 3e-3, 1e-3),
    )
    xy = rng.uniform(-0.35, 0.35, size=(25, 2))
    J = cam.projection_param_jacobian(xy)
    assert J.shape == (25, 2, 16)

    def f(p):
        c = cam.with_params(p)
        return c.pixels_from_normalized(c.distort(xy))

    step = np.array([1e-3] * 4 + [1e-6] * 12)  # px, unitless
    fd = central_jacobian(f, cam.params, step)
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-6)  # px per unit


def test_pose_sensitivity_to_the_camera_matches_refitting(rng):
    cam = reference_camera()
    T = look_at_pose(700, BOARD, tilt_deg=(15, -20, 10), offset_mm=(40, 30))
    det = _detection(BOARD, exact_corners(cam, BOARD, T) + rng.normal(scale=0.05, size=(BOARD.n_corners, 2)))
    p0 = estimate_pose(det, BOARD, cam, refine="corners")
    A = p0.calibration_jacobian
    assert A.shape == (6, 9)
    assert p0.cov_calibration is None  # the reference camera has no uncertainty

    def refit(params):
        p = estimate_pose(det, BOARD, cam.with_params(params), initial=p0.board2cam, refine="corners")
        return _pose_delta(p.board2cam, p0.board2cam)

    step = np.array([0.5, 0.5, 0.5, 0.5, 1e-4, 1e-4, 1e-5, 1e-5, 1e-4])
    fd = central_jacobian(refit, cam.params, step)
    # First order in the residuals (0.05 px here): agreement to a few 1e-3 of each column's size.
    scale = np.abs(fd).max(axis=0, keepdims=True)
    np.testing.assert_allclose(A / scale, fd / scale, atol=5e-3)
    # A focal-length error of 1e-3 moves the board by 1e-3 of its distance along the axis.
    dz = A[2, 0] * cam.fx * 1e-3 + A[2, 1] * cam.fy * 1e-3
    assert dz == pytest.approx(
        1e-3 * T[2, 3] + 1e-3 * (T[:3, :3] @ BOARD.object_points().mean(0))[2], rel=0.05
    )


def test_pose_covariance_is_noise_plus_the_calibration_share(rng):
    cam = _calibrated(reference_camera(), rng)
    assert cam.cov.shape == (9, 9)
    T = look_at_pose(700, BOARD, tilt_deg=(10, -15, 5), offset_mm=(20, 10))
    det = _detection(BOARD, exact_corners(cam, BOARD, T) + rng.normal(scale=0.05, size=(BOARD.n_corners, 2)))
    p = estimate_pose(det, BOARD, cam, refine="corners")
    bare = estimate_pose(det, BOARD, CameraModel(cam.image_size, cam.fx, cam.fy, cam.cx, cam.cy, cam.dist))
    np.testing.assert_allclose(p.cov_noise, bare.cov, rtol=1e-9, atol=1e-15)
    A = p.calibration_jacobian
    np.testing.assert_allclose(p.cov_calibration, A @ cam.cov @ A.T, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(p.cov, bare.cov + p.cov_calibration, rtol=1e-9, atol=1e-15)
    # At 700 mm the calibration's share of the distance's variance is comparable to the noise's.
    assert p.cov_calibration[2, 2] > 0.3 * bare.cov[2, 2]


def test_photometric_pose_follows_the_camera_as_the_corner_fit_predicts():
    cam = small_camera()
    T = look_at_pose(300, BOARD, tilt_deg=(8, -12, 3), offset_mm=(10, 5))
    img = quick_board_image(cam, [(BOARD, T)], rng=np.random.default_rng(3))
    det = detect_board(img, BOARD, camera=cam)
    p0 = estimate_pose(det, BOARD, cam, image=img, refine="photometric")
    assert p0.method == "photometric", p0.fallback
    A = p0.calibration_jacobian
    for k, h in ((0, 2.0), (4, 2e-3)):  # fx (px), k1: a few sigma of a careful calibration

        def refit(x, k=k):
            params = cam.params.copy()
            params[k] = x
            p = estimate_pose(det, BOARD, cam.with_params(params), image=img, refine="photometric")
            assert p.method == "photometric", p.fallback
            return _pose_delta(p.board2cam, p0.board2cam)

        fd = central_jacobian(refit, cam.params[k], h)
        # The approximation (the board's edges, each pinned across itself; no pixel weights,
        # no nuisance parameters): within 8 % of the column (4 % seen for fx and k1).
        np.testing.assert_allclose(A[:3, k], fd[:3], atol=0.08 * np.abs(fd[:3]).max())
        np.testing.assert_allclose(A[3:, k], fd[3:], atol=0.08 * np.abs(fd[3:]).max())


# ---------------------------------------------------------------------- displacements (test-bed)
def _measurement(name, pose, cam):
    return ImageMeasurement(image=name, mobile=pose, calibration_cov=cam.calibration_cov)


def test_displacement_calibration_share_matches_monte_carlo_over_cameras(rng):
    """Cameras drawn from the calibration's covariance, fixed detections: the spread is predicted."""
    truth = reference_camera()
    cam = _calibrated(truth, rng)
    T0 = look_at_pose(700, BOARD, tilt_deg=(10, -15, 5), offset_mm=(20, 10))
    T1 = moved_pose(T0, [20.0, -5.0, 8.0, 0.01, -0.02, 0.005])
    uv0 = exact_corners(truth, BOARD, T0) + rng.normal(scale=0.03, size=(BOARD.n_corners, 2))
    uv1 = exact_corners(truth, BOARD, T1) + rng.normal(scale=0.03, size=(BOARD.n_corners, 2))
    d0, d1 = _detection(BOARD, uv0), _detection(BOARD, uv1)

    def disp(c):
        ms = [
            _measurement(n, estimate_pose(d, BOARD, c, refine="corners"), c)
            for n, d in (("ref", d0), ("moved", d1))
        ]
        return compliant_displacement(ms[:1], ms[1:], frame="cam")

    nominal = disp(cam)
    pred = nominal.cov_calibration
    assert pred is not None and nominal.calibration_jacobian.shape == (6, 9)
    np.testing.assert_allclose(nominal.cov, nominal.cov_noise + pred, rtol=1e-12)
    L = np.linalg.cholesky(cam.cov + 1e-30 * np.eye(9))
    samples = []
    for _ in range(300):
        c = cam.with_params(cam.params + L @ rng.standard_normal(9))
        samples.append(disp(c).vector)
    emp = np.cov(np.array(samples).T)
    ratio = np.sqrt(np.diag(emp) / np.diag(pred))
    print("predicted calibration sigma", np.sqrt(np.diag(pred)), "Monte-Carlo / predicted", ratio)
    # 300 draws: a standard deviation within +/- 4 % (1 sigma); first-order propagation.
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    # Not the sum of the two poses' shares: that would be far larger along the line of sight.
    p0 = estimate_pose(d0, BOARD, cam, refine="corners")
    naive = p0.cov_calibration[2, 2] * 2
    assert pred[2, 2] < 0.5 * naive


def test_calibration_share_does_not_shrink_with_repeats(rng):
    cam = _calibrated(reference_camera(), rng)
    T0 = look_at_pose(700, BOARD, tilt_deg=(10, -15, 5), offset_mm=(20, 10))
    T1 = moved_pose(T0, [0.0, 0.0, 20.0, 0.0, 0.0, 0.0])  # 20 mm along the line of sight

    def ms(T, n, name):
        out = []
        for k in range(n):
            uv = exact_corners(cam, BOARD, T) + rng.normal(scale=0.05, size=(BOARD.n_corners, 2))
            p = estimate_pose(_detection(BOARD, uv), BOARD, cam, refine="corners")
            out.append(_measurement(f"{name}{k}", p, cam))
        return out

    one = compliant_displacement(ms(T0, 1, "u"), ms(T1, 1, "l"), frame="cam")
    five = compliant_displacement(ms(T0, 5, "u"), ms(T1, 5, "l"), frame="cam")
    assert five.pairing == "pairs"
    # Equal to 2 % of the largest translation and rotation variances (the poses differ by noise).
    v5, v1 = np.diag(five.cov_calibration), np.diag(one.cov_calibration)
    np.testing.assert_allclose(v5[:3], v1[:3], atol=0.02 * v1[:3].max())
    np.testing.assert_allclose(v5[3:], v1[3:], atol=0.02 * v1[3:].max())
    np.testing.assert_allclose(np.diag(five.cov_noise), np.diag(one.cov_noise) / 5, rtol=0.3)
    # Along the line of sight a focal-length error is a scale error of the displacement: 20 mm
    # times the focal length's relative sigma (fx and fy move together in a calibration).
    rel_f = np.sqrt(cam.cov[:2, :2].sum() / 4) / (0.5 * (cam.fx + cam.fy))
    assert five.d_sigma_calibration[2] == pytest.approx(20.0 * rel_f, rel=0.3)


def test_camera_without_uncertainty_gives_no_share(rng):
    cam = reference_camera()
    T0 = look_at_pose(700, BOARD)
    ms = [
        _measurement(n, estimate_pose(_detection(BOARD, exact_corners(cam, BOARD, T)), BOARD, cam), cam)
        for n, T in (("a", T0), ("b", moved_pose(T0, [1.0, 0, 0, 0, 0, 0])))
    ]
    d = compliant_displacement(ms[:1], ms[1:], frame="cam")
    assert d.cov_calibration is None and d.calibration_jacobian is not None
    assert np.all(np.isnan(d.calibration_share)) and np.all(np.isnan(d.d_sigma_calibration))


# ------------------------------------------------------------------------ real photographs
@pytest.fixture(scope="module")
def bouguet():
    files = sorted(CALIB_DIR.glob("Image*.tif"), key=lambda p: int(p.stem[5:]))
    return calibrate_files(files, Chessboard(13, 12, 30.0), model="k3")


def test_real_pose_covariance_grows_by_the_calibration_share(bouguet, rng):
    """Bouguet's views: the pose's calibration share against refitting with cameras drawn from it."""
    cam = bouguet.camera
    board = Chessboard(13, 12, 30.0)
    files = sorted(CALIB_DIR.glob("Image*.tif"), key=lambda p: int(p.stem[5:]))
    from stiffmap.vision.images import read_image

    det = detect_board(read_image(files[0]), board, camera=cam)
    p = estimate_pose(det, board, cam, refine="corners")
    L = np.linalg.cholesky(cam.cov)
    draws = []
    for _ in range(300):
        c = cam.with_params(cam.params + L @ rng.standard_normal(len(cam.params)))
        q = estimate_pose(det, board, c, initial=p.board2cam, refine="corners")
        draws.append(_pose_delta(q.board2cam, p.board2cam))
    emp = np.cov(np.array(draws).T)
    ratio = np.sqrt(np.diag(emp) / np.diag(p.cov_calibration))
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    # The distance's 1 sigma grows from the corners' noise alone to nearly twice it (1.8 on Image1).
    grow = np.sqrt(p.cov[2, 2] / p.cov_noise[2, 2])
    assert grow > 1.5, grow
