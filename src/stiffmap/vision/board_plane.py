"""The board plane in the image: homographies from the board to the pixels and what they check.

A planar board's corners are related to their pixels by a homography (up to the lens
distortion). The detectors use it to sample the image at board points (the saddle
contrast of a corner, the checkerboard contrast of a grid, whether the printed board
continues beyond the grid found), to measure how well corners fit the board's plane and
reject those that do not, to mask a board found before the next search, and to size the
corner-refinement window from the local square size.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..camera import CameraModel, UndistortionError
from .detection import BoardDetection, DetectionError, grid_of

__all__ = [
    "REJECT_PX",
    "WINDOW_FRACTION",
    "apply_homography",
    "board_continues",
    "side_with_corners",
    "detection_mask",
    "fit_homography",
    "fit_residuals",
    "grid_contrast",
    "grid_edge_fraction",
    "grid_spacing",
    "mask_polygon",
    "reject_outliers",
    "corner_saddles",
    "saddle_score",
    "sample_bilinear",
    "trim_to_saddles",
    "window_for",
]

#: Window half-size of cornerSubPix as a fraction of the local square size.
WINDOW_FRACTION = 0.25
#: Default absolute floor of the corner-rejection threshold, px.
REJECT_PX = 0.5


def sample_bilinear(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear grey level at points (..., 2) (x, y) px; points outside are clamped."""
    h, w = image.shape
    x = np.clip(pts[..., 0], 0, w - 1.001)
    y = np.clip(pts[..., 1], 0, h - 1.001)
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    fx = x - x0
    fy = y - y0
    im = image
    a = im[y0, x0] * (1 - fx) + im[y0, x0 + 1] * fx
    b = im[y0 + 1, x0] * (1 - fx) + im[y0 + 1, x0 + 1] * fx
    return a * (1 - fy) + b * fy


def fit_homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares homography (normalised DLT through OpenCV) mapping src (n, 2) to dst (n, 2)."""
    H, _ = cv2.findHomography(src.astype(np.float64), dst.astype(np.float64), 0)
    if H is None:
        raise DetectionError("degenerate corner layout (homography fit failed)", reason="partial")
    return H


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = pts @ H[:, :2].T + H[:, 2]
    return q[..., :2] / q[..., 2:3]


def grid_spacing(grid: np.ndarray) -> tuple[float, float]:
    """Median and minimum distance between neighbouring corners of a (rows, cols, 2) grid, px."""
    d = np.concatenate(
        [
            np.linalg.norm(np.diff(grid, axis=1), axis=-1).ravel(),
            np.linalg.norm(np.diff(grid, axis=0), axis=-1).ravel(),
        ]
    )
    return float(np.median(d)), float(d.min())


def window_for(median_spacing: float, min_spacing: float) -> int:
    w = int(round(WINDOW_FRACTION * median_spacing))
    w = min(w, int(0.45 * min_spacing))
    return int(np.clip(w, 2, 40))


def saddle_score(image: np.ndarray, H: np.ndarray, pts_board: np.ndarray) -> np.ndarray:
    """Saddle contrast at board points (k, 2) in square units, through homography H (board -> px).

    With the four neighbouring square centres a = (+,+), b = (-,-), c = (+,-), d = (-,+):
    |a + b - c - d| / 2 - |a - b| / 2 - |c - d| / 2: about the black/white contrast at a
    chessboard corner, about 0 on a board's outer edge or in a flat area.
    """
    offs = np.array([[0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5]])
    q = pts_board[:, None, :] + offs[None]
    v = sample_bilinear(image, apply_homography(H, q.reshape(-1, 2))).reshape(-1, 4)
    a, b, c, d = v.T
    return np.abs(a + b - c - d) / 2 - np.abs(a - b) / 2 - np.abs(c - d) / 2


def board_continues(image: np.ndarray, grid: np.ndarray, contrast: float) -> str | None:
    """Which side (if any) of the grid has a row of chessboard corners just outside it."""
    rows, cols = grid.shape[:2]
    obj = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2).astype(float)
    return side_with_corners(image, fit_homography(obj, grid.reshape(-1, 2)), cols, rows, contrast)


def side_with_corners(image: np.ndarray, H: np.ndarray, cols: int, rows: int, contrast: float) -> str | None:
    """Which side (if any) of a cols x rows grid of corners, mapped by H (square units -> px),
    has a row of chessboard corners (saddles of at least half ``contrast``) one step outside it."""
    sides = {
        "left": np.c_[np.full(rows, -1.0), np.arange(rows)],
        "right": np.c_[np.full(rows, float(cols)), np.arange(rows)],
        "top": np.c_[np.arange(cols), np.full(cols, -1.0)],
        "bottom": np.c_[np.arange(cols), np.full(cols, float(rows))],
    }
    h, w = image.shape
    for name, pts in sides.items():
        px = apply_homography(H, pts)
        inside = (px[:, 0] > 2) & (px[:, 0] < w - 3) & (px[:, 1] > 2) & (px[:, 1] < h - 3)
        if inside.sum() < max(2, 0.5 * len(pts)):
            continue
        s = saddle_score(image, H, pts[inside])
        if np.mean(s > 0.5 * contrast) > 0.5:
            return name
    return None


def corner_saddles(image: np.ndarray, grid: np.ndarray, reach: float = 0.5) -> np.ndarray:
    """Saddle contrast (as :func:`saddle_score`) at each corner of a (rows, cols, 2) grid.

    The four square centres around a corner come from the grid's own local steps
    (central differences, one-sided on the edges), not from one homography, so the
    test holds under strong lens distortion. ``reach`` (in steps along each axis) places
    the samples: 0.5 at the squares' centres, less to stay inside outer squares that a
    printed board cuts short.
    """
    du = np.gradient(grid, axis=1)
    dv = np.gradient(grid, axis=0)
    centres = [grid + reach * (su * du + sv * dv) for su, sv in ((1, 1), (-1, -1), (1, -1), (-1, 1))]
    a, b, c, d = (sample_bilinear(image, q) for q in centres)
    return np.abs(a + b - c - d) / 2 - np.abs(a - b) / 2 - np.abs(c - d) / 2


def trim_to_saddles(image: np.ndarray, grid: np.ndarray, fraction: float = 0.5) -> np.ndarray | None:
    """The grid without its outer rows and columns whose corners are not chessboard saddles.

    OpenCV's "larger" search may follow a board into its printed margin or the table
    behind it; there the "corners" sit on an edge, not where four squares meet. A
    side is removed while the median saddle contrast of its corners is below
    ``fraction`` times the median of the grid's interior. Returns None when fewer
    than 3x3 corners remain.
    """
    g = np.asarray(grid, dtype=np.float64)
    while min(g.shape[:2]) >= 3:
        s = corner_saddles(image, g)
        ref = float(np.median(s[1:-1, 1:-1]))
        if ref <= 0:
            return None
        sides = {
            "top": np.median(s[0]),
            "bottom": np.median(s[-1]),
            "left": np.median(s[:, 0]),
            "right": np.median(s[:, -1]),
        }
        worst = min(sides, key=sides.get)
        if sides[worst] >= fraction * ref:
            return g
        g = {"top": g[1:], "bottom": g[:-1], "left": g[:, 1:], "right": g[:, :-1]}[worst]
    return None


def grid_edge_fraction(image: np.ndarray, grid: np.ndarray, level: float = 0.4) -> float:
    """Share of a grid's sides (neighbouring corners) that lie on a black/white edge.

    On a chessboard the segment between two neighbouring corners is the edge between two
    squares of opposite colours: the image across its middle, a quarter of a square to
    either side, differs by the board's contrast. A grid whose steps skip squares or run
    diagonally (OpenCV's exhaustive search sometimes threads one through a larger board)
    crosses a corner or a square's middle there instead: about half its sides fail.

    Parameters
    ----------
    image : ndarray, shape (h, w)
    grid : ndarray, shape (rows, cols, 2), px
    level : float
        A side is on an edge when its difference is at least ``level`` times the 90th
        percentile of the grid's differences (the board's contrast).

    Returns
    -------
    float
        In [0, 1]; 1 for a chessboard's own grid (above 0.84 on the real photographs of
        ``../shared/data``, about 0.5 for grids threaded through a larger board).
    """
    g = np.asarray(grid, dtype=np.float64)
    if min(g.shape[:2]) < 2:
        return 0.0
    du = np.gradient(g, axis=1)
    dv = np.gradient(g, axis=0)
    diffs = []
    # Sides along the rows (neighbours in a row) are crossed along the column step, and back.
    for mid, step in (
        (0.5 * (g[:, 1:] + g[:, :-1]), 0.5 * (dv[:, 1:] + dv[:, :-1])),
        (0.5 * (g[1:] + g[:-1]), 0.5 * (du[1:] + du[:-1])),
    ):
        a = sample_bilinear(image, mid + 0.25 * step)
        b = sample_bilinear(image, mid - 0.25 * step)
        diffs.append(np.abs(a - b).ravel())
    d = np.concatenate(diffs)
    ref = float(np.quantile(d, 0.9))
    if ref <= 0:
        return 0.0
    return float(np.mean(d >= level * ref))


def grid_contrast(image: np.ndarray, grid: np.ndarray) -> float:
    rows, cols = grid.shape[:2]
    obj = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2).astype(float)
    H = fit_homography(obj, grid.reshape(-1, 2))
    return float(np.median(saddle_score(image, H, obj)))


def fit_residuals(
    corners: np.ndarray, obj_xy: np.ndarray, camera: CameraModel | None, fit: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Distance of each corner to the board-plane model fitted to the corners in ``fit``, px.

    With the camera known the model is a homography in undistorted normalised
    coordinates (residuals scaled to px by the focal lengths). Without it, the
    lens distortion bends the board's image by up to several px, so the model is
    a homography in px plus a polynomial correction in the board coordinates
    (cubic from 20 corners on, quintic from 80 on); the same when the camera's
    distortion model cannot be inverted at some corners (beyond its calibrated field).

    Returns
    -------
    residuals : ndarray, shape (m,), px
    H : ndarray, shape (3, 3)
        The homography part of the model.
    """
    fit = np.ones(len(corners), dtype=bool) if fit is None else fit
    if camera is not None:
        try:
            pts = camera.rays_from_pixels(corners)
        except UndistortionError:
            # Corners beyond the field where the lens model is invertible: the model without it.
            return fit_residuals(corners, obj_xy, None, fit)
        unit = np.array([camera.fx, camera.fy])
    else:
        pts = corners
        unit = np.ones(2)
    H = fit_homography(obj_xy[fit], pts[fit])
    d = apply_homography(H, obj_xy) - pts
    n_fit = int(fit.sum())
    if camera is None and n_fit >= 20:
        degree = 5 if n_fit >= 80 else 3
        lo, hi = obj_xy.min(axis=0), obj_xy.max(axis=0)
        u, v = ((2 * obj_xy - lo - hi) / np.maximum(hi - lo, 1e-12)).T
        M = np.stack([u**i * v**j for i in range(degree + 1) for j in range(degree + 1 - i)], axis=1)
        coef, *_ = np.linalg.lstsq(M[fit], d[fit], rcond=None)
        d = d - M @ coef
    return np.linalg.norm(d * unit, axis=1), H


def reject_outliers(
    corners: np.ndarray, ids: np.ndarray, obj_xy: np.ndarray, camera: CameraModel | None, reject_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop corners that do not fit the board homography; returns corners, ids, residuals, rejected ids.

    A corner is rejected when its distance to the homography fitted to the kept
    corners exceeds ``max(reject_px, 5 * 1.4826 * median residual)``; repeated
    until the kept set does not change (at most 4 rounds).
    """
    if len(ids) < 4:  # a board too blurred for the corner refinement: no plane to fit
        raise DetectionError(
            f"only {len(ids)} corners of the board could be located to sub-pixel precision "
            "(blur, glare or occlusion)",
            reason="partial",
        )
    keep = np.ones(len(ids), dtype=bool)
    for _ in range(4):
        res, _ = fit_residuals(corners, obj_xy, camera, keep)
        thr = max(reject_px, 5.0 * 1.4826 * float(np.median(res[keep])))
        new_keep = res <= thr
        if new_keep.sum() < 4 or np.array_equal(new_keep, keep):
            keep = new_keep
            break
        keep = new_keep
    if keep.sum() < 4:
        raise DetectionError(
            f"only {int(keep.sum())} of {len(ids)} corners fit the board's plane (blur, glare or occlusion)",
            reason="partial",
        )
    res, _ = fit_residuals(corners[keep], obj_xy[keep], camera)
    return corners[keep], ids[keep], res, ids[~keep]


def detection_mask(det: BoardDetection, margin_sq: float = 1.6) -> np.ndarray:
    """Quadrilateral around a detected board (all of it, also the unseen part), px."""
    cb = grid_of(det.board)
    obj = cb.object_points()[det.ids, :2] / cb.square_mm
    H = fit_homography(obj, det.corners)
    m = margin_sq
    quad = np.array(
        [[-m, -m], [cb.cols - 1 + m, -m], [cb.cols - 1 + m, cb.rows - 1 + m], [-m, cb.rows - 1 + m]]
    )
    return apply_homography(H, quad)


def mask_polygon(grid: np.ndarray, margin_sq: float = 1.6) -> np.ndarray:
    """Quadrilateral around a found grid, grown by ``margin_sq`` squares, px."""
    rows, cols = grid.shape[:2]
    obj = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2).astype(float)
    H = fit_homography(obj, grid.reshape(-1, 2))
    m = margin_sq
    quad = np.array([[-m, -m], [cols - 1 + m, -m], [cols - 1 + m, rows - 1 + m], [-m, rows - 1 + m]])
    return apply_homography(H, quad)
