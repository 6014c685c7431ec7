"""Is the board asked for the one the images show? A quick check before the full search.

A wrong ``--board`` is the commonest first mistake with real photographs: the squares counted
instead of the inner corners (14x13 for a 13x12 board), a size copied from another set (9x6 on
a 13x12 board), a row missed. The full search tries every detector at every scale on every
image before it gives up (minutes on a set of twenty), and a board asked smaller than the
printed one is found as a sub-grid of it. :func:`check_board_size` answers first, in seconds,
on a few images of the set:

1. Each sampled image is reduced to about :data:`~stiffmap.vision.images.COARSE_TARGET_PX`
   on its longest side (the coarse search's scale) and searched once with OpenCV's
   ``findChessboardCornersSB`` for the board asked for. A grid found that is a board's
   (:func:`~stiffmap.vision.chessboard.is_board_grid`) and that no row of saddles continues
   (:func:`~stiffmap.vision.board_plane.board_continues`) is the board: the check ends there
   (one search on one image when the size is right).
2. Otherwise the printed board is *grown*: from the grid found (a sub-grid of a larger board),
   or from the grid the same detector's "larger" mode follows from a 4x4 pattern anywhere on
   the board (without its rows that are not saddles), rows of corners are
   extrapolated outward while they are chessboard saddles
   (:func:`~stiffmap.vision.chessboard.grow_grid`) -- to the board's edge, or to the image's.
3. A size grown whole is confirmed by the detector asked for that size (a whole board of
   it, not continuing): growing proposes, detection confirms.

When :data:`AGREE` images confirm one size other than the one asked for and none showed the
board asked for, :class:`BoardSizeError` names it. Anything less (a board cut by the image's
edge, nothing found) leaves the decision to the full search, which has the last word: the
check never refuses a set on which the board asked for was seen.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..targets import CharucoBoard, Chessboard
from .board_plane import board_continues, corner_saddles, mask_polygon, trim_to_saddles
from .chessboard import GROW_REACH, find_chessboard_sb, grow_grid, is_board_grid, seed_grid
from .images import coarse_scales, read_image, reduce_image

__all__ = ["AGREE", "SAMPLE", "BoardSeen", "BoardSizeError", "board_seen", "check_board_size"]

#: Images that must confirm one other board size, none showing the board asked for, before it
#: is named.
AGREE = 2
#: Images looked at, at most (spread over the set).
SAMPLE = 6
#: Grids of other sizes masked in one image before it is given up (a second board in view).
MAX_GRIDS = 3


class BoardSizeError(InputError):
    """The images show a board of another size than the one asked for.

    Attributes
    ----------
    asked : tuple of int
        (cols, rows) inner corners asked for.
    shown : tuple of int
        (cols, rows) inner corners the images show, in the orientation asked for.
    """

    def __init__(self, message: str, asked: tuple[int, int], shown: tuple[int, int]) -> None:
        super().__init__(message)
        self.asked = asked
        self.shown = shown


@dataclass(frozen=True)
class BoardSeen:
    """What one image shows of the board asked for.

    Attributes
    ----------
    verdict : str
        ``"match"`` (the board asked for, whole), ``"other"`` (a board of another size,
        confirmed whole), ``"cut"`` (a board running out of the image, at least ``size``),
        ``"none"`` (no chessboard found at this scale).
    size : tuple of int or None
        (cols, rows) inner corners of the board seen, in the orientation asked for.
    """

    verdict: str
    size: tuple[int, int] | None = None


def _sb(small: np.ndarray, pattern: tuple[int, int], flags: int = 0) -> np.ndarray | None:
    """The (rows, cols, 2) grid ``findChessboardCornersSB`` finds for ``pattern``, or None."""
    ok, c = find_chessboard_sb(small, pattern, flags)
    if not ok or c is None or c.size < 2 * pattern[0] * pattern[1]:
        return None
    g = c.reshape(-1, 2).astype(np.float64)
    if len(g) != pattern[0] * pattern[1] or not np.all(np.isfinite(g)):
        return None  # the "larger" mode returns more corners than asked: not a grid of pattern
    return g.reshape(pattern[1], pattern[0], 2)


def _named(grid: np.ndarray, board: Chessboard) -> tuple[int, int]:
    """A grid's size (cols, rows), in the orientation of ``board`` (the longer side first when its is)."""
    r, q = grid.shape[:2]
    if (q >= r) != (board.cols >= board.rows):
        q, r = r, q
    return int(q), int(r)


def _same(a: tuple[int, int], b: tuple[int, int]) -> bool:
    return sorted(a) == sorted(b)


#: Least median saddle contrast of a grid's outer row or column, as a share of its interior's.
SIDE_SADDLE_SHARE = 0.5


def _board_grid(small: np.ndarray, g: np.ndarray) -> tuple[bool, float]:
    """:func:`~stiffmap.vision.chessboard.is_board_grid`, and each outer row and column of
    saddles: the detector may run a row along the board's edge, where black squares meet the
    margin (a 10x6 grid on a 9x6 board of ``christos``: one row in ten, 90 % saddles still)."""
    ok, contrast = is_board_grid(small, g)
    if not ok or min(g.shape[:2]) < 3:
        return ok, contrast
    s = corner_saddles(small, g, GROW_REACH)
    ref = float(np.median(s[1:-1, 1:-1]))
    sides = (s[0], s[-1], s[:, 0], s[:, -1])
    return all(np.median(x) >= SIDE_SADDLE_SHARE * ref for x in sides), contrast


def _whole_of(small: np.ndarray, size: tuple[int, int]) -> bool:
    """Whether the detector finds a whole board of ``size`` (not part of a larger one)."""
    g = _sb(small, size)
    if g is None:
        return False
    ok, contrast = _board_grid(small, g)
    return ok and board_continues(small, g, contrast) is None


def _grown(small: np.ndarray, seed: np.ndarray, board: Chessboard) -> tuple[BoardSeen, np.ndarray]:
    """The board grown from ``seed`` corners: its verdict, and its grid (to mask)."""
    grown = grow_grid(small, seed)
    size = _named(grown.grid, board)
    if _same(size, (board.cols, board.rows)):
        return BoardSeen("match", size), grown.grid
    if grown.cut or not _whole_of(small, size):
        return BoardSeen("cut", size), grown.grid
    return BoardSeen("other", size), grown.grid


def _look_once(small: np.ndarray, board: Chessboard) -> tuple[BoardSeen, np.ndarray | None]:
    """One search of a reduced image: the verdict and the grid it rests on (None: nothing)."""
    g = _sb(small, board.pattern_size)
    if g is not None:
        ok, contrast = _board_grid(small, g)
        if ok and board_continues(small, g, contrast) is None:
            return BoardSeen("match", (board.cols, board.rows)), g
        if ok:  # a sub-grid of a larger printed board
            seen, grown = _grown(small, g, board)
            # Not grown past the size asked for, though a row of saddles goes on: a grid that
            # skips squares (running diagonally), not the board's.
            return (BoardSeen("none"), grown) if seen.verdict == "match" else (seen, grown)
    seed = _seed(small)
    if seed is not None:
        return _grown(small, seed, board)
    return BoardSeen("none"), None


def _seed(small: np.ndarray) -> np.ndarray | None:
    """Part of a printed board to grow: the grid the detector's "larger" mode follows from a
    4x4 pattern (without its rows off the board), else a 3x3 seed among its corners."""
    ok, c, meta = find_chessboard_sb(small, (4, 4), cv2.CALIB_CB_LARGER, meta=True)
    if not ok or c is None or meta is None:
        return None
    r, q = meta.shape[:2]
    if c.size == 2 * r * q:
        g = trim_to_saddles(small, c.reshape(r, q, 2).astype(np.float64))
        if g is not None and _board_grid(small, g)[0]:
            return g
    return seed_grid(small, c)


def board_seen(image: np.ndarray, board: Chessboard, others: Sequence[Chessboard] = ()) -> BoardSeen:
    """What an image shows of ``board``, searched once on the image reduced to the coarse scale.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8
    board : Chessboard
        The board asked for.
    others : sequence of Chessboard
        Other boards that may be in view (a fixed target): a board of one of their sizes is
        never named. Every board of another size than ``board`` is masked and the search goes
        on (a second board in view, declared or not), up to :data:`MAX_GRIDS` boards.

    Returns
    -------
    BoardSeen
    """
    small = reduce_image(image, coarse_scales(image.shape, None)[0])
    fill = int(np.median(small))
    other_sizes = [(o.cols, o.rows) for o in others]
    verdict = BoardSeen("none")
    for k in range(MAX_GRIDS):
        if k and _seed(small) is None:
            break  # no other board in view (a cheap look before the detector's full search)
        seen, grid = _look_once(small, board)
        if grid is None or seen.verdict == "match":
            return seen if seen.verdict == "match" else verdict
        if verdict.verdict == "none" and not any(_same(seen.size, s) for s in other_sizes):
            verdict = seen  # the first board of a size not known: named unless the one asked for is seen
        cv2.fillConvexPoly(small, np.round(mask_polygon(grid, 1.0)).astype(np.int32), fill)
    return verdict


def _sample(n: int, k: int) -> list[int]:
    """Up to ``k`` indices spread over ``n`` images: the middle first, then outward."""
    idx = list(dict.fromkeys(int(round(x)) for x in np.linspace(0, n - 1, min(n, k))))
    mid = (n - 1) / 2
    return sorted(idx, key=lambda i: abs(i - mid))


def _message(board: Chessboard, size: tuple[int, int], names: list[str], looked: int, what: str) -> str:
    asked = f"{board.cols}x{board.rows}"
    shown = f"{size[0]}x{size[1]}"
    text = (
        f"the images show a {shown} chessboard (inner corners), not {asked}: did you mean "
        f"{what} {shown}? ({len(names)} of the {looked} images checked show it whole: "
        f"{', '.join(names)})"
    )
    if _same((size[0] + 1, size[1] + 1), (board.cols, board.rows)):
        text += f"; {asked} counts the squares, {what} counts the inner corners (one fewer each way)"
    return text


def check_board_size(
    paths: Sequence[str | os.PathLike],
    board,
    *,
    others: Sequence = (),
    progress: Callable[[int, int], None] | None = None,
    sample: int = SAMPLE,
    what: str = "--board",
) -> list[BoardSeen]:
    """Check, on a few of the images, that they show the board asked for; raise if they show another.

    The images are looked at in turn (up to ``sample``, spread over the list, the middle one
    first; unreadable ones skipped) with :func:`board_seen`, until one shows the board asked
    for (the check passes) or :data:`AGREE` confirm one other size (:class:`BoardSizeError`).
    A ChArUco board (its markers name its size) passes unchecked.

    Parameters
    ----------
    paths : sequence of path-like
        Image files.
    board : Chessboard or CharucoBoard
    others : sequence of Chessboard or CharucoBoard
        Other boards in view (a fixed target), as :func:`board_seen`.
    progress : callable, optional
        ``progress(done, total)`` after each image looked at.
    sample : int
        Images looked at, at most.
    what : str
        How the board is named in the message (``"--board"``, ``"--fixed-board"``).

    Returns
    -------
    list of BoardSeen
        What each image looked at showed.

    Raises
    ------
    BoardSizeError
        One line: the size the images show, the images that show it, and the ``--board`` to give.
    """
    if not isinstance(board, Chessboard):
        return []
    others = [o.chessboard if isinstance(o, CharucoBoard) else o for o in others]
    others = [o for o in others if isinstance(o, Chessboard)]  # a size as text: not yet a board
    order = _sample(len(paths), sample)
    seen: list[BoardSeen] = []
    votes: dict[tuple[int, int], list[str]] = {}
    for done, i in enumerate(order, 1):
        try:
            image = read_image(paths[i])
        except InputError:
            continue  # the full search names it
        s = board_seen(image, board, others)
        seen.append(s)
        if progress is not None:
            progress(done, len(order))
        if s.verdict == "match":
            return seen
        if s.verdict == "other":
            names = votes.setdefault(tuple(sorted(s.size)), [])
            names.append(Path(paths[i]).name)
            if len(names) >= AGREE:
                raise BoardSizeError(
                    _message(board, s.size, names, len(seen), what), (board.cols, board.rows), s.size
                )
    return seen
