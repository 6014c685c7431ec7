"""Fusion of several cameras' poses of one board (stiffmap.vision.fuse).

Every Jacobian of the fusion is checked by central finite differences: the map of a camera's
pose to the rig frame, the extrinsic sensitivity, the board-symmetry re-expression, and the
fused pose's sensitivity to each view's pose and to every parameter of the rig. The fused
estimate is compared with a joint Gauss-Newton over both cameras' corners, a rig of one camera
with the camera's own pose, and the consistency statistic with its chi-square law.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_scenes import exact_corners
from helpers.finite_difference import central_jacobian
from helpers.random_matrices import random_rotation
from helpers.rig_scenes import board2cams, board_in_rig, rig_camera, stereo_rig

from stiffmap.camera import CameraModel
from stiffmap.geometry import rotvec_from_matrix
from stiffmap.posemath import BoardPose, perturb_pose, projection_jacobian
from stiffmap.rig import Rig, RigCamera
from stiffmap.targets import CharucoBoard, Chessboard
from stiffmap.vision.detection import BoardDetection
from stiffmap.vision.fuse import (
    FUSED_METHOD,
    FusedPose,
    board_symmetries,
    extrinsic_jacobian,
    fuse_poses,
    to_rig_frame,
)
from stiffmap.vision.pose import estimate_pose

BOARD = Chessboard(8, 6, 10.0)  # symmetric: cols + rows even
STEP = np.array([1e-4] * 3 + [1e-7] * 3)  # mm, rad


def tangent(T, T_ref):
    d = np.empty(6)
    d[:3] = T[:3, 3] - T_ref[:3, 3]
    d[3:] = rotvec_from_matrix(T[:3, :3] @ T_ref[:3, :3].T)
    return d


def random_pose(rng, distance=650.0):
    T = np.eye(4)
    T[:3, :3] = random_rotation(rng)
    T[:3, 3] = rng.normal(size=3) * 50 + [0, 0, distance]
    return T


def random_cov(rng, sig_t=1e-3, sig_r=3e-6):
    """A (6, 6) pose covariance with correlations (mm^2, rad^2)."""
    L = rng.normal(size=(6, 6))
    C = L @ L.T + 6 * np.eye(6)
    s = np.array([sig_t] * 3 + [sig_r] * 3)
    return C * np.outer(s, s) / 12


def pose_of(T, cov, A=None, cov_cal=None, n=48):
    total = cov if cov_cal is None else cov + cov_cal
    return BoardPose(
        board2cam=T,
        cov=total,
        rms_px=0.1,
        n_corners=n,
        residuals_px=np.zeros((n, 2)),
        sigma_px=0.1,
        condition=10.0,
        iterations=3,
        method="photometric",
        calibration_jacobian=A,
        cov_calibration=cov_cal,
    )


def cal_cov(camera: CameraModel, rng) -> np.ndarray:
    """A plausible calibration covariance of a camera's 9 parameters (fx fy cx cy k1 k2 p1 p2 k3)."""
    s = np.array([0.5, 0.5, 0.4, 0.4, 2e-3, 8e-3, 5e-5, 5e-5, 2e-2])
    L = rng.normal(size=(9, 9)) * 0.3 + np.eye(9)
    C = L @ L.T
    d = np.sqrt(np.diag(C))
    return C / np.outer(d, d) * np.outer(s, s)


def with_cov(camera: CameraModel, C: np.ndarray) -> CameraModel:
    d = camera.to_dict()
    d["cov"] = {"params": list(camera.param_names), "matrix": C.tolist()}
    return CameraModel.from_dict(d)


def rig_with_joint_cov(rng, n_cams=2) -> Rig:
    """A rig of ``n_cams`` cameras about 60 degrees apart with a full joint covariance."""
    cam = rig_camera()
    base = stereo_rig(cam)
    cams = [base.cameras[0], base.cameras[1]]
    if n_cams == 3:
        c3 = stereo_rig(cam, angle_deg=-45).cameras[1]
        cams.append(RigCamera("top", cam, c3.cam2rig))
    rig = Rig(tuple(cams))
    n = len(rig.param_names)
    L = rng.normal(size=(n, n)) * 0.2 + np.eye(n)
    C = L @ L.T
    d = np.sqrt(np.diag(C))
    scale = np.empty(n)
    for name_i, pn in enumerate(rig.param_names):
        p = pn.split(".")[1]
        scale[name_i] = {"fx": 0.5, "fy": 0.5, "cx": 0.4, "cy": 0.4, "k1": 2e-3, "k2": 8e-3, "p1": 5e-5}.get(
            p, {"p2": 5e-5, "k3": 2e-2, "tx": 0.05, "ty": 0.05, "tz": 0.08}.get(p, 2e-4)
        )
    return Rig(rig.cameras, cov=C / np.outer(d, d) * np.outer(scale, scale))


# ----------------------------------------------------------------------- the maps' Jacobians
def test_to_rig_frame_jacobian_is_the_finite_difference():
    rng = np.random.default_rng(1)
    Tb, C = random_pose(rng), random_pose(rng, 200)
    T0, J = to_rig_frame(Tb, C)
    np.testing.assert_allclose(T0, C @ Tb, atol=1e-12)
    Jfd = central_jacobian(lambda d: tangent(to_rig_frame(perturb_pose(Tb, d), C)[0], T0), np.zeros(6), STEP)
    np.testing.assert_allclose(J, Jfd, atol=1e-7)


def test_extrinsic_jacobian_is_the_finite_difference():
    rng = np.random.default_rng(2)
    Tb, C = random_pose(rng), random_pose(rng, 200)
    E = extrinsic_jacobian(Tb, C)
    Efd = central_jacobian(lambda d: tangent(perturb_pose(C, d) @ Tb, C @ Tb), np.zeros(6), STEP)
    # Rotation steps of 1e-7 rad over a lever of ~700 mm: truncation ~1e-11 mm per mm step.
    np.testing.assert_allclose(E, Efd, atol=1e-6)


def test_board_symmetries_map_the_grid_onto_itself():
    q = BOARD.object_points()
    names = [n for n, _ in board_symmetries(BOARD)]
    assert names == ["none", "half turn"]
    for _, S in board_symmetries(BOARD):
        moved = q @ S[:3, :3].T + S[:3, 3]
        d = np.linalg.norm(moved[:, None, :] - q[None, :, :], axis=2).min(axis=1)
        assert d.max() < 1e-9
    square = Chessboard(7, 7, 5.0)
    assert len(board_symmetries(square)) == 4
    for _, S in board_symmetries(square):
        qs = square.object_points()
        moved = qs @ S[:3, :3].T + S[:3, 3]
        assert np.linalg.norm(moved[:, None] - qs[None], axis=2).min(axis=1).max() < 1e-9
    assert len(board_symmetries(Chessboard(9, 6, 10.0))) == 1  # colours fix the origin
    assert len(board_symmetries(CharucoBoard(9, 7, 10.0, 7.0, "DICT_5X5_100"))) == 1


def test_a_half_turned_view_is_brought_to_the_fused_frame_with_its_covariance():
    """A camera that numbered the symmetric board from the other end: the same physical pose,
    the covariance and sensitivity moved with the map M checked by finite differences."""
    rng = np.random.default_rng(3)
    rig = stereo_rig(rig_camera())
    T_rig = board_in_rig(BOARD, tilt_deg=(5, -4, 20))
    Tc = board2cams(rig, T_rig)
    name, S = board_symmetries(BOARD)[1]
    T1, N1, A1 = Tc[1], random_cov(rng), rng.normal(size=(6, 9)) * 1e-3
    p0 = pose_of(Tc[0], random_cov(rng), rng.normal(size=(6, 9)) * 1e-3)
    straight = fuse_poses(rig, {0: p0, 1: pose_of(T1, N1, A1)}, board=BOARD)
    # The same view numbered from the other end: pose T S, noise and sensitivity moved by
    # M = d(T S)/d(T) (left perturbations), here from finite differences.
    M = central_jacobian(lambda d: tangent(perturb_pose(T1, d) @ S, T1 @ S), np.zeros(6), STEP)
    turned_view = pose_of(T1 @ S, M @ N1 @ M.T, M @ A1)
    turned = fuse_poses(rig, {0: p0, 1: turned_view}, board=BOARD, reference=straight.board2rig)
    assert turned.views[1].symmetry == name and straight.views[1].symmetry == "none"
    np.testing.assert_allclose(turned.board2rig, straight.board2rig, atol=1e-9)
    np.testing.assert_allclose(turned.cov_noise, straight.cov_noise, rtol=1e-6, atol=1e-16)
    np.testing.assert_allclose(
        turned.calibration_jacobian, straight.calibration_jacobian, rtol=1e-6, atol=1e-12
    )


# -------------------------------------------------------------- the fused pose's Jacobians
@pytest.mark.parametrize("n_cams", [2, 3])
def test_fused_sensitivities_are_the_finite_differences(n_cams):
    """d fused / d (each view's pose) and d fused / d (every rig parameter), views consistent.

    The fused pose as a function of the views' poses (each moved in its camera frame) and of
    the rig's parameters (intrinsics move each camera's pose by its A_k, extrinsics move the
    camera in the rig) is differentiated numerically and compared with (sum W)^-1 W_k J_k and
    with ``calibration_jacobian``; the noise propagated through the former is ``cov_noise``.
    """
    rng = np.random.default_rng(10 + n_cams)
    rig = rig_with_joint_cov(rng, n_cams)
    T_rig = board_in_rig(BOARD, tilt_deg=(6, -3, 10), offset_mm=(4, -6))
    Tc = board2cams(rig, T_rig)
    Ns = [random_cov(rng) for _ in Tc]
    As = [rng.normal(size=(6, 9)) * np.array([2e-3, 2e-3, 2e-2, 1e-6, 1e-6, 1e-5])[:, None] for _ in Tc]
    views = {k: pose_of(Tc[k], Ns[k], As[k]) for k in range(len(Tc))}
    fused = fuse_poses(rig, views, board=BOARD)
    np.testing.assert_allclose(fused.board2rig, T_rig, atol=1e-9)
    assert fused.chi2 < 1e-6 and fused.dof == 6 * (n_cams - 1) and fused.consistency_warning is None

    # Sensitivity to each view's own pose (camera frame): G_k, and sum G_k N_k G_k^T = cov_noise.
    cov = np.zeros((6, 6))
    for k in range(len(Tc)):

        def moved(d, k=k):
            vs = dict(views)
            vs[k] = pose_of(perturb_pose(Tc[k], d), Ns[k], As[k])
            return tangent(fuse_poses(rig, vs, board=BOARD).board2rig, fused.board2rig)

        G = central_jacobian(moved, np.zeros(6), STEP)
        cov += G @ Ns[k] @ G.T
    np.testing.assert_allclose(cov, fused.cov_noise, rtol=1e-5, atol=1e-18)

    # Sensitivity to the rig's parameters.
    names = rig.param_names

    def with_params(p):
        cams = []
        vs = {}
        for k, c in enumerate(rig.cameras):
            si = rig.intrinsic_slice(k)
            vs[k] = pose_of(perturb_pose(Tc[k], As[k] @ p[si]), Ns[k], As[k])
            se = rig.extrinsic_slice(k)
            C = c.cam2rig if se is None else perturb_pose(c.cam2rig, p[se])
            cams.append(RigCamera(c.name, c.camera, C))
        return tangent(fuse_poses(Rig(tuple(cams)), vs, board=BOARD).board2rig, fused.board2rig)

    steps = np.array([1e-4 if n.split(".")[1] in ("tx", "ty", "tz") else 1e-6 for n in names])
    Afd = central_jacobian(with_params, np.zeros(len(names)), steps)
    A = fused.calibration_jacobian
    assert A.shape == (6, len(names))
    scale = np.abs(A).max(axis=1, keepdims=True)
    np.testing.assert_allclose(A / scale, Afd / scale, atol=1e-6)
    np.testing.assert_allclose(fused.cov_calibration, A @ rig.cov @ A.T, rtol=1e-12)
    np.testing.assert_allclose(fused.cov, fused.cov_noise + fused.cov_calibration, rtol=1e-12)


# --------------------------------------------------------------------------- one camera
def test_a_rig_of_one_camera_gives_the_cameras_own_pose():
    rng = np.random.default_rng(4)
    cam = with_cov(rig_camera(), cal_cov(rig_camera(), rng))
    T = random_pose(rng)
    A = rng.normal(size=(6, 9)) * 1e-3
    Sc = cam.calibration_cov
    p = pose_of(T, random_cov(rng), A, 0.5 * (A @ Sc @ A.T + (A @ Sc @ A.T).T))
    f = fuse_poses(Rig.single(cam), {0: p})
    assert isinstance(f, FusedPose) and f.cameras == ("camera",) and f.dof == 0
    np.testing.assert_array_equal(f.board2rig, p.board2cam)
    np.testing.assert_array_equal(f.board2cam, p.board2cam)  # one camera: its own frame's pose
    np.testing.assert_allclose(f.cov, p.cov, rtol=1e-12, atol=0)
    np.testing.assert_allclose(f.cov_noise, p.cov_noise, rtol=1e-12, atol=1e-24)
    np.testing.assert_array_equal(f.calibration_jacobian, p.calibration_jacobian)
    assert (f.method, f.rms_px, f.n_corners, f.fallback) == (p.method, p.rms_px, p.n_corners, p.fallback)


def test_a_board_seen_by_the_second_camera_only_is_mapped_to_the_rig_frame():
    rng = np.random.default_rng(5)
    rig = stereo_rig(rig_camera())
    T_rig = board_in_rig(BOARD, tilt_deg=(3, 2, 1))
    Tc = board2cams(rig, T_rig)
    N = random_cov(rng)
    f = fuse_poses(rig, {"right": pose_of(Tc[1], N, np.zeros((6, 9)))}, board=BOARD)
    np.testing.assert_allclose(f.board2rig, T_rig, atol=1e-9)
    np.testing.assert_allclose(f.board2cam, Tc[1], atol=1e-9)  # the right camera's own pose
    both = fuse_poses(rig, {"left": pose_of(Tc[0], N, np.zeros((6, 9))), "right": f.views[0].pose})
    with pytest.raises(AttributeError, match="fused from 2 cameras has no one camera frame: read board2rig"):
        _ = both.board2cam
    R = rig.cameras[1].cam2rig[:3, :3]
    J = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), R]])
    np.testing.assert_allclose(f.cov_noise, J @ N @ J.T, rtol=1e-12, atol=1e-20)
    assert f.cameras == ("right",) and f.method == "photometric"
    # The extrinsic columns: the camera's pose in the rig moves the board with it.
    np.testing.assert_allclose(
        f.calibration_jacobian[:, rig.extrinsic_slice(1)], extrinsic_jacobian(Tc[1], rig.cameras[1].cam2rig)
    )


# ----------------------------------------------------- fused = joint fit to first order
def _corner_view(camera, T, rng, noise_px):
    uv = exact_corners(camera, BOARD, T) + rng.normal(size=(BOARD.n_corners, 2)) * noise_px
    n = BOARD.n_corners
    det = BoardDetection(board=BOARD, corners=uv, ids=np.arange(n), residual_px=np.zeros(n))
    return det, estimate_pose(det, BOARD, camera, refine="corners")


def _joint_gauss_newton(rig, dets, sigmas, T0, iters=10):
    """board2rig minimising sum_k sum_i |pi_k(...) - uv_ki|^2 / s_k^2 over both cameras' corners."""
    T = T0.copy()
    q = BOARD.object_points()
    for _ in range(iters):
        H = np.zeros((6, 6))
        g = np.zeros(6)
        for c, det, s in zip(rig.cameras, dets, sigmas, strict=True):
            Rc = c.cam2rig[:3, :3]
            Tk = np.linalg.inv(c.cam2rig) @ T
            uv, J = projection_jacobian(Tk, q, c.camera)
            Jr = J.reshape(-1, 6) @ np.block([[Rc.T, np.zeros((3, 3))], [np.zeros((3, 3)), Rc.T]])
            e = (uv - det.corners).reshape(-1)
            H += Jr.T @ Jr / s**2
            g += Jr.T @ e / s**2
        T = perturb_pose(T, -np.linalg.solve(H, g))
    return T, np.linalg.inv(H)


def test_the_fused_pose_is_the_joint_fit_of_both_cameras_corners():
    rng = np.random.default_rng(6)
    rig = stereo_rig(rig_camera())
    for trial in range(3):
        T_rig = board_in_rig(BOARD, tilt_deg=rng.uniform(-10, 10, 3), offset_mm=rng.uniform(-10, 10, 2))
        views = [
            _corner_view(c.camera, T, rng, 0.15)
            for c, T in zip(rig.cameras, board2cams(rig, T_rig), strict=True)
        ]
        fused = fuse_poses(rig, {k: v[1] for k, v in enumerate(views)}, board=BOARD)
        sig = [v[1].sigma_px for v in views]
        T_joint, cov_joint = _joint_gauss_newton(rig, [v[0] for v in views], sig, fused.board2rig)
        d = tangent(T_joint, fused.board2rig)
        z = float(np.sqrt(d @ np.linalg.solve(fused.cov_noise, d)))
        assert z < 0.02, (trial, z)  # a small fraction of one sigma
        # The same covariance: every direction's variance within 2 % (generalised eigenvalues).
        ratios = np.linalg.eigvals(np.linalg.solve(cov_joint, fused.cov_noise)).real
        assert np.all(np.abs(ratios - 1) < 0.02), ratios
        # And the fused pose is within its sigma of the truth (chi2 over 6 dof below 99.9 %).
        e = tangent(fused.board2rig, T_rig)
        assert e @ np.linalg.solve(fused.cov_noise, e) < 22.5


# ------------------------------------------------------------------------ consistency
def test_consistency_statistic_follows_its_law_with_the_calibration_error():
    """Views drawn with their noise and a common calibration error (joint rig covariance):
    chi2 has mean 6 (n - 1); with the calibration error left out of V it would be far larger."""
    rng = np.random.default_rng(7)
    rig = rig_with_joint_cov(rng, 3)
    T_rig = board_in_rig(BOARD, tilt_deg=(5, 5, 5))
    Tc = board2cams(rig, T_rig)
    Ns = [random_cov(rng, 3e-4, 1e-6) for _ in Tc]
    As = [rng.normal(size=(6, 9)) * np.array([2e-3, 2e-3, 2e-2, 1e-6, 1e-6, 1e-5])[:, None] for _ in Tc]
    Lc = np.linalg.cholesky(rig.cov + 1e-30 * np.eye(len(rig.param_names)))
    chis, warned = [], 0
    for _ in range(300):
        p = Lc @ rng.normal(size=len(rig.param_names))
        cams, vs = [], {}
        for k, c in enumerate(rig.cameras):
            si, se = rig.intrinsic_slice(k), rig.extrinsic_slice(k)
            noise = np.linalg.cholesky(Ns[k]) @ rng.normal(size=6)
            vs[k] = pose_of(perturb_pose(Tc[k], As[k] @ p[si] + noise), Ns[k], As[k])
            # The rig file holds the calibrated (erroneous) poses: the truth is perturbed by -p.
            cams.append(
                RigCamera(c.name, c.camera, c.cam2rig if se is None else perturb_pose(c.cam2rig, -p[se]))
            )
        f = fuse_poses(Rig(tuple(cams), cov=rig.cov), vs, board=BOARD)
        chis.append(f.chi2)
        warned += f.consistency_warning is not None
    chis = np.array(chis)
    # Mean 12 with standard error sqrt(2 * 12 / 300) = 0.28.
    assert abs(chis.mean() - 12) < 1.2, chis.mean()
    assert warned <= 1


def test_a_wrong_rig_file_is_named():
    rng = np.random.default_rng(8)
    rig = stereo_rig(rig_camera())
    T_rig = board_in_rig(BOARD)
    Tc = board2cams(rig, T_rig)
    N = random_cov(rng)
    # The right camera moved by 0.5 mm since the rig was calibrated.
    moved = perturb_pose(rig.cameras[1].cam2rig, [0.5, 0, 0, 0, 0, 0])
    Tc1 = np.linalg.inv(moved) @ T_rig
    f = fuse_poses(rig, {0: pose_of(Tc[0], N), 1: pose_of(Tc1, N)}, board=BOARD, label="mobile target")
    assert f.consistency_warning is not None
    for needle in ("mobile target", "chi2", "left", "right", "rig file", "camera move"):
        assert needle in f.consistency_warning
    assert f.p_value < 1e-4 and f.method == FUSED_METHOD


def test_bad_arguments_are_named():
    rig = stereo_rig(rig_camera())
    p = pose_of(np.eye(4), np.eye(6) * 1e-6)
    with pytest.raises(ValueError, match="at least one"):
        fuse_poses(rig, {})
    with pytest.raises(ValueError, match="out of range"):
        fuse_poses(rig, {2: p})
    with pytest.raises(ValueError, match="no camera 'middle'"):
        fuse_poses(rig, {"middle": p})
    with pytest.raises(ValueError, match=r"calibration_jacobian must be \(6, 9\)"):
        fuse_poses(rig, {0: pose_of(np.eye(4), np.eye(6) * 1e-6, np.zeros((6, 4)))})
