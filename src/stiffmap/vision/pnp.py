"""A board's first pose from its corners through any lens model (OpenCV's ``solvePnP``).

OpenCV's ``solvePnP`` knows the pinhole model with the polynomial distortion; a camera with
another lens model (:data:`stiffmap.camera.LENS_MODELS`: the fisheye model) gives it the
corners' undistorted rays (x/z, y/z) instead, with the identity camera matrix and no
distortion: the same problem, since a ray is what a pixel means to any model. The pose is
only the start of the reprojection fit in pixels (:mod:`stiffmap.vision.pose`), which uses
the camera's own model.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..camera import CameraModel, UndistortionError

__all__ = ["solve_pnp"]


def solve_pnp(
    camera: CameraModel, object_points, corners, flags: int = cv2.SOLVEPNP_ITERATIVE
) -> tuple[bool, np.ndarray, np.ndarray]:
    """``cv2.solvePnP`` of board points and their pixels through ``camera``'s lens model.

    Parameters
    ----------
    camera : CameraModel
    object_points : array_like, shape (m, 3)
        Board points, mm.
    corners : array_like, shape (m, 2)
        Their pixels, px.
    flags : int
        OpenCV's method (``cv2.SOLVEPNP_*``).

    Returns
    -------
    ok : bool
        False when OpenCV finds no pose, or a corner has no ray (beyond the lens model's field).
    rvec, tvec : ndarray, shape (3, 1)
        board2cam's rotation vector (rad) and translation (mm), OpenCV's.
    """
    obj = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    uv = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if camera.model == "opencv":
        return cv2.solvePnP(obj, uv, camera.matrix, camera.dist_array, flags=flags)
    try:
        rays = camera.rays_from_pixels(uv)
    except UndistortionError:
        return False, np.zeros((3, 1)), np.zeros((3, 1))
    return cv2.solvePnP(obj, rays, np.eye(3), None, flags=flags)
