"""ChArUco boards: corners identified by the markers in the white squares.

OpenCV's ``CharucoDetector`` runs on the reduced image (the scales of the chessboard
search); the markers identify each corner, so a partly hidden board still gives the
visible corners with their canonical ids. The corners are then refined at full
resolution and those off the board's plane rejected, as for chessboards.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from ..camera import CameraModel
from ..targets import CharucoBoard
from .board_plane import apply_homography, fit_homography, reject_outliers, window_for
from .corners import refine_corners
from .detection import BoardDetection, DetectionError, board_label
from .images import coarse_scales, reduce_image

__all__ = ["detect_charuco"]


def _charuco_detector(board: CharucoBoard):
    try:
        dic = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    except AttributeError:
        raise ValueError(f"unknown ArUco dictionary {board.dictionary!r}") from None
    cb = cv2.aruco.CharucoBoard((board.squares_x, board.squares_y), board.square_mm, board.marker_mm, dic)
    return cv2.aruco.CharucoDetector(cb)


def detect_charuco(
    image: np.ndarray,
    board: CharucoBoard,
    camera: CameraModel | None,
    scale: int | None,
    reject_px: float,
    min_corners: int,
    t0: float,
) -> BoardDetection:
    det = _charuco_detector(board)
    cb = board.chessboard
    best = None
    for s in coarse_scales(image.shape, scale):
        small = reduce_image(image, s)
        cc, cid, _, mid = det.detectBoard(small)
        n = 0 if cid is None else len(cid)
        if best is None or n > best[2]:
            best = (cc, cid, n, s, 0 if mid is None else len(mid))
        if n >= min_corners:
            break
    cc, cid, n, s, n_markers = best
    if n < min_corners:
        if n_markers == 0:
            raise DetectionError(
                f"no {board_label(board)} found (no {board.dictionary} markers in the image)",
                reason="not_found",
            )
        raise DetectionError(
            f"{board_label(board)}: only {n} corners identified ({n_markers} markers seen); "
            f"at least {min_corners} are needed (board mostly hidden, or wrong dictionary/size)",
            reason="partial",
        )
    ids = cid.ravel().astype(int)
    pts = cc.reshape(-1, 2).astype(np.float64) * s + (s - 1) / 2
    order = np.argsort(ids)
    ids = ids[order]
    pts = pts[order]
    # Local square size from the homography of the identified corners.
    obj_xy = cb.object_points()[ids, :2]
    H = fit_homography(obj_xy / cb.square_mm, pts)
    step = np.linalg.norm(apply_homography(H, obj_xy / cb.square_mm + [1.0, 0.0]) - pts, axis=1)
    win = window_for(float(np.median(step)), float(step.min()))
    pts, ok = refine_corners(image, pts, win)
    failed = ids[~ok]
    corners, ids, res, rejected = reject_outliers(pts[ok], ids[ok], obj_xy[ok], camera, reject_px)
    rejected = np.sort(np.concatenate([rejected, failed]))
    if len(ids) < min_corners:
        raise DetectionError(
            f"{board_label(board)}: only {len(ids)} corners fit the board's plane", reason="partial"
        )
    return BoardDetection(
        board=board,
        corners=corners,
        ids=ids,
        residual_px=res,
        tracked=False,
        window_px=win,
        scale=s,
        orientation="markers",
        rejected=rejected,
        seconds=time.perf_counter() - t0,
    )
