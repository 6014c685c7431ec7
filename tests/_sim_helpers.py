"""Shared helpers of the virtual test-bed's tests (tests/test_sim_*.py)."""

from __future__ import annotations

import numpy as np

from stiffmap.camera import CameraModel
from stiffmap.sim.scene import board_pose_at_pixel as pose_at_pixel  # noqa: F401


def brute_force_reflectance(camera: CameraModel, target, roi, n: int = 64, background: float = 0.35):
    """Reference render: n x n point samples per pixel, each mapped exactly (no linearisation).

    Every sub-sample's ray is undistorted by Newton's method
    (``CameraModel.rays_from_pixels``) and met with the board plane; the print is
    point-sampled. Independent of the renderer's coverage formulas; its own error
    on an edge pixel is at most about 1/n of the contrast.
    """
    c0, r0, c1, r1 = roi
    off = (np.arange(n) + 0.5) / n - 0.5
    cols = np.arange(c0, c1, dtype=np.float64)
    rows = np.arange(r0, r1, dtype=np.float64)
    U = cols[None, :, None, None] + off[None, None, None, :]
    V = rows[:, None, None, None] + off[None, None, :, None]
    U, V = np.broadcast_arrays(U, V)
    rays = camera.rays_from_pixels(np.stack([U, V], axis=-1))
    d = np.concatenate([rays, np.ones((*rays.shape[:-1], 1))], axis=-1)
    T = target.board2cam
    R, t = T[:3, :3], T[:3, 3]
    lam = (R[:, 2] @ t) / (d @ R[:, 2])
    p = lam[..., None] * d - t
    refl, alpha = target.texture().sample(p @ R[:, 0], p @ R[:, 1])
    return (refl * alpha + (1 - alpha) * background).mean(axis=(2, 3))
