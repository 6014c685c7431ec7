"""Boards posed before a camera with known ground truth: poses, exact corners, small cameras.

Independent of the library's own pose maths where a test compares against it (the pose
moves by :func:`moved_pose`, the corners by a plain projection).
"""

from __future__ import annotations

import numpy as np

from helpers.random_matrices import random_rotation
from stiffmap.camera import CameraModel
from stiffmap.geometry import matrix_from_euler, matrix_from_rotvec
from stiffmap.targets import Chessboard
from stiffmap.vision import BoardPose


def look_at_pose(distance_mm: float, board: Chessboard, *, tilt_deg=(0.0, 0.0, 0.0), offset_mm=(0.0, 0.0)):
    """A ``board2cam`` pose: the board's centre on the optical axis at ``distance_mm``.

    Parameters
    ----------
    distance_mm : float
        Distance of the board centre along the optical axis, mm.
    tilt_deg : (3,) float
        Rotations about the board's x, y and z axes, degrees (applied in that order).
    offset_mm : (2,) float
        Lateral offset of the board centre (camera x, y), mm.

    Returns
    -------
    ndarray, shape (4, 4)
    """
    R = matrix_from_euler(np.radians(np.asarray(tilt_deg, dtype=float)))
    centre = np.array([(board.cols - 1) * board.square_mm / 2, (board.rows - 1) * board.square_mm / 2, 0.0])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.array([offset_mm[0], offset_mm[1], distance_mm]) - R @ centre
    return T


def two_target_scene(
    rng: np.random.Generator, mobile: Chessboard, fixed: Chessboard
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scene of the displacement tests: a mobile and a fixed target before the camera, and the base.

    The mobile board's centre 700 mm from the camera, the fixed board's 750 mm, both tilted
    and off the axis; ``fixed2base`` a random rotation (drawn from ``rng``) and a translation
    of (120, -80, 310) mm.

    Returns
    -------
    mobile2cam, fixed2cam, fixed2base : ndarray, shape (4, 4), mm
    """
    mobile2cam = look_at_pose(700, mobile, tilt_deg=(10, -15, 5), offset_mm=(20, 10))
    fixed2cam = look_at_pose(750, fixed, tilt_deg=(-5, 20, -3), offset_mm=(-150, 100))
    fixed2base = np.eye(4)
    fixed2base[:3, :3] = random_rotation(rng)
    fixed2base[:3, 3] = [120.0, -80.0, 310.0]
    return mobile2cam, fixed2cam, fixed2base


def close_two_target_poses(mobile: Chessboard, fixed: Chessboard) -> tuple[np.ndarray, np.ndarray]:
    """The rendered two-target scene of :func:`small_camera`: the mobile board 300 mm away, the fixed 340 mm.

    Both tilted a few degrees and off the axis, side by side in the 640x480 image.

    Returns
    -------
    mobile2cam, fixed2cam : ndarray, shape (4, 4), mm
    """
    mobile2cam = look_at_pose(300, mobile, tilt_deg=(8, -12, 3), offset_mm=(38, 28))
    fixed2cam = look_at_pose(340, fixed, tilt_deg=(-5, 10, -2), offset_mm=(-60, -48))
    return mobile2cam, fixed2cam


def moved_pose(T: np.ndarray, delta) -> np.ndarray:
    """The pose moved by a small (dt, dr), left convention of docs/conventions.md.

    t <- t + dt, R <- Exp(dr) R, both in the camera frame.

    Parameters
    ----------
    T : ndarray, shape (4, 4), mm
    delta : array_like, shape (6,)
        (dt (3, mm), dr (3, rad)).

    Returns
    -------
    ndarray, shape (4, 4)
        A new array.
    """
    out = T.copy()
    out[:3, 3] = T[:3, 3] + delta[:3]
    out[:3, :3] = matrix_from_rotvec(delta[3:]) @ T[:3, :3]
    return out


def random_displacement(
    rng: np.random.Generator, magnitude_mm: float, max_rotation_rad: float = 1e-3
) -> np.ndarray:
    """A small (dt (3, mm), dr (3, rad)) for :func:`moved_pose`: a translation of ``magnitude_mm``
    along a random direction and a rotation of up to ``max_rotation_rad`` about a random axis
    (camera frame; the benchmarks' "load" between an unloaded and a loaded image)."""
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    rv = rng.normal(size=3)
    rv *= rng.uniform(0, max_rotation_rad) / np.linalg.norm(rv)
    return np.concatenate([magnitude_mm * u, rv])


def exact_corners(camera: CameraModel, board: Chessboard, board2cam: np.ndarray) -> np.ndarray:
    """Exact pixel positions of the inner corners, shape (n, 2), canonical order."""
    b2c = np.asarray(board2cam, dtype=np.float64)
    return camera.project(board.object_points() @ b2c[:3, :3].T + b2c[:3, 3])


def exact_board_pose(board2cam: np.ndarray, cov: np.ndarray, n_corners: int) -> BoardPose:
    """A measured pose with no residual: ``board2cam`` with covariance ``cov`` (6, 6), from n corners."""
    return BoardPose(
        board2cam=board2cam,
        cov=cov,
        rms_px=0.0,
        n_corners=n_corners,
        residuals_px=np.zeros((n_corners, 2)),
        sigma_px=0.0,
        condition=1.0,
        iterations=0,
    )


def small_camera() -> CameraModel:
    """A 640x480 camera with moderate barrel distortion, for quick tests."""
    return CameraModel((640, 480), 900.0, 905.0, 322.5, 236.0, (-0.12, 0.08, 0.0005, -0.0003, 0.0))


def scaled_camera(camera: CameraModel, s: float) -> CameraModel:
    """The same optics on a sensor with s times fewer pixels per side (same field of view)."""
    w, h = camera.image_size
    return CameraModel(
        (round(w * s), round(h * s)),
        camera.fx * s,
        camera.fy * s,
        (camera.cx + 0.5) * s - 0.5,
        (camera.cy + 0.5) * s - 0.5,
        camera.dist,
    )
