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
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import CameraModel
from ..targets import Chessboard
from .board_plane import (
    board_continues,
    corner_saddles,
    grid_contrast,
    grid_edge_fraction,
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

__all__ = [
    "MIN_CONTRAST",
    "MIN_EDGE_FRACTION",
    "MIN_SADDLE_SHARE",
    "GrownGrid",
    "LargerBoard",
    "grow_grid",
    "is_board_grid",
    "larger_board",
    "seed_grid",
    "search_chessboards",
    "finish_chessboard",
    "diagnose",
]

#: Least black/white contrast (grey levels) of a grid accepted as a board.
MIN_CONTRAST = 10.0
#: Least share of a grid's sides that must lie on black/white edges
#: (:func:`~stiffmap.vision.board_plane.grid_edge_fraction`): a chessboard's own grid has
#: 0.84-1 on the real photographs of ``../shared/data``; grids OpenCV's exhaustive search
#: threads through a larger board (skipping squares, running diagonally) about 0.5.
MIN_EDGE_FRACTION = 0.7


#: Least share of a grid's corners that must be saddles of at least 0.3 times the grid's median
#: saddle contrast (:func:`~stiffmap.vision.board_plane.corner_saddles`): 90 % or more of the
#: corners of every board of the real sets are; a grid shifted onto a board's outer edge (its
#: corners there where a black square meets the margin, no saddle) has a row or column of
#: non-saddles (OpenCV's exhaustive 7x5 search on a 9x6 board of ``greninja``: 11 of 35).
MIN_SADDLE_SHARE = 0.9


def is_board_grid(image: np.ndarray, grid: np.ndarray) -> tuple[bool, float]:
    """Whether a grid is a chessboard's (contrast, its sides on edges, its corners saddles), and
    its contrast."""
    contrast = grid_contrast(image, grid)
    if contrast < MIN_CONTRAST or grid_edge_fraction(image, grid) < MIN_EDGE_FRACTION:
        return False, contrast
    # Sampled a quarter of a step from each corner: inside outer squares that a printed board
    # cuts short (OpenCV's stereo samples: their centres fall on the margin, left05 failed).
    sad = corner_saddles(image, grid, GROW_REACH)
    return bool(np.mean(sad >= 0.3 * np.median(sad)) >= MIN_SADDLE_SHARE), contrast


@dataclass(frozen=True)
class GrownGrid:
    """A grid of chessboard corners grown outward as far as the printed board goes.

    Attributes
    ----------
    grid : ndarray, shape (rows, cols, 2), px
    cut : bool
        True when the board runs on past the image's edge on some side (its size is then
        a lower bound).
    """

    grid: np.ndarray
    cut: bool


@dataclass(frozen=True)
class LargerBoard:
    """A printed chessboard larger than the board asked for, seen in an image.

    Attributes
    ----------
    cols, rows : int
        Its inner corners, named in the orientation of the board asked for (the longer
        side first when the asked board's is).
    whole : bool
        False when it runs on past the image's edge (the size is then a lower bound).
    """

    cols: int
    rows: int
    whole: bool

    @classmethod
    def of(cls, grown: GrownGrid, board: Chessboard) -> LargerBoard:
        r, q = grown.grid.shape[:2]
        if (q >= r) != (board.cols >= board.rows):
            q, r = r, q
        return cls(int(q), int(r), not grown.cut)

    @property
    def size(self) -> str:
        return f"{self.cols}x{self.rows}"

    def describe(self, board: Chessboard) -> str:
        """The wrong-size verdict: what the image shows instead of ``board``."""
        if self.whole:
            return (
                f"the image shows a {self.size} chessboard (inner corners), not {board.cols}x{board.rows}: "
                f"did you mean --board {self.size}?"
            )
        return (
            f"the image shows a chessboard of at least {self.size} inner corners (it runs out of the "
            f"image), not {board.cols}x{board.rows} (wrong board size? COLSxROWS counts inner corners)"
        )


#: A row of predicted corners outside a grid is the board's when this share of them are saddles.
GROW_SHARE = 0.7
#: Largest board side a grid is grown to, corners.
GROW_MAX = 80
#: Where the saddle test of a grown row samples the squares around a corner, in steps.
GROW_REACH = 0.25


def grow_grid(image: np.ndarray, grid: np.ndarray) -> GrownGrid:
    """Grow a grid of chessboard corners outward while the printed board goes on.

    Each side in turn: the next row of corners is extrapolated from the last three (or two),
    refined (``cornerSubPix``), and taken when at least :data:`GROW_SHARE` of its corners
    are saddles (:func:`~stiffmap.vision.board_plane.corner_saddles`) of at least half their
    neighbour's in the last row and a quarter of the grid's median, that stayed within a
    quarter of a square of the prediction. A row that leaves the image
    ends that side (``cut`` when its corners inside the image are still the board's).
    Local extrapolation follows the lens distortion, which a homography would not.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
    grid : ndarray, shape (rows, cols, 2), px
        Corners of part of a board (at least 2 x 2).

    Returns
    -------
    GrownGrid
    """
    g = np.asarray(grid, dtype=np.float64)
    h, w = image.shape
    # Samples a quarter of a step from each corner: inside outer squares cut short (OpenCV's
    # stereo samples), where the squares' centres would fall on the margin.
    ref = float(np.median(corner_saddles(image, g, GROW_REACH)))
    cut = False
    open_sides = ["top", "bottom", "left", "right"]
    while open_sides and max(g.shape[:2]) < GROW_MAX:
        side = open_sides.pop(0)
        t = {
            "top": lambda a: a[::-1],
            "bottom": lambda a: a,
            "left": lambda a: a[:, ::-1].transpose(1, 0, 2),
            "right": lambda a: a.transpose(1, 0, 2),
        }[side]
        a = t(g)  # the side to grow is the last row of a
        if a.shape[0] >= 3:
            pred = 3 * a[-1] - 3 * a[-2] + a[-3]
        else:
            pred = 2 * a[-1] - a[-2]
        step = float(np.median(np.linalg.norm(np.diff(a[-1], axis=0), axis=-1)))
        margin = 0.6 * step + 2
        inside = (pred[:, 0] > margin) & (pred[:, 0] < w - 1 - margin)
        inside &= (pred[:, 1] > margin) & (pred[:, 1] < h - 1 - margin)
        if not inside.any():
            continue
        win = int(np.clip(round(0.25 * step), 2, 20))
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 20, 0.01)
        ref_pts = np.ascontiguousarray(pred[inside], dtype=np.float32).reshape(-1, 1, 2)
        refined = cv2.cornerSubPix(image, ref_pts.copy(), (win, win), (-1, -1), crit).reshape(-1, 2)
        moved = np.linalg.norm(refined - pred[inside], axis=1) < 0.25 * step
        row = pred.copy()
        row[inside] = refined
        trial = np.concatenate([a, row[None]], axis=0)
        sads = corner_saddles(image, trial, GROW_REACH)
        sad, last = sads[-1][inside], sads[-2][inside]
        # Against the neighbouring corner of the last row (lighting varies over a board: a
        # tablet's screen seen obliquely halves its contrast from one side to the other), and
        # against a quarter of the grid's median (not a flat margin's speck).
        good = moved & (sad >= 0.5 * last) & (sad >= 0.25 * ref)
        if good.mean() < GROW_SHARE:
            continue
        if not inside.all():
            cut = True  # the board goes on past the image's edge
            continue
        back = {
            "top": lambda a: a[::-1],
            "bottom": lambda a: a,
            "left": lambda a: a.transpose(1, 0, 2)[:, ::-1],
            "right": lambda a: a.transpose(1, 0, 2),
        }[side]
        g = back(trial)
        open_sides.append(side)
    return GrownGrid(g, cut)


def seed_grid(image: np.ndarray, points: np.ndarray) -> np.ndarray | None:
    """A 3 x 3 grid of chessboard corners around the middle of a set of corners, or None.

    OpenCV's detectors asked for a pattern smaller than the printed board return real
    corners of it, but not always in grid order; this takes the corner nearest their
    centroid and two of its nearest neighbours as the grid's steps (tried in order of length:
    on a sheared view a diagonal neighbour can be nearer than the other axis', and its lattice
    is not a board's), and refines the 3 x 3 lattice they span (a seed for :func:`grow_grid`).
    None when no pair gives chessboard saddles on the board's edges.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 3:
        return None
    p0 = pts[np.argmin(np.linalg.norm(pts - pts.mean(axis=0), axis=1))]
    d = pts - p0
    n = np.linalg.norm(d, axis=1)
    near = [d[k] for k in np.argsort(n) if n[k] > 1e-9][:6]
    pairs = [
        (a, b)
        for i, a in enumerate(near)
        for b in near[i + 1 :]
        if abs(a @ b) < 0.7 * np.linalg.norm(a) * np.linalg.norm(b)
    ]
    pairs.sort(key=lambda ab: np.linalg.norm(ab[0]) + np.linalg.norm(ab[1]))
    for u, v in pairs[:6]:
        seed = _lattice_seed(image, p0, u, v)
        if seed is not None:
            return seed
    return None


def _lattice_seed(image: np.ndarray, p0: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """The 3 x 3 lattice p0 + i u + j v, refined; None unless it is a chessboard's grid."""
    i, j = np.meshgrid(np.arange(-1, 2), np.arange(-1, 2))
    g = p0 + j[..., None] * v + i[..., None] * u
    step = min(np.linalg.norm(u), np.linalg.norm(v))
    h, w = image.shape
    lo, hi_x, hi_y = step / 2 + 2, w - step / 2 - 3, h - step / 2 - 3
    if not (np.all(g >= lo) and np.all(g[..., 0] < hi_x) and np.all(g[..., 1] < hi_y)):
        return None
    win = int(np.clip(round(0.25 * step), 2, 20))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 20, 0.01)
    ref = cv2.cornerSubPix(image, g.reshape(-1, 1, 2).astype(np.float32), (win, win), (-1, -1), crit)
    ref = ref.reshape(3, 3, 2).astype(np.float64)
    if np.max(np.linalg.norm(ref - g, axis=-1)) > 0.25 * step:
        return None
    sad = corner_saddles(image, ref)
    if not (sad.min() >= 0.5 * np.median(sad) > 0 and is_board_grid(image, ref)[0]):
        return None
    return ref


def larger_board(image: np.ndarray, points: np.ndarray, board: Chessboard) -> LargerBoard | None:
    """The printed board around corners ``points`` (seeded, then grown), when larger than ``board``."""
    seed = seed_grid(image, points)
    if seed is None:
        return None
    big = LargerBoard.of(grow_grid(image, seed), board)
    if big.cols < board.cols or big.rows < board.rows or big.cols * big.rows <= board.n_corners:
        return None
    return big


def search_chessboards(
    image: np.ndarray,
    boards: Sequence[Chessboard],
    scale: int | None,
    masks: list[np.ndarray],
    larger: dict[int, LargerBoard] | None = None,
) -> dict[int, tuple[np.ndarray, int]]:
    """Coarse grids (rows, cols, 2) in full-resolution px for the boards found, keyed by index.

    ``masks`` (polygons, px) hide boards already known in this image (tracked ones);
    the polygons of the boards found are appended to it. A grid of a board's size that is
    part of a larger printed board is grown to that board (:func:`grow_grid`), which is
    hidden from the rest of the search and recorded in ``larger`` (keyed as the result).
    """
    order = sorted(range(len(boards)), key=lambda k: -boards[k].n_corners)
    remaining = list(order)
    found: dict[int, tuple[np.ndarray, int]] = {}
    larger = {} if larger is None else larger
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
                    if k in larger and detector != "sb":
                        continue  # the image shows a larger board: only the cheap search goes on
                    b = boards[k]
                    g_small = _find_grid(small, b, detector)
                    if g_small is None:
                        continue
                    ok, contrast = is_board_grid(small, g_small)
                    if not ok:
                        continue  # a spurious grid: not a board
                    if board_continues(small, g_small, contrast) is not None:
                        # Part of a larger board: recorded (grown to it) and hidden from the search.
                        big = larger.get(k) or larger_board(small, g_small, b)
                        if big is not None:
                            larger[k] = big
                        cv2.fillConvexPoly(small, np.round(mask_polygon(g_small, 1.0)).astype(np.int32), fill)
                        masks.append(mask_polygon(g_small * s + (s - 1) / 2, 1.0))
                        progress = True
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
        if all(k in larger for k in remaining):
            break  # no finer scale for boards the image shows larger
    return found


def find_chessboard_sb(small: np.ndarray, pattern: tuple[int, int], flags: int = 0, *, meta: bool = False):
    """``cv2.findChessboardCornersSB`` (``...WithMeta`` if ``meta``), the same answer every call.

    The SB detector draws from OpenCV's global random generator (``cv::theRNG``), so one image
    could give another grid depending on what was detected before it in the process (measured:
    Bouguet's Image15.tif searched for a 9x6 board alternated between "a 13x12 board" and "only
    part of a board" on repeated calls, and a scan of a folder depended on the folder scanned
    before it). The generator is reset before every call: each call sees the state of a fresh
    process (``setRNGSeed(0)`` gives OpenCV's initial state, 0xffffffff).
    """
    cv2.setRNGSeed(0)
    if meta:
        return cv2.findChessboardCornersSBWithMeta(small, pattern, flags=flags)
    return cv2.findChessboardCornersSB(small, pattern, flags=flags)


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
        ok, c = find_chessboard_sb(small, ps, flags)
    if not ok or c is None or c.size != 2 * board.n_corners:
        return None
    g = c.reshape(board.rows, board.cols, 2).astype(np.float64)
    return g if np.all(np.isfinite(g)) else None


def diagnose(
    image: np.ndarray,
    board: Chessboard,
    masks: list[np.ndarray],
    scale: int | None,
    larger: LargerBoard | None = None,
) -> DetectionError:
    """Why a chessboard was not found: no grid at all, a larger board, or a partial one.

    ``larger`` is the larger board the search already followed (:func:`search_chessboards`):
    the answer then costs nothing more. Otherwise searched at the detection's coarse scale,
    then at half that reduction (a small board far away may only be seen whole there); this
    runs only when detection failed, so the finer pass costs a message, not measurements.
    """
    if larger is not None:
        return DetectionError(larger.describe(board), reason="wrong_size", larger=larger)
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


def _wrong_size(small: np.ndarray, grid: np.ndarray, board: Chessboard) -> DetectionError | None:
    """The wrong-size verdict when ``grid``'s corners grow into a board larger than ``board``."""
    big = larger_board(small, grid, board)
    return None if big is None else DetectionError(big.describe(board), reason="wrong_size", larger=big)


def _diagnose_at(
    image: np.ndarray, board: Chessboard, masks: list[np.ndarray], s: int
) -> tuple[DetectionError | None, list[tuple[int, int]]]:
    """One scale of :func:`diagnose`: a wrong-size verdict, or the grids seen there."""
    small = reduce_image(image, s)
    fill = int(np.median(small))
    for poly in masks:
        cv2.fillConvexPoly(small, np.round((poly - (s - 1) / 2) / s).astype(np.int32), fill)
    want = f"{board.cols}x{board.rows}"
    # A larger board the detectors see part of (their grids seed it, then it is grown): cheap.
    for flags in (cv2.CALIB_CB_LARGER, 0):
        ok, c = find_chessboard_sb(small, (4, 4), flags)
        if ok and c is not None:
            big = larger_board(small, c, board)
            if big is not None:
                return DetectionError(big.describe(board), reason="wrong_size", larger=big), []
    # Is there a grid of the expected size that continues beyond it (a larger board)?
    for ps in (board.pattern_size, (board.rows, board.cols)):
        ok, c = find_chessboard_sb(small, ps, cv2.CALIB_CB_EXHAUSTIVE)
        if ok and c is not None:
            g = c.reshape(ps[1], ps[0], 2).astype(np.float64)
            is_grid, contrast = is_board_grid(small, g)
            if is_grid and board_continues(small, g, contrast):
                verdict = _wrong_size(small, g, board)
                return verdict or DetectionError(
                    f"the chessboard in the image has more inner corners than {want} "
                    "(wrong board size? COLSxROWS counts inner corners)",
                    reason="wrong_size",
                ), []
    # What chessboard grids are there at all? (The detector's "larger" mode returns the
    # biggest grid it can follow, possibly only part of a board; found ones are masked.)
    seen: list[tuple[int, int]] = []
    for _ in range(4):
        ok, c, meta = find_chessboard_sb(small, (3, 3), cv2.CALIB_CB_LARGER, meta=True)
        if not ok or meta is None or c is None:
            break
        r, q = meta.shape[:2]
        g = c.reshape(r, q, 2).astype(np.float64)
        trimmed = trim_to_saddles(small, g)
        if trimmed is not None and is_board_grid(small, trimmed)[0]:
            verdict = _wrong_size(small, trimmed, board)
            if verdict is not None:
                return verdict, []
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
