"""Board detection: coarse search on a reduced image, sub-pixel refinement at full resolution.

Pipeline of :func:`detect_boards` (``docs/vision.md``), one module per step:

1. **Tracking** (:mod:`~stiffmap.vision.tracking`, :func:`track_board`): in a sequence
   the previous image's corners seed the refinement directly; the result is accepted
   only when no corner moved more than a quarter of a square from its seed and every
   corner fits the homography, otherwise the full detection runs.
2. **ChArUco boards** (:mod:`~stiffmap.vision.charuco`) are found with OpenCV's
   ``CharucoDetector`` on the reduced image; the markers identify each corner, so a
   partly hidden board still gives the visible corners with their canonical ids.
3. **Chessboard search** (:mod:`~stiffmap.vision.chessboard`) with OpenCV's
   ``findChessboardCornersSB`` on the image reduced by an integer factor (about 1/3 for
   2592x1944), falling back to finer scales and to the exhaustive search only when that
   fails. Several boards in one image are told apart by their size (inner corners): the
   board with the most corners is searched first and each board found (and each board
   already tracked) is masked before the next search, because the detector returns at
   most one board per call. A grid is checked to be the whole board: a saddle test one
   step outside each side says when the printed board continues (wrong ``--board``
   size), and the checkerboard contrast of the inner squares rejects spurious grids.
4. **Refinement** (:mod:`~stiffmap.vision.corners`) at full resolution, window
   half-size about a quarter of the local square size.
5. **Canonical order** (:mod:`~stiffmap.vision.ordering`, ``docs/conventions.md``): the
   grid is re-indexed so that the board frame is right-handed (z into the board) and
   square (i, j) is black when i + j is even. When the colours cannot decide
   (``cols + rows`` even, square boards) the ordering follows continuity with a
   reference detection, else the board's x axis is taken as the one pointing most to
   the image's right.
6. **Residuals** (:mod:`~stiffmap.vision.board_plane`): a homography is fitted from the
   board plane to the corners (in undistorted coordinates when the camera is known);
   corners whose residual is above ``max(reject_px, 5 x robust sigma)`` are rejected and
   kept out of ``corners``.

The result is a :class:`~stiffmap.vision.detection.BoardDetection`; a board that cannot
be found raises :class:`~stiffmap.vision.detection.DetectionError` saying why.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from ..camera import CameraModel
from ..targets import CharucoBoard, Chessboard, as_board
from .board_plane import REJECT_PX, detection_mask
from .charuco import detect_charuco
from .chessboard import diagnose, finish_chessboard, search_chessboards
from .detection import Board, BoardDetection, DetectionError, board_label, grid_of
from .images import check_image
from .tracking import track_board

__all__ = [
    "Board",
    "BoardDetection",
    "DetectionError",
    "detect_board",
    "detect_boards",
    "track_board",
    "board_label",
]


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
    hidden=(),
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
    hidden : sequence of array_like, shape (k, 2)
        Polygons (px) of boards found otherwise in this image, hidden from the search.

    Returns
    -------
    list of BoardDetection, in the order of ``boards``

    Raises
    ------
    DetectionError
        Naming the boards that could not be found and why; its ``found`` holds, in the order of
        ``boards``, the detections of those that were (None for the others).
    """
    img = check_image(image)
    boards = list(boards)
    n = len(boards)
    prev, ref = _check_boards(boards, previous, reference, source)
    out: list[BoardDetection | None] = [None] * n
    for k in range(n):
        if prev[k] is not None:
            out[k] = track_board(img, prev[k], camera=camera, reject_px=reject_px)
    todo_chess = [k for k in range(n) if out[k] is None and isinstance(boards[k], Chessboard)]
    try:
        for k in range(n):
            if out[k] is None and isinstance(boards[k], CharucoBoard):
                out[k] = detect_charuco(
                    img, boards[k], camera, scale, reject_px, min_corners, time.perf_counter()
                )
        if todo_chess:
            _search_chessboards(img, boards, todo_chess, out, ref, camera, scale, reject_px, hidden)
    except DetectionError as e:
        err = e.with_source(source) if source else e
        # The boards that were found before the failure (a rig's other cameras may see the rest).
        err.found = list(out)
        raise err from None
    return [d for d in out if d is not None]


def _check_boards(boards: list, previous, reference, source):
    """The previous and reference detections (one per board), and the chessboards' sizes
    checked (two of one size cannot be told apart)."""
    n = len(boards)
    prev = list(previous) if previous is not None else [None] * n
    ref = list(reference) if reference is not None else list(prev)
    if len(prev) != n or len(ref) != n:
        raise ValueError(f"previous/reference must have one entry per board ({n})")
    sizes = [tuple(sorted(grid_of(b).pattern_size)) for b in boards if isinstance(b, Chessboard)]
    if len(set(sizes)) != len(sizes):
        raise DetectionError(
            "two chessboards of the same size cannot be told apart in one image; use boards of "
            "different sizes (e.g. 12x7 on the base, 8x6 on the platform) or ChArUco boards",
            source=source,
            reason="ambiguous",
        )
    return prev, ref


def _search_chessboards(img, boards, todo_chess, out, ref, camera, scale, reject_px, hidden) -> None:
    """The full search for chessboards ``todo_chess`` (their detections set in ``out``); raises
    naming why the missing ones were not found."""
    t_search = time.perf_counter()
    # Boards already found in this image (tracked, ChArUco) are hidden from the search.
    masks = [detection_mask(d) for d in out if d is not None and d.n_corners >= 4] + list(hidden)
    larger: dict = {}
    found = search_chessboards(img, [boards[k] for k in todo_chess], scale, masks, larger)
    # The search time is shared by the boards it found.
    t_share = (time.perf_counter() - t_search) / max(len(found), 1)
    for j, k in enumerate(todo_chess):
        if j in found:
            grid, s = found[j]
            out[k] = finish_chessboard(
                img, boards[k], grid, s, camera, ref[k], reject_px, time.perf_counter() - t_share
            )
    missing = [k for k in todo_chess if out[k] is None]
    if missing:
        # Boards already found in this image are masked for the diagnosis.
        errs = [diagnose(img, boards[k], masks, scale, larger.get(todo_chess.index(k))) for k in missing]
        if len(errs) == 1:
            raise errs[0]
        raise DetectionError("; ".join(e.detail for e in errs), reason=errs[0].reason, larger=errs[0].larger)


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
    square_mm: float | None = None,
) -> BoardDetection:
    """Find one board in an image (see :func:`detect_boards`).

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
    board : Chessboard or CharucoBoard
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (:func:`~stiffmap.targets.as_board`).
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
    board = as_board(board, square_mm, "board")
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
