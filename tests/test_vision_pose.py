"""Pose estimation: analytic Jacobian, covariance against Monte Carlo, accuracy on rendered images."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import exact_corners, look_at_pose, moved_pose, two_target_scene
from helpers.finite_difference import central_jacobian
from helpers.random_matrices import random_rotation

from stiffmap.camera import reference_camera
from stiffmap.geometry import rotvec_from_matrix
from stiffmap.targets import Chessboard
from stiffmap.vision import (
    BoardDetection,
    DetectionError,
    detect_board,
    estimate_pose,
    mobile2base_from_poses,
    projection_jacobian,
)

CAM = reference_camera()
BOARD = Chessboard(8, 6, 10.0)


def _pose_error(T_est, T_true):
    dr = rotvec_from_matrix(T_est[:3, :3] @ T_true[:3, :3].T)
    return np.concatenate([T_est[:3, 3] - T_true[:3, 3], dr])


def _synthetic_detection(T, sigma_px, rng):
    uv = exact_corners(CAM, BOARD, T) + rng.normal(scale=sigma_px, size=(BOARD.n_corners, 2))
    return BoardDetection(
        board=BOARD, corners=uv, ids=np.arange(BOARD.n_corners), residual_px=np.zeros(BOARD.n_corners)
    )


def test_projection_jacobian_matches_finite_differences(rng):
    T = look_at_pose(620, BOARD, tilt_deg=(20, -30, 40), offset_mm=(60, -40))
    obj = BOARD.object_points()
    _, J = projection_jacobian(T, obj, CAM)
    h = np.array([1e-4] * 3 + [1e-7] * 3)  # mm, rad
    fd = central_jacobian(lambda e: projection_jacobian(moved_pose(T, e), obj, CAM)[0], np.zeros(6), h)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-4)


def test_pose_covariance_matches_monte_carlo(rng):
    T = look_at_pose(800, BOARD, tilt_deg=(15, -20, 10), offset_mm=(40, 30))
    sigma = 0.05  # px
    errs, covs = [], []
    for _ in range(300):
        p = estimate_pose(_synthetic_detection(T, sigma, rng), BOARD, CAM)
        errs.append(_pose_error(p.board2cam, T))
        covs.append(p.cov)
    E = np.array(errs)
    emp = np.cov(E.T)
    pred = np.mean(covs, axis=0)
    ratio = np.diag(emp) / np.diag(pred)
    assert np.all((ratio > 0.75) & (ratio < 1.33)), ratio  # 300 draws: +/- 8 % (1 sigma) on a variance
    # Mean error within 4 standard errors of zero: the estimator is unbiased.
    assert np.all(np.abs(E.mean(axis=0)) < 4 * np.sqrt(np.diag(emp) / len(E)))
    # Correlations as predicted (the depth-tilt coupling of a small board).
    corr_pred = pred / np.sqrt(np.outer(np.diag(pred), np.diag(pred)))
    corr_emp = emp / np.sqrt(np.outer(np.diag(emp), np.diag(emp)))
    np.testing.assert_allclose(corr_emp, corr_pred, atol=0.15)


def test_initial_guess_converges_to_the_same_pose(rng):
    T = look_at_pose(550, BOARD, tilt_deg=(-25, 15, 170), offset_mm=(-30, 20))
    det = _synthetic_detection(T, 0.03, rng)
    p0 = estimate_pose(det, BOARD, CAM)
    start = moved_pose(T, np.array([2.0, -1.5, 8.0, 0.02, -0.03, 0.01]))
    p1 = estimate_pose(det, BOARD, CAM, initial=start)
    np.testing.assert_allclose(p1.board2cam, p0.board2cam, atol=1e-7)
    assert p1.sigma_px == pytest.approx(0.03, rel=0.25)


@pytest.mark.parametrize("seed", range(3))
def test_frontal_boards_and_random_poses_are_recovered(seed):
    rng = np.random.default_rng(seed)
    n = 0
    while n < 20:
        R = random_rotation(rng)
        if R[2, 2] < 0.5:  # keep boards facing the camera (z within 60 degrees of the axis)
            continue
        n += 1
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [rng.uniform(-60, 60), rng.uniform(-40, 40), rng.uniform(500, 900)]
        p = estimate_pose(_synthetic_detection(T, 1e-3, rng), BOARD, CAM)
        e = _pose_error(p.board2cam, T)
        assert np.all(np.abs(e) < 6 * np.sqrt(np.diag(p.cov)) + 1e-9)


def test_rendered_image_pose_within_its_covariance():
    T = look_at_pose(700, BOARD, tilt_deg=(10, -15, 5), offset_mm=(20, 10))
    img = quick_board_image(CAM, [(BOARD, T)], rng=np.random.default_rng(11))
    p = estimate_pose(detect_board(img, BOARD, camera=CAM), BOARD, CAM)
    e = _pose_error(p.board2cam, T)
    z = e / np.sqrt(np.diag(p.cov))
    assert np.all(np.abs(z) < 5), z
    assert abs(e[2]) < 0.05  # mm along the optical axis
    assert np.all(np.abs(e[:2]) < 0.005)  # mm across it
    assert p.rms_px < 0.05  # px


def test_too_few_corners_and_board_mismatch(rng):
    T = look_at_pose(700, BOARD)
    det = _synthetic_detection(T, 0.05, rng)
    few = BoardDetection(board=BOARD, corners=det.corners[:3], ids=det.ids[:3], residual_px=np.zeros(3))
    with pytest.raises(DetectionError, match="too few") as e:
        estimate_pose(few, BOARD, CAM, source="x.png")
    assert str(e.value).startswith("x.png:")
    with pytest.raises(ValueError, match="asked for"):
        estimate_pose(det, Chessboard(9, 6, 10.0), CAM)


def test_mobile2base_covariance_by_monte_carlo(rng):
    M, F, B = two_target_scene(rng, BOARD, Chessboard(12, 7, 10.0))
    A = rng.normal(size=(6, 6))
    Cm = A @ A.T * 1e-6
    A = rng.normal(size=(6, 6))
    Cf = A @ A.T * 1e-6
    T0, cov = mobile2base_from_poses(M, Cm, F, Cf, B)
    np.testing.assert_allclose(T0, B @ np.linalg.inv(F) @ M, atol=1e-9)
    Lm, Lf = np.linalg.cholesky(Cm), np.linalg.cholesky(Cf)
    errs = []
    for _ in range(4000):
        Mi = moved_pose(M, Lm @ rng.normal(size=6))
        Fi = moved_pose(F, Lf @ rng.normal(size=6))
        errs.append(_pose_error(B @ np.linalg.inv(Fi) @ Mi, T0))
    emp = np.cov(np.array(errs).T)
    np.testing.assert_allclose(emp, cov, atol=0.08 * np.sqrt(np.outer(np.diag(cov), np.diag(cov))).max())
    np.testing.assert_allclose(np.diag(emp) / np.diag(cov), 1.0, atol=0.1)
