"""Printed targets as piecewise-constant textures on a grid of lines (board frame, mm).

A chessboard or ChArUco board is a set of axis-aligned rectangles in its own
frame (``docs/conventions.md``, "Targets"): squares, the bits of the ArUco
markers and a white margin. All of them are cells of one grid: the sorted
x-lines ``xs`` and y-lines ``ys`` cut the board plane into cells, and cell
(ix, iy) -- between ``xs[ix - 1]`` and ``xs[ix]`` and between ``ys[iy - 1]``
and ``ys[iy]``, with ix in 0..len(xs) and iy in 0..len(ys) -- has one
reflectance and one opacity. The cells of the outer ring (index 0 or last) are
off the board: opacity 0.

Colour convention (:mod:`stiffmap.targets`): square (i, j), covering
[i s, (i+1) s] x [j s, (j+1) s], is black when i + j is even. ChArUco boards
carry OpenCV's ArUco markers in their white squares, placed and numbered as
``cv2.aruco.CharucoBoard`` places them (its board frame is ours shifted by one
square: OpenCV's origin is the outer corner of the top-left square).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..targets import CharucoBoard, Chessboard

__all__ = ["BoardTexture", "texture_from_board", "WHITE", "BLACK"]

#: Default reflectances of the printed paper and of the toner (0..1).
WHITE = 0.92
BLACK = 0.06


@dataclass(frozen=True)
class BoardTexture:
    """A board's print as cells of a grid of lines.

    Attributes
    ----------
    xs : ndarray, shape (nx,)
        Strictly increasing x-lines, mm (board frame).
    ys : ndarray, shape (ny,)
        Strictly increasing y-lines, mm.
    reflectance : ndarray, shape (nx + 1, ny + 1)
        Reflectance (0..1) of each cell.
    alpha : ndarray, shape (nx + 1, ny + 1)
        1 on the board (squares, markers, margin), 0 off it.
    extent : (float, float, float, float)
        (x0, y0, x1, y1) of the board's physical outline (with margin), mm.
    """

    xs: np.ndarray
    ys: np.ndarray
    reflectance: np.ndarray
    alpha: np.ndarray
    extent: tuple[float, float, float, float]

    def cell_index(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Cell indices (ix, iy) of board points (x, y) in mm."""
        return np.searchsorted(self.xs, x, side="right"), np.searchsorted(self.ys, y, side="right")

    def sample(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(reflectance, alpha) at board points (x, y), mm (point samples, no filtering)."""
        ix, iy = self.cell_index(x, y)
        return self.reflectance[ix, iy], self.alpha[ix, iy]


def _grid_texture(
    xs: np.ndarray, ys: np.ndarray, colour_at, extent: tuple[float, float, float, float]
) -> BoardTexture:
    xs = np.unique(np.asarray(xs, dtype=np.float64))
    ys = np.unique(np.asarray(ys, dtype=np.float64))
    # Cell centres (the outer ring gets points just outside the board).
    cx = np.concatenate([[xs[0] - 1.0], 0.5 * (xs[1:] + xs[:-1]), [xs[-1] + 1.0]])
    cy = np.concatenate([[ys[0] - 1.0], 0.5 * (ys[1:] + ys[:-1]), [ys[-1] + 1.0]])
    X, Y = np.meshgrid(cx, cy, indexing="ij")
    refl, alpha = colour_at(X, Y)
    refl = np.ascontiguousarray(refl, dtype=np.float64)
    alpha = np.ascontiguousarray(alpha, dtype=np.float64)
    for a in (xs, ys, refl, alpha):
        a.setflags(write=False)
    return BoardTexture(xs, ys, refl, alpha, extent)


def _square_colour(board: Chessboard, X, Y, white: float, black: float) -> np.ndarray:
    s = board.square_mm
    i = np.floor(X / s).astype(np.int64)
    j = np.floor(Y / s).astype(np.int64)
    return np.where((i + j) % 2 == 0, black, white)


def texture_from_board(
    board: Chessboard | CharucoBoard,
    *,
    margin_mm: float | None = None,
    white: float = WHITE,
    black: float = BLACK,
) -> BoardTexture:
    """The print of a chessboard or ChArUco board.

    Parameters
    ----------
    board : Chessboard or CharucoBoard
    margin_mm : float, optional
        White border around the outer squares, mm (default one square; a
        chessboard detector needs a light quiet zone around the pattern).
    white, black : float
        Reflectances (0..1) of paper and ink.

    Returns
    -------
    BoardTexture
    """
    if not isinstance(board, (Chessboard, CharucoBoard)):
        raise ValueError(f"board must be a Chessboard or CharucoBoard, got {type(board).__name__}")
    s = board.square_mm
    m = s if margin_mm is None else float(margin_mm)
    if not np.isfinite(m) or m < 0:
        raise ValueError(f"margin_mm must be a finite number >= 0, got {margin_mm!r}")
    for name, v in (("white", white), ("black", black)):
        if not (np.isfinite(v) and 0.0 <= v <= 1.0):
            raise ValueError(f"{name} reflectance must be in [0, 1], got {v!r}")
    chess = board.chessboard if isinstance(board, CharucoBoard) else board
    x0, y0, x1, y1 = chess.extent_mm()
    ext = (x0 - m, y0 - m, x1 + m, y1 + m)
    xs = [ext[0], ext[2], *np.arange(chess.cols + 2) * s + x0]
    ys = [ext[1], ext[3], *np.arange(chess.rows + 2) * s + y0]

    def on_board(X, Y):
        return (X > ext[0]) & (X < ext[2]) & (Y > ext[1]) & (Y < ext[3])

    def in_squares(X, Y):
        return (X > x0) & (X < x1) & (Y > y0) & (Y < y1)

    if isinstance(board, Chessboard):

        def colour(X, Y):
            refl = np.where(in_squares(X, Y), _square_colour(chess, X, Y, white, black), white)
            return refl, on_board(X, Y).astype(np.float64)

        return _grid_texture(np.array(xs), np.array(ys), colour, ext)

    markers = _charuco_markers(board)  # list of (x0, y0, bits)
    nb = markers[0][2].shape[0] if markers else 0
    cell = board.marker_mm / nb if nb else 0.0
    for mx, my, _ in markers:
        xs.extend(mx + np.arange(nb + 1) * cell)
        ys.extend(my + np.arange(nb + 1) * cell)

    def colour_charuco(X, Y):
        refl = np.where(in_squares(X, Y), _square_colour(chess, X, Y, white, black), white)
        for mx, my, bits in markers:
            cx = np.floor((X - mx) / cell).astype(np.int64)
            cy = np.floor((Y - my) / cell).astype(np.int64)
            inside = (cx >= 0) & (cx < nb) & (cy >= 0) & (cy < nb)
            vals = np.where(bits[np.clip(cy, 0, nb - 1), np.clip(cx, 0, nb - 1)], white, black)
            refl = np.where(inside, vals, refl)
        return refl, on_board(X, Y).astype(np.float64)

    return _grid_texture(np.array(xs), np.array(ys), colour_charuco, ext)


def _charuco_markers(board: CharucoBoard) -> list[tuple[float, float, np.ndarray]]:
    """Markers of a ChArUco board as OpenCV lays them out, in our board frame.

    Returns a list of (x0, y0, bits): the marker's corner of smallest x and y
    (mm, our frame) and its cells including the black border, shape
    (n + 2, n + 2), True for white, rows along y.
    """
    name = board.dictionary
    if not hasattr(cv2.aruco, name):
        raise ValueError(f"unknown ArUco dictionary {name!r} (expected an OpenCV name such as DICT_5X5_100)")
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    cvb = cv2.aruco.CharucoBoard(
        (board.squares_x, board.squares_y), board.square_mm, board.marker_mm, dictionary
    )
    if cvb.getLegacyPattern():  # pragma: no cover - OpenCV default is the modern pattern
        raise RuntimeError("OpenCV's ChArUco board uses the legacy pattern; stiffmap expects the modern one")
    ids = np.asarray(cvb.getIds()).ravel()
    nbits = int(dictionary.markerSize)
    s = board.square_mm
    out = []
    for corners, mid in zip(cvb.getObjPoints(), ids, strict=True):
        c = np.asarray(corners, dtype=np.float64).reshape(4, 3)
        img = cv2.aruco.generateImageMarker(dictionary, int(mid), nbits + 2, borderBits=1)
        # OpenCV's board frame has its origin at the outer corner of the first square.
        out.append((float(c[:, 0].min()) - s, float(c[:, 1].min()) - s, np.asarray(img) > 127))
    return out
