"""Tracking a board along a sequence: the previous image's corners refined in the next image.

In a sequence the previous image's corners seed the sub-pixel refinement directly; the
result is accepted only when every corner converged, none moved more than a quarter of a
square from its seed, every corner fits the homography, and the board does not continue one
step outside the tracked grid; otherwise the caller runs the full detection
(:func:`~stiffmap.vision.detect.detect_boards`). The last check catches a board that moved by
about a whole square between the images: every seed then lands near the neighbouring corner
and the grid fits perfectly, numbered one square off (the board's outer corners meet its
margin in junctions that refine like corners).
"""

from __future__ import annotations

import time

import numpy as np

from ..camera import CameraModel
from .board_plane import (
    REJECT_PX,
    apply_homography,
    fit_homography,
    fit_residuals,
    saddle_score,
    side_with_corners,
)
from .corners import refine_corners
from .detection import BoardDetection, grid_of
from .images import check_image

__all__ = ["track_board", "followed_detection"]


def track_board(
    image,
    previous: BoardDetection,
    *,
    camera: CameraModel | None = None,
    reject_px: float = REJECT_PX,
    max_shift: float = 0.25,
) -> BoardDetection | None:
    """Refine the previous image's corners in a new image, or None when that is not safe.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
    previous : BoardDetection
        The same board in the previous image of the sequence.
    camera : CameraModel, optional
        For residuals in undistorted coordinates.
    reject_px : float
        Floor of the residual threshold, px.
    max_shift : float
        Largest accepted corner motion from its seed, in squares.

    Returns
    -------
    BoardDetection or None
        None when a corner moved more than ``max_shift`` squares, a corner does not
        fit the homography, the board continues outside the grid, or the corners leave the
        image: the caller then runs the full detection.
    """
    t0 = time.perf_counter()
    img = check_image(image)
    seeds = previous.corners
    if seeds.shape[0] < 4:
        return None
    h, w = img.shape
    win = int(previous.window_px) or 5
    if (
        seeds[:, 0].min() < win + 1
        or seeds[:, 1].min() < win + 1
        or seeds[:, 0].max() > w - win - 2
        or seeds[:, 1].max() > h - win - 2
    ):
        return None
    new, ok = refine_corners(img, seeds, win)
    if not ok.all():
        return None
    cb = grid_of(previous.board)
    obj_xy = cb.object_points()[previous.ids, :2]
    H = fit_homography(obj_xy / cb.square_mm, seeds)
    step = np.linalg.norm(apply_homography(H, obj_xy / cb.square_mm + [1.0, 0.0]) - seeds, axis=1)
    if np.any(np.linalg.norm(new - seeds, axis=1) > max_shift * step):
        return None
    res, _ = fit_residuals(new, obj_xy, camera)
    sigma = 1.4826 * np.median(res)
    if np.any(res > max(reject_px, 5.0 * sigma)):
        return None
    # Numbered one square off (the board moved by about a square): corners just outside the grid.
    H_new = fit_homography(obj_xy / cb.square_mm, new)
    contrast = float(np.median(saddle_score(img, H_new, obj_xy / cb.square_mm)))
    if side_with_corners(img, H_new, cb.cols, cb.rows, contrast) is not None:
        return None
    return BoardDetection(
        board=previous.board,
        corners=new,
        ids=previous.ids.copy(),
        residual_px=res,
        tracked=True,
        window_px=win,
        scale=0,
        orientation="tracked",
        phase=previous.phase,
        rejected=np.zeros(0, dtype=int),
        seconds=time.perf_counter() - t0,
    )


def followed_detection(previous: BoardDetection, board2cam: np.ndarray, camera: CameraModel, seconds: float):
    """The detection of a board followed by its photometric fit alone (no corners measured).

    Its ``corners`` are the previous detection's corners projected at the fitted pose
    (``board2cam``), its ``residual_px`` NaN (not measured), ``orientation`` ``"photometric"``
    (see :func:`~stiffmap.vision.pose.follow_pose`); they seed the next image's tracking.
    """
    obj = previous.object_points()
    corners = camera.project(obj @ board2cam[:3, :3].T + board2cam[:3, 3])
    return BoardDetection(
        board=previous.board,
        corners=corners,
        ids=previous.ids.copy(),
        residual_px=np.full(previous.ids.size, np.nan),
        tracked=True,
        window_px=previous.window_px,
        scale=0,
        orientation="photometric",
        phase=previous.phase,
        rejected=np.zeros(0, dtype=int),
        seconds=seconds,
    )
