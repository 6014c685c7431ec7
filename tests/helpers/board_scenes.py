"""Boards posed before a camera with known ground truth: poses, exact corners, small cameras.

Independent of the library's own pose maths where a test compares against it (the corners
by a plain projection).
"""

from __future__ import annotations

import numpy as np

from stiffmap.camera import CameraModel
from stiffmap.geometry import matrix_from_euler
from stiffmap.targets import Chessboard


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


def exact_corners(camera: CameraModel, board: Chessboard, board2cam: np.ndarray) -> np.ndarray:
    """Exact pixel positions of the inner corners, shape (n, 2), canonical order."""
    b2c = np.asarray(board2cam, dtype=np.float64)
    return camera.project(board.object_points() @ b2c[:3, :3].T + b2c[:3, 3])


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
