"""Chessboard search: coarse grids on a reduced image, checked, refined and ordered.

1. **Coarse search** with OpenCV's detectors on the image reduced by an integer factor
   (:func:`~stiffmap.vision.images.coarse_scales`): ``findChessboardCornersSB`` first,
   then the classic ``findChessboardCorners`` (adaptive threshold, quads; it finds boards
   seen at steep angles that SB misses; on images up to 1700 px), then SB's exhaustive
   search, and the same at finer scales down to full resolution only when the coarser
   ones fail. Several boards
   in one image are told apart by their size (inner corners): the board with the most
   corners is searched first and each board found is masked before the next search,
   because the detectors return at most one board per call.
2. **Checks** that the grid is the whole board: a saddle test one step outside each side
   of the grid says when the printed board continues (wrong ``--board`` size), and the
   checkerboard contrast of the inner squares rejects spurious grids.
3. **Refinement** (:func:`~stiffmap.vision.corners.refine_corners`) at full resolution,
   window half-size about a quarter of the local square size, then the canonical order
   (:mod:`stiffmap.vision.ordering`) and the rejection of corners off the board's plane.

When a board is not found, :func:`diagnose` says why: no grid at all, a larger board
(wrong size), or only part of one. A grid that OpenCV's "larger" mode follows beyond the
board (its printed margin, the table edge behind it) is trimmed of the outer rows whose
corners are not chessboard saddles before its size is named.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import cv2
import numpy as np

from ..camera import CameraModel
from ..targets import Chessboard
from .board_plane import (
    board_continues,
    grid_contrast,
    grid_spacing,
    mask_polygon,
    reject_outliers,
    trim_to_saddles,
    window_for,
)
from .corners import refine_corners
from .detection import BoardDetection, DetectionError
from .images import coarse_scales, reduce_image
from .ordering import canonical_order

__all__ = ["MIN_CONTRAST", "search_chessboards", "finish_chessboard", "diagnose"]

#: Least black/white contrast (grey levels) of a grid accepted as a board.
MIN_CONTRAST = 10.0


def search_chessboards(
    image: np.ndarray, boards: Sequence[Chessboard], scale: int | None, masks: list[np.ndarray]
) -> dict[int, tuple[np.ndarray, int]]:
    """Coarse grids (rows, cols, 2) in full-resolution px for the boards found, keyed by index.

    ``masks`` (polygons, px) hide boards already known in this image (tracked ones);
    the polygons of the boards found are appended to it.
    """
    order = sorted(range(len(boards)), key=lambda k: -boards[k].n_corners)
    remaining = list(order)
    found: dict[int, tuple[np.ndarray, int]] = {}
    for s in coarse_scales(image.shape, scale):
        small = reduce_image(image, s)
        fill = int(np.median(small))
        for poly in masks:
            cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
        for detector in DETECTORS:
            progress = True
            while progress and remaining:
                progress = False
                for k in list(remaining):
                    b = boards[k]
                    g_small = _find_grid(small, b, detector)
                    if g_small is None:
                        continue
                    contrast = grid_contrast(small, g_small)
                    if contrast < MIN_CONTRAST or board_continues(small, g_small, contrast) is not None:
                        # A part of a larger board, or a spurious grid: not this board.
                        continue
                    grid = g_small * s + (s - 1) / 2
                    found[k] = (grid, s)
                    remaining.remove(k)
                    poly = mask_polygon(grid)
                    masks.append(poly)
                    cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
                    progress = True
            if not remaining:
                return found
    return found


#: OpenCV's detectors in the order they are tried at each scale (cheapest, most often right first).
DETECTORS = ("sb", "classic", "sb-exhaustive")
#: The classic detector runs only on images up to this size (longest side, px): its quad
#: search grows steeply with the image, and a partial board in a 2592x1944 frame can keep it
#: busy for minutes (about 2 s at 860 px).
CLASSIC_MAX_PX = 1700


def _find_grid(small: np.ndarray, board: Chessboard, detector: str) -> np.ndarray | None:
    """The (rows, cols, 2) grid one OpenCV detector finds for ``board`` in ``small``, or None."""
    ps = board.pattern_size
    if detector == "classic":
        if max(small.shape) > CLASSIC_MAX_PX:
            return None
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE  # FAST_CHECK misses steep views
        ok, c = cv2.findChessboardCorners(small, ps, flags=flags)
    else:
        flags = cv2.CALIB_CB_EXHAUSTIVE if detector == "sb-exhaustive" else 0
        ok, c = cv2.findChessboardCornersSB(small, ps, flags=flags)
    if not ok or c is None or c.size != 2 * board.n_corners:
        return None
    g = c.reshape(board.rows, board.cols, 2).astype(np.float64)
    return g if np.all(np.isfinite(g)) else None


def diagnose(
    image: np.ndarray, board: Chessboard, masks: list[np.ndarray], scale: int | None
) -> DetectionError:
    """Why a chessboard was not found: no grid at all, a larger board, or a partial one.

    Searched at the detection's coarse scale, then at half that reduction (a small
    board far away may only be seen whole there); this runs only when detection
    failed, so the finer pass costs a message, not measurements.
    """
    want = f"{board.cols}x{board.rows}"
    best: list[tuple[int, int]] = []
    s0 = coarse_scales(image.shape, scale)[0]
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
    """One scale of :func:`diagnose`: a wrong-size verdict, or the grids seen there."""
    small = reduce_image(image, s)
    fill = int(np.median(small))
    for poly in masks:
        cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
    want = f"{board.cols}x{board.rows}"
    # Is there a grid of the expected size that continues beyond it (a larger board)?
    for ps in (board.pattern_size, (board.rows, board.cols)):
        ok, c = cv2.findChessboardCornersSB(small, ps, flags=cv2.CALIB_CB_EXHAUSTIVE)
        if ok and c is not None:
            g = c.reshape(ps[1], ps[0], 2).astype(np.float64)
            contrast = grid_contrast(small, g)
            if contrast >= MIN_CONTRAST and board_continues(small, g, contrast):
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
        trimmed = trim_to_saddles(small, g)
        cv2.fillConvexPoly(small, np.round(mask_polygon(g, 1.2)).astype(np.int32), fill)
        if trimmed is None:
            continue
        g = trimmed
        r, q = g.shape[:2]
        if (q >= r) != (board.cols >= board.rows):
            q, r = r, q  # name the grid in the orientation of the size asked for
        seen.append((q, r))
    larger = [(q, r) for q, r in seen if (q >= board.cols and r >= board.rows)]
    if larger:
        return DetectionError(
            f"no {want} chessboard found; the image holds a chessboard grid of at least "
            f"{larger[0][0]}x{larger[0][1]} inner corners "
            "(wrong board size? COLSxROWS counts inner corners)",
            reason="wrong_size",
        ), seen
    return None, seen


def finish_chessboard(
    image: np.ndarray,
    board: Chessboard,
    grid: np.ndarray,
    scale: int,
    camera: CameraModel | None,
    reference: BoardDetection | None,
    reject_px: float,
    t0: float,
) -> BoardDetection:
    med, mn = grid_spacing(grid)
    win = window_for(med, mn)
    pts, ok = refine_corners(image, grid.reshape(-1, 2), win)
    # A corner whose refinement failed keeps its coarse position for the ordering only.
    refined = np.where(ok[:, None], pts, grid.reshape(-1, 2)).reshape(grid.shape)
    okg = ok.reshape(grid.shape[:2])
    contrast = grid_contrast(image, refined)
    canon, how, phase = canonical_order(image, refined, board, contrast, reference)
    # Apply the same re-indexing to the success flags.
    flat = refined.reshape(-1, 2)
    pos = np.array([int(np.argmin(np.abs(flat - p).sum(axis=1))) for p in canon.reshape(-1, 2)])
    ok_canon = okg.reshape(-1)[pos]
    corners = canon.reshape(-1, 2)
    ids = np.arange(board.n_corners)
    obj_xy = board.object_points()[:, :2]
    failed = ids[~ok_canon]
    corners, ids, res, rejected = reject_outliers(
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
        phase=phase,
        rejected=rejected,
        seconds=time.perf_counter() - t0,
    )
