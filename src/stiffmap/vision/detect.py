"""Board detection: coarse search on a reduced image, sub-pixel refinement at full resolution.

Pipeline of :func:`detect_boards` for chessboards (``docs/vision.md``):

1. **Coarse search** with OpenCV's ``findChessboardCornersSB`` on the image
   reduced by an integer factor (about 1/3 for 2592x1944), falling back to finer
   scales and to the exhaustive search only when that fails. Several boards in one
   image are told apart by their size (inner corners): the board with the most
   corners is searched first and each board found is masked before the next
   search, because the detector returns at most one board per call.
2. **Checks** that the grid is the whole board: a saddle test one step outside
   each side of the grid says when the printed board continues (wrong
   ``--board`` size), and the checkerboard contrast of the inner squares rejects
   spurious grids.
3. **Refinement** with ``cornerSubPix`` at full resolution, window half-size
   about a quarter of the local square size.
4. **Canonical order** (``docs/conventions.md``): the grid is re-indexed so that
   the board frame is right-handed (z into the board) and square (i, j) is black
   when i + j is even. When the colours cannot decide (``cols + rows`` even,
   square boards) the ordering follows continuity with a reference detection,
   else the board's x axis is taken as the one pointing most to the image's right.
5. **Residuals**: a homography is fitted from the board plane to the corners (in
   undistorted coordinates when the camera is known); corners whose residual is
   above ``max(reject_px, 5 x robust sigma)`` are rejected and kept out of
   ``corners``.

Tracking (:func:`track_board`): in a sequence the previous image's corners seed
``cornerSubPix`` directly; the result is accepted only when no corner moved more
than a quarter of a square from its seed and every corner fits the homography,
otherwise the full detection runs.

ChArUco boards (:class:`~stiffmap.targets.CharucoBoard`) are found with OpenCV's
``CharucoDetector`` on the reduced image; the markers identify each corner, so a
partly hidden board still gives the visible corners with their canonical ids.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..targets import CharucoBoard, Chessboard
from .corners import refine_corners

__all__ = [
    "Board",
    "BoardDetection",
    "DetectionError",
    "detect_board",
    "detect_boards",
    "track_board",
    "board_label",
]

Board = Chessboard | CharucoBoard

#: Longest side of the reduced image used for the coarse search, px.
COARSE_TARGET_PX = 900
#: Window half-size of cornerSubPix as a fraction of the local square size.
WINDOW_FRACTION = 0.25
#: Default absolute floor of the corner-rejection threshold, px.
REJECT_PX = 0.5
#: Least black/white contrast (grey levels) of a grid accepted as a board.
MIN_CONTRAST = 10.0


class DetectionError(InputError):
    """A board could not be found or used in an image.

    Attributes
    ----------
    reason : str
        ``"not_found"`` (no board of that size), ``"wrong_size"`` (the printed
        board has more corners than the size given), ``"partial"`` (only part of
        the board is visible or usable), ``"ambiguous"`` (boards that cannot be
        told apart).
    """

    def __init__(self, message: str, *, source: str | None = None, reason: str = "not_found") -> None:
        super().__init__(message, source=source)
        self.reason = reason

    def with_source(self, source: str) -> DetectionError:
        if self.source:
            return self
        return DetectionError(self.detail, source=source, reason=self.reason)


def board_label(board: Board) -> str:
    """``"8x6 chessboard"`` or ``"ChArUco 9x7 squares (8x6 corners)"``."""
    if isinstance(board, CharucoBoard):
        cb = board.chessboard
        return f"ChArUco {board.squares_x}x{board.squares_y} squares ({cb.cols}x{cb.rows} corners)"
    return f"{board.cols}x{board.rows} chessboard"


def _grid_of(board: Board) -> Chessboard:
    return board.chessboard if isinstance(board, CharucoBoard) else board


@dataclass(frozen=True)
class BoardDetection:
    """Corners of one board found in one image.

    Attributes
    ----------
    board : Chessboard or CharucoBoard
    corners : ndarray, shape (m, 2), px
        Refined corner positions in canonical order (increasing ``ids``).
    ids : ndarray of int, shape (m,)
        Canonical corner index ``r * cols + c`` of each corner.
    residual_px : ndarray, shape (m,)
        Distance of each corner to the homography fitted to all kept corners, px
        (in undistorted coordinates when the camera was given).
    tracked : bool
        True when the corners were refined from the previous image's corners
        without a full search.
    window_px : int
        Half-size of the ``cornerSubPix`` window, px.
    scale : int
        Reduction factor of the image where the coarse search found the board
        (1 = full resolution; 0 when tracked).
    orientation : str
        What fixed the corner numbering: ``"colour"``, ``"continuity"``,
        ``"default"`` (symmetric board, no reference: x axis towards the image's
        right), ``"markers"`` (ChArUco) or ``"tracked"``.
    rejected : ndarray of int
        Canonical ids of corners found but rejected by the homography check.
    seconds : float
        Time spent, s.
    """

    board: Board
    corners: np.ndarray
    ids: np.ndarray
    residual_px: np.ndarray
    tracked: bool = False
    window_px: int = 0
    scale: int = 1
    orientation: str = "colour"
    rejected: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    seconds: float = 0.0

    @property
    def n_corners(self) -> int:
        """Number of corners kept."""
        return int(self.ids.size)

    @property
    def complete(self) -> bool:
        """True when every inner corner of the board was kept."""
        return self.n_corners == _grid_of(self.board).n_corners

    @property
    def rms_residual_px(self) -> float:
        """RMS of the homography residuals, px."""
        return float(np.sqrt(np.mean(self.residual_px**2))) if self.residual_px.size else float("nan")

    def object_points(self) -> np.ndarray:
        """Board-frame coordinates of the kept corners, shape (m, 3), mm."""
        return _grid_of(self.board).object_points()[self.ids]


# --------------------------------------------------------------------------- helpers
def _check_image(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ValueError(f"image must be a 2-D uint8 grey array (h, w), got {img.dtype} {img.shape}")
    if img.shape[0] < 8 or img.shape[1] < 8:
        raise ValueError(f"image too small: {img.shape}")
    return np.ascontiguousarray(img)


def _auto_scales(shape: tuple[int, int], scale: int | None) -> list[int]:
    if scale is not None:
        s = int(scale)
        if s < 1:
            raise ValueError(f"scale must be an integer >= 1, got {scale}")
    else:
        s = max(1, int(round(max(shape) / COARSE_TARGET_PX)))
    out = [s]
    while s > 1:
        s = max(1, s // 2) if s > 3 else 1
        out.append(s)
    return out


def _reduce(image: np.ndarray, s: int) -> np.ndarray:
    if s == 1:
        return image.copy()
    h, w = image.shape
    return cv2.resize(image, (w // s, h // s), interpolation=cv2.INTER_AREA)


def _sample(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
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


def _homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares homography (normalised DLT through OpenCV) mapping src (n, 2) to dst (n, 2)."""
    H, _ = cv2.findHomography(src.astype(np.float64), dst.astype(np.float64), 0)
    if H is None:
        raise DetectionError("degenerate corner layout (homography fit failed)", reason="partial")
    return H


def _apply_h(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = pts @ H[:, :2].T + H[:, 2]
    return q[..., :2] / q[..., 2:3]


def _grid_spacing(grid: np.ndarray) -> tuple[float, float]:
    """Median and minimum distance between neighbouring corners of a (rows, cols, 2) grid, px."""
    d = np.concatenate(
        [
            np.linalg.norm(np.diff(grid, axis=1), axis=-1).ravel(),
            np.linalg.norm(np.diff(grid, axis=0), axis=-1).ravel(),
        ]
    )
    return float(np.median(d)), float(d.min())


def _window_for(median_spacing: float, min_spacing: float) -> int:
    w = int(round(WINDOW_FRACTION * median_spacing))
    w = min(w, int(0.45 * min_spacing))
    return int(np.clip(w, 2, 40))


def _saddle_score(image: np.ndarray, H: np.ndarray, pts_board: np.ndarray) -> np.ndarray:
    """Saddle contrast at board points (k, 2) in square units, through homography H (board -> px).

    With the four neighbouring square centres a = (+,+), b = (-,-), c = (+,-), d = (-,+):
    |a + b - c - d| / 2 - |a - b| / 2 - |c - d| / 2: about the black/white contrast at a
    chessboard corner, about 0 on a board's outer edge or in a flat area.
    """
    offs = np.array([[0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5]])
    q = pts_board[:, None, :] + offs[None]
    v = _sample(image, _apply_h(H, q.reshape(-1, 2))).reshape(-1, 4)
    a, b, c, d = v.T
    return np.abs(a + b - c - d) / 2 - np.abs(a - b) / 2 - np.abs(c - d) / 2


# ------------------------------------------------------------------ canonical order
def _candidates(grid: np.ndarray) -> list[np.ndarray]:
    """Re-indexings of a (rows, cols, 2) grid that keep its shape and a right-handed frame."""
    rows, cols = grid.shape[:2]
    cands = [grid, grid[::-1, ::-1], grid[::-1, :], grid[:, ::-1]]
    if rows == cols:
        t = grid.transpose(1, 0, 2)
        cands += [t, t[::-1, ::-1], t[::-1, :], t[:, ::-1]]
    keep = []
    for g in cands:
        vx = (g[:, -1] - g[:, 0]).mean(axis=0)
        vy = (g[-1, :] - g[0, :]).mean(axis=0)
        # Image axes (x right, y down) and the board frame (z into the board, seen from
        # its front): board x cross board y must point away from the camera: positive here.
        if vx[0] * vy[1] - vx[1] * vy[0] > 0:
            keep.append(np.ascontiguousarray(g))
    return keep


def _parity_score(image: np.ndarray, g: np.ndarray) -> float:
    """Mean grey of inner squares with i + j even minus odd (negative for the canonical colours)."""
    centres = (g[:-1, :-1] + g[:-1, 1:] + g[1:, :-1] + g[1:, 1:]) / 4
    # (j, i) indexing: rows are j (board y), columns i (board x); square (i, j) has corners
    # (i, j) .. (i+1, j+1), i.e. grid[j, i] .. grid[j+1, i+1].
    jj, ii = np.meshgrid(np.arange(centres.shape[0]), np.arange(centres.shape[1]), indexing="ij")
    v = _sample(image, centres)
    even = ((ii + jj) % 2) == 0
    return float(v[even].mean() - v[~even].mean()) if (~even).any() else float(v[even].mean())


def _order(
    image: np.ndarray, grid: np.ndarray, board: Chessboard, contrast: float, reference: BoardDetection | None
) -> tuple[np.ndarray, str]:
    """Canonical (rows, cols, 2) grid and what decided it."""
    cands = _candidates(grid)
    if not cands:  # pragma: no cover - every grid has a right-handed re-indexing
        raise DetectionError("cannot orient the corner grid", reason="partial")
    scores = np.array([_parity_score(image, g) for g in cands])
    decisive = np.abs(scores) > 0.3 * max(contrast, 1.0)
    colour_ok = [g for g, s, d in zip(cands, scores, decisive, strict=True) if d and s < 0]
    if colour_ok and len(colour_ok) < len(cands):
        cands = colour_ok
        how = "colour"
    else:
        how = ""
    if len(cands) == 1:
        return cands[0], how
    if reference is not None and reference.n_corners:
        ids = reference.ids
        errs = [np.mean(np.linalg.norm(g.reshape(-1, 2)[ids] - reference.corners, axis=1)) for g in cands]
        return cands[int(np.argmin(errs))], "continuity" if not how else "colour+continuity"
    # No reference: the x axis pointing most to the image's right.
    right = []
    for g in cands:
        vx = (g[:, -1] - g[:, 0]).mean(axis=0)
        right.append(vx[0] / (np.linalg.norm(vx) + 1e-12))
    return cands[int(np.argmax(right))], "default" if not how else "colour+default"


# ------------------------------------------------------------------- chessboards
def _board_continues(image: np.ndarray, grid: np.ndarray, contrast: float) -> str | None:
    """Which side (if any) of the grid has a row of chessboard corners just outside it."""
    rows, cols = grid.shape[:2]
    obj = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2).astype(float)
    H = _homography(obj, grid.reshape(-1, 2))
    sides = {
        "left": np.c_[np.full(rows, -1.0), np.arange(rows)],
        "right": np.c_[np.full(rows, float(cols)), np.arange(rows)],
        "top": np.c_[np.arange(cols), np.full(cols, -1.0)],
        "bottom": np.c_[np.arange(cols), np.full(cols, float(rows))],
    }
    h, w = image.shape
    for name, pts in sides.items():
        px = _apply_h(H, pts)
        inside = (px[:, 0] > 2) & (px[:, 0] < w - 3) & (px[:, 1] > 2) & (px[:, 1] < h - 3)
        if inside.sum() < max(2, 0.5 * len(pts)):
            continue
        s = _saddle_score(image, H, pts[inside])
        if np.mean(s > 0.5 * contrast) > 0.5:
            return name
    return None


def _grid_contrast(image: np.ndarray, grid: np.ndarray) -> float:
    rows, cols = grid.shape[:2]
    obj = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2).astype(float)
    H = _homography(obj, grid.reshape(-1, 2))
    return float(np.median(_saddle_score(image, H, obj)))


def _fit_residuals(
    corners: np.ndarray, obj_xy: np.ndarray, camera: CameraModel | None, fit: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Distance of each corner to the board-plane model fitted to the corners in ``fit``, px.

    With the camera known the model is a homography in undistorted normalised
    coordinates (residuals scaled to px by the focal lengths). Without it, the
    lens distortion bends the board's image by up to several px, so the model is
    a homography in px plus a polynomial correction in the board coordinates
    (cubic from 20 corners on, quintic from 80 on).

    Returns
    -------
    residuals : ndarray, shape (m,), px
    H : ndarray, shape (3, 3)
        The homography part of the model.
    """
    fit = np.ones(len(corners), dtype=bool) if fit is None else fit
    if camera is not None:
        pts = camera.rays_from_pixels(corners)
        unit = np.array([camera.fx, camera.fy])
    else:
        pts = corners
        unit = np.ones(2)
    H = _homography(obj_xy[fit], pts[fit])
    d = _apply_h(H, obj_xy) - pts
    n_fit = int(fit.sum())
    if camera is None and n_fit >= 20:
        degree = 5 if n_fit >= 80 else 3
        lo, hi = obj_xy.min(axis=0), obj_xy.max(axis=0)
        u, v = ((2 * obj_xy - lo - hi) / np.maximum(hi - lo, 1e-12)).T
        M = np.stack([u**i * v**j for i in range(degree + 1) for j in range(degree + 1 - i)], axis=1)
        coef, *_ = np.linalg.lstsq(M[fit], d[fit], rcond=None)
        d = d - M @ coef
    return np.linalg.norm(d * unit, axis=1), H


def _reject(
    corners: np.ndarray, ids: np.ndarray, obj_xy: np.ndarray, camera: CameraModel | None, reject_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop corners that do not fit the board homography; returns corners, ids, residuals, rejected ids.

    A corner is rejected when its distance to the homography fitted to the kept
    corners exceeds ``max(reject_px, 5 * 1.4826 * median residual)``; repeated
    until the kept set does not change (at most 4 rounds).
    """
    keep = np.ones(len(ids), dtype=bool)
    for _ in range(4):
        res, _ = _fit_residuals(corners, obj_xy, camera, keep)
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
    res, _ = _fit_residuals(corners[keep], obj_xy[keep], camera)
    return corners[keep], ids[keep], res, ids[~keep]


def _search_chessboards(
    image: np.ndarray, boards: Sequence[Chessboard], scale: int | None, masks: list[np.ndarray]
) -> dict[int, tuple[np.ndarray, int]]:
    """Coarse grids (rows, cols, 2) in full-resolution px for the boards found, keyed by index.

    ``masks`` (polygons, px) hide boards already known in this image (tracked ones);
    the polygons of the boards found are appended to it.
    """
    order = sorted(range(len(boards)), key=lambda k: -boards[k].n_corners)
    remaining = list(order)
    found: dict[int, tuple[np.ndarray, int]] = {}
    for s in _auto_scales(image.shape, scale):
        small = _reduce(image, s)
        fill = int(np.median(small))
        for poly in masks:
            cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
        for flags in (0, cv2.CALIB_CB_EXHAUSTIVE):
            progress = True
            while progress and remaining:
                progress = False
                for k in list(remaining):
                    b = boards[k]
                    ok, c = cv2.findChessboardCornersSB(small, b.pattern_size, flags=flags)
                    if not ok or c is None or c.size != 2 * b.n_corners:
                        continue
                    g_small = c.reshape(b.rows, b.cols, 2).astype(np.float64)
                    contrast = _grid_contrast(small, g_small)
                    if contrast < MIN_CONTRAST or _board_continues(small, g_small, contrast) is not None:
                        # A part of a larger board, or a spurious grid: not this board.
                        continue
                    grid = g_small * s + (s - 1) / 2
                    found[k] = (grid, s)
                    remaining.remove(k)
                    poly = _mask_polygon(grid)
                    masks.append(poly)
                    cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
                    progress = True
            if not remaining:
                return found
    return found


def _detection_mask(det: BoardDetection, margin_sq: float = 1.6) -> np.ndarray:
    """Quadrilateral around a detected board (all of it, also the unseen part), px."""
    cb = _grid_of(det.board)
    obj = cb.object_points()[det.ids, :2] / cb.square_mm
    H = _homography(obj, det.corners)
    m = margin_sq
    quad = np.array(
        [[-m, -m], [cb.cols - 1 + m, -m], [cb.cols - 1 + m, cb.rows - 1 + m], [-m, cb.rows - 1 + m]]
    )
    return _apply_h(H, quad)


def _mask_polygon(grid: np.ndarray, margin_sq: float = 1.6) -> np.ndarray:
    """Quadrilateral around a found grid, grown by ``margin_sq`` squares, px."""
    rows, cols = grid.shape[:2]
    obj = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2).astype(float)
    H = _homography(obj, grid.reshape(-1, 2))
    m = margin_sq
    quad = np.array([[-m, -m], [cols - 1 + m, -m], [cols - 1 + m, rows - 1 + m], [-m, rows - 1 + m]])
    return _apply_h(H, quad)


def _diagnose(
    image: np.ndarray, board: Chessboard, masks: list[np.ndarray], scale: int | None
) -> DetectionError:
    """Why a chessboard was not found: no grid at all, a larger board, or a partial one.

    Searched at the detection's coarse scale, then at half that reduction (a small
    board far away may only be seen whole there); this runs only when detection
    failed, so the finer pass costs a message, not measurements.
    """
    want = f"{board.cols}x{board.rows}"
    best: list[tuple[int, int]] = []
    s0 = _auto_scales(image.shape, scale)[0]
    for s in dict.fromkeys((s0, max(1, (s0 + 1) // 2))):
        verdict, seen = _diagnose_at(image, board, masks, s)
        if verdict is not None:
            return verdict
        if sum(q * r for q, r in seen) > sum(q * r for q, r in best):
            best = seen
    if best:
        names = " and ".join(f"{q}x{r}" for q, r in best)
        return DetectionError(
            f"no complete {want} chessboard found; only chessboard grids of {names} inner corners are "
            "visible (board partly hidden, out of the frame, or a different board size)",
            reason="partial",
        )
    return DetectionError(f"no {want} chessboard found in the image", reason="not_found")


def _diagnose_at(
    image: np.ndarray, board: Chessboard, masks: list[np.ndarray], s: int
) -> tuple[DetectionError | None, list[tuple[int, int]]]:
    """One scale of :func:`_diagnose`: a wrong-size verdict, or the grids seen there."""
    small = _reduce(image, s)
    fill = int(np.median(small))
    for poly in masks:
        cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
    want = f"{board.cols}x{board.rows}"
    # Is there a grid of the expected size that continues beyond it (a larger board)?
    for ps in (board.pattern_size, (board.rows, board.cols)):
        ok, c = cv2.findChessboardCornersSB(small, ps, flags=cv2.CALIB_CB_EXHAUSTIVE)
        if ok and c is not None:
            g = c.reshape(ps[1], ps[0], 2).astype(np.float64)
            contrast = _grid_contrast(small, g)
            if contrast >= MIN_CONTRAST and _board_continues(small, g, contrast):
                return DetectionError(
                    f"the chessboard in the image has more inner corners than {want} "
                    "(wrong board size? COLSxROWS counts inner corners)",
                    reason="wrong_size",
                ), []
    # What chessboard grids are there at all? (The detector's "larger" mode returns the
    # biggest grid it can follow, possibly only part of a board; found ones are masked.)
    seen: list[tuple[int, int]] = []
    for _ in range(4):
        ok, c, meta = cv2.findChessboardCornersSBWithMeta(small, (3, 3), flags=cv2.CALIB_CB_LARGER)
        if not ok or meta is None or c is None:
            break
        r, q = meta.shape[:2]
        g = c.reshape(r, q, 2).astype(np.float64)
        if (q >= r) != (board.cols >= board.rows):
            q, r = r, q  # name the grid in the orientation of the size asked for
        seen.append((q, r))
        cv2.fillConvexPoly(small, np.round(_mask_polygon(g, 1.2)).astype(np.int32), fill)
    larger = [(q, r) for q, r in seen if (q >= board.cols and r >= board.rows)]
    if larger:
        return DetectionError(
            f"no {want} chessboard found; the image holds a chessboard grid of at least "
            f"{larger[0][0]}x{larger[0][1]} inner corners "
            "(wrong board size? COLSxROWS counts inner corners)",
            reason="wrong_size",
        ), seen
    return None, seen


def _finish_chessboard(
    image: np.ndarray,
    board: Chessboard,
    grid: np.ndarray,
    scale: int,
    camera: CameraModel | None,
    reference: BoardDetection | None,
    reject_px: float,
    t0: float,
) -> BoardDetection:
    med, mn = _grid_spacing(grid)
    win = _window_for(med, mn)
    pts, ok = refine_corners(image, grid.reshape(-1, 2), win)
    # A corner whose refinement failed keeps its coarse position for the ordering only.
    refined = np.where(ok[:, None], pts, grid.reshape(-1, 2)).reshape(grid.shape)
    okg = ok.reshape(grid.shape[:2])
    contrast = _grid_contrast(image, refined)
    canon, how = _order(image, refined, board, contrast, reference)
    # Apply the same re-indexing to the success flags.
    flat = refined.reshape(-1, 2)
    pos = np.array([int(np.argmin(np.abs(flat - p).sum(axis=1))) for p in canon.reshape(-1, 2)])
    ok_canon = okg.reshape(-1)[pos]
    corners = canon.reshape(-1, 2)
    ids = np.arange(board.n_corners)
    obj_xy = board.object_points()[:, :2]
    failed = ids[~ok_canon]
    corners, ids, res, rejected = _reject(
        corners[ok_canon], ids[ok_canon], obj_xy[ok_canon], camera, reject_px
    )
    rejected = np.sort(np.concatenate([rejected, failed]))
    return BoardDetection(
        board=board,
        corners=corners,
        ids=ids,
        residual_px=res,
        tracked=False,
        window_px=win,
        scale=scale,
        orientation=how,
        rejected=rejected,
        seconds=time.perf_counter() - t0,
    )


# ----------------------------------------------------------------------- ChArUco
def _charuco_detector(board: CharucoBoard):
    try:
        dic = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    except AttributeError:
        raise ValueError(f"unknown ArUco dictionary {board.dictionary!r}") from None
    cb = cv2.aruco.CharucoBoard((board.squares_x, board.squares_y), board.square_mm, board.marker_mm, dic)
    return cv2.aruco.CharucoDetector(cb)


def _detect_charuco(
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
    for s in _auto_scales(image.shape, scale):
        small = _reduce(image, s)
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
    H = _homography(obj_xy / cb.square_mm, pts)
    step = np.linalg.norm(_apply_h(H, obj_xy / cb.square_mm + [1.0, 0.0]) - pts, axis=1)
    win = _window_for(float(np.median(step)), float(step.min()))
    pts, ok = refine_corners(image, pts, win)
    failed = ids[~ok]
    corners, ids, res, rejected = _reject(pts[ok], ids[ok], obj_xy[ok], camera, reject_px)
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


# ------------------------------------------------------------------------ public
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
        fit the homography, or the corners leave the image: the caller then runs
        the full detection.
    """
    t0 = time.perf_counter()
    img = _check_image(image)
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
    cb = _grid_of(previous.board)
    obj_xy = cb.object_points()[previous.ids, :2]
    H = _homography(obj_xy / cb.square_mm, seeds)
    step = np.linalg.norm(_apply_h(H, obj_xy / cb.square_mm + [1.0, 0.0]) - seeds, axis=1)
    if np.any(np.linalg.norm(new - seeds, axis=1) > max_shift * step):
        return None
    res, _ = _fit_residuals(new, obj_xy, camera)
    sigma = 1.4826 * np.median(res)
    if np.any(res > max(reject_px, 5.0 * sigma)):
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
        rejected=np.zeros(0, dtype=int),
        seconds=time.perf_counter() - t0,
    )


def detect_boards(
    image,
    boards: Sequence[Board],
    *,
    previous: Sequence[BoardDetection | None] | None = None,
    reference: Sequence[BoardDetection | None] | None = None,
    camera: CameraModel | None = None,
    scale: int | None = None,
    reject_px: float = REJECT_PX,
    min_corners: int = 6,
    source: str | None = None,
) -> list[BoardDetection]:
    """Find several boards in one image, each identified by its size.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
        Grey image (:func:`~stiffmap.vision.images.read_image`).
    boards : sequence of Chessboard or CharucoBoard
        Chessboards must differ in size (inner corners, in either orientation).
    previous : sequence of BoardDetection or None, optional
        The same boards in the previous image of a sequence: their corners are
        refined first (:func:`track_board`) and the full search runs only for the
        boards where that fails.
    reference : sequence of BoardDetection or None, optional
        Detections that fix the numbering of symmetric boards by continuity
        (default: ``previous``).
    camera : CameraModel, optional
        Residuals in undistorted coordinates (tighter outlier test).
    scale : int, optional
        Reduction factor for the coarse search (default: about 900 px on the
        longest side), with finer scales tried when it fails.
    reject_px : float
        Floor of the corner-rejection threshold, px.
    min_corners : int
        Fewest corners accepted for a ChArUco board.
    source : str, optional
        The image's file name, for error messages.

    Returns
    -------
    list of BoardDetection, in the order of ``boards``

    Raises
    ------
    DetectionError
        Naming the first board that could not be found and why.
    """
    img = _check_image(image)
    boards = list(boards)
    n = len(boards)
    prev = list(previous) if previous is not None else [None] * n
    ref = list(reference) if reference is not None else list(prev)
    if len(prev) != n or len(ref) != n:
        raise ValueError(f"previous/reference must have one entry per board ({n})")
    sizes = [tuple(sorted(_grid_of(b).pattern_size)) for b in boards if isinstance(b, Chessboard)]
    if len(set(sizes)) != len(sizes):
        raise DetectionError(
            "two chessboards of the same size cannot be told apart in one image; use boards of "
            "different sizes (e.g. 12x7 on the base, 8x6 on the platform) or ChArUco boards",
            source=source,
            reason="ambiguous",
        )
    out: list[BoardDetection | None] = [None] * n
    for k in range(n):
        if prev[k] is not None:
            out[k] = track_board(img, prev[k], camera=camera, reject_px=reject_px)
    todo_chess = [k for k in range(n) if out[k] is None and isinstance(boards[k], Chessboard)]
    try:
        for k in range(n):
            if out[k] is None and isinstance(boards[k], CharucoBoard):
                out[k] = _detect_charuco(
                    img, boards[k], camera, scale, reject_px, min_corners, time.perf_counter()
                )
        if todo_chess:
            t_search = time.perf_counter()
            # Boards already found in this image (tracked, ChArUco) are hidden from the search.
            masks = [_detection_mask(d) for d in out if d is not None and d.n_corners >= 4]
            found = _search_chessboards(img, [boards[k] for k in todo_chess], scale, masks)
            # The search time is shared by the boards it found.
            t_share = (time.perf_counter() - t_search) / max(len(found), 1)
            for j, k in enumerate(todo_chess):
                if j in found:
                    grid, s = found[j]
                    out[k] = _finish_chessboard(
                        img, boards[k], grid, s, camera, ref[k], reject_px, time.perf_counter() - t_share
                    )
            missing = [k for k in todo_chess if out[k] is None]
            if missing:
                # Boards already found in this image are masked for the diagnosis.
                errs = [_diagnose(img, boards[k], masks, scale) for k in missing]
                if len(errs) == 1:
                    raise errs[0]
                raise DetectionError("; ".join(e.detail for e in errs), reason=errs[0].reason)
    except DetectionError as e:
        if source:
            raise e.with_source(source) from None
        raise
    return [d for d in out if d is not None]


def detect_board(
    image,
    board: Board,
    *,
    previous: BoardDetection | None = None,
    reference: BoardDetection | None = None,
    camera: CameraModel | None = None,
    scale: int | None = None,
    reject_px: float = REJECT_PX,
    min_corners: int = 6,
    source: str | None = None,
) -> BoardDetection:
    """Find one board in an image (see :func:`detect_boards`).

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
    board : Chessboard or CharucoBoard
    previous : BoardDetection, optional
        The board in the previous image: tracked first, full search on failure.
    reference : BoardDetection, optional
        Fixes the numbering of a symmetric board by continuity (default ``previous``).
    camera, scale, reject_px, min_corners, source
        As in :func:`detect_boards`.

    Returns
    -------
    BoardDetection

    Raises
    ------
    DetectionError
        The board is not in the image, partly hidden, or the printed board has a
        different size.
    """
    return detect_boards(
        image,
        [board],
        previous=[previous],
        reference=[reference if reference is not None else previous],
        camera=camera,
        scale=scale,
        reject_px=reject_px,
        min_corners=min_corners,
        source=source,
    )[0]
