"""OpenCV's own chessboard corners near known ones: a reference detector beside stiffmap's vision code."""

from __future__ import annotations

import cv2
import numpy as np


def opencv_corners_near(
    image: np.ndarray, truth_uv: np.ndarray, pattern: tuple[int, int], margin_px: int, half_window: int
) -> np.ndarray | None:
    """``findChessboardCornersSB`` + ``cornerSubPix`` on a crop around the board.

    The crop (the true corners' bounding box grown by ``margin_px``) only bounds the search.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
    truth_uv : ndarray, shape (n, 2), px
        The board's true corners.
    pattern : (cols, rows)
        Inner corners of the board.
    margin_px : int
    half_window : int
        ``cornerSubPix``'s half window, px.

    Returns
    -------
    ndarray, shape (n, 2), px, or None when the board is not found
        In OpenCV's numbering (which may start at either end of the board).
    """
    lo = np.maximum(np.floor(truth_uv.min(axis=0)).astype(int) - margin_px, 0)
    hi = np.ceil(truth_uv.max(axis=0)).astype(int) + margin_px
    crop = np.ascontiguousarray(image[lo[1] : hi[1], lo[0] : hi[0]])
    ok, c = cv2.findChessboardCornersSB(crop, pattern, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    win = (half_window, half_window)
    return cv2.cornerSubPix(crop, c, win, (-1, -1), crit).reshape(-1, 2).astype(np.float64) + lo
