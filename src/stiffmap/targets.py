"""Planar calibration targets: chessboards and ChArUco boards (pure geometry).

The board frame is canonical (``docs/conventions.md``): x along the columns of
inner corners, y along the rows, z = x cross y into the board (right-handed);
inner corner (c, r) is at (c * s, r * s, 0) mm for square size s.

Squares are indexed by the inner corner at their lower (x, y) side plus one:
square (i, j), i in -1..cols-1, j in -1..rows-1, covers
[i s, (i+1) s] x [j s, (j+1) s]. Square (i, j) is **black when i + j is even**,
so the square diagonally outside the origin corner, (-1, -1), is black. When
``cols + rows`` is odd the colour pattern is not invariant under a half turn,
so the origin is fixed by the colours in every image; when it is even, the board
looks the same turned by 180 degrees and the ordering must follow continuity
with a reference image.

This module holds no image code: ``stiffmap.vision`` detects these boards and
``stiffmap.sim`` renders them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Chessboard",
    "CharucoBoard",
    "as_board",
    "parse_board_size",
    "ARUCO_DICTIONARIES",
    "SQUARE_MM_RANGE",
]

_SIZE = re.compile(r"^\s*(\d+)\s*[xX×]\s*(\d+)\s*$")

#: Fewest inner corners along one side of a chessboard (OpenCV's detectors need 3).
MIN_CORNERS_PER_SIDE = 3
#: Most inner corners along one side of a board (a printed target, not a texture).
MAX_CORNERS_PER_SIDE = 200
#: Plausible side of a square or of a marker, mm (a micro-target to a 10 m board).
SQUARE_MM_RANGE = (1e-3, 1e4)
#: OpenCV's predefined ArUco dictionaries -> how many markers each holds.
ARUCO_DICTIONARIES = {
    **{f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)},
    "DICT_ARUCO_ORIGINAL": 1024,
    "DICT_APRILTAG_16h5": 30,
    "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_36h10": 2320,
    "DICT_APRILTAG_36h11": 587,
    "DICT_ARUCO_MIP_36h12": 250,
}


def parse_board_size(text: str) -> tuple[int, int]:
    """Parse ``"COLSxROWS"`` (inner corners) into (cols, rows).

    Raises
    ------
    ValueError
        If the text is not two integers joined by ``x``, each from 3 to 200.
    """
    m = _SIZE.match(str(text))
    if not m:
        raise ValueError(f"board size must look like COLSxROWS (inner corners), e.g. 13x12; got {text!r}")
    cols, rows = int(m.group(1)), int(m.group(2))
    _check_corners(cols, rows)
    return cols, rows


def _check_corners(cols: int, rows: int, least: int = MIN_CORNERS_PER_SIDE) -> None:
    if cols < least or rows < least:
        raise ValueError(f"a board needs at least {least}x{least} inner corners, got {cols}x{rows}")
    if max(cols, rows) > MAX_CORNERS_PER_SIDE:
        raise ValueError(
            f"{cols}x{rows} inner corners is not a printed board (at most {MAX_CORNERS_PER_SIDE} per side)"
        )


def _check_positive(value: float, name: str) -> float:
    """A side in mm: finite, within :data:`SQUARE_MM_RANGE`."""
    v = float(value)
    lo, hi = SQUARE_MM_RANGE
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a positive number of mm, got {value!r}")
    if not lo <= v <= hi:
        raise ValueError(f"{name} of {v:g} mm is not a printed square's side (expected {lo:g} to {hi:g} mm)")
    return v


@dataclass(frozen=True)
class Chessboard:
    """A chessboard target.

    Parameters
    ----------
    cols, rows : int
        Inner corners along x and along y (``COLSxROWS``).
    square_mm : float
        Side of a square, mm.

    Examples
    --------
    A board of 9x6 inner corners and 25 mm squares: 54 corners, row-major from the origin;
    9 + 6 is odd, so the square colours fix the origin in every image.

    >>> b = Chessboard.parse("9x6", 25.0)
    >>> b.n_corners, b.orientation_from_colours
    (54, True)
    >>> b.object_points()[[0, 1, 9, 53]].tolist()  # corners (0, 0), (1, 0), (0, 1), (8, 5), mm
    [[0.0, 0.0, 0.0], [25.0, 0.0, 0.0], [0.0, 25.0, 0.0], [200.0, 125.0, 0.0]]
    """

    cols: int
    rows: int
    square_mm: float

    def __post_init__(self) -> None:
        _check_corners(int(self.cols), int(self.rows))
        object.__setattr__(self, "cols", int(self.cols))
        object.__setattr__(self, "rows", int(self.rows))
        object.__setattr__(self, "square_mm", _check_positive(self.square_mm, "square_mm"))

    @classmethod
    def parse(cls, size: str, square_mm: float) -> Chessboard:
        """Board from ``"COLSxROWS"`` and a square size in mm."""
        cols, rows = parse_board_size(size)
        return cls(cols, rows, square_mm)

    @property
    def size(self) -> str:
        """``"COLSxROWS"``."""
        return f"{self.cols}x{self.rows}"

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows), the ``patternSize`` OpenCV expects."""
        return (self.cols, self.rows)

    @property
    def orientation_from_colours(self) -> bool:
        """True when the square colours fix the origin (``cols + rows`` odd)."""
        return (self.cols + self.rows) % 2 == 1

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame.

        Returns
        -------
        ndarray, shape (cols * rows, 3), mm
            Row-major: index ``r * cols + c`` is corner (c, r) at (c s, r s, 0).
        """
        c, r = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        pts = np.zeros((self.rows * self.cols, 3))
        pts[:, 0] = c.ravel() * self.square_mm
        pts[:, 1] = r.ravel() * self.square_mm
        return pts

    def square_is_black(self, i, j):
        """Colour of square (i, j) (see the module docstring): black when i + j is even."""
        return (np.asarray(i) + np.asarray(j)) % 2 == 0

    def extent_mm(self) -> tuple[float, float, float, float]:
        """Printed area (x0, y0, x1, y1) in the board frame, mm, without any white margin."""
        s = self.square_mm
        return (-s, -s, self.cols * s, self.rows * s)


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board: a chessboard with ArUco markers in its white squares.

    Parameters
    ----------
    squares_x, squares_y : int
        Squares along x and y; inner corners are (squares_x - 1) x (squares_y - 1).
    square_mm, marker_mm : float
        Side of a square and of a marker, mm (marker_mm < square_mm).
    dictionary : str
        OpenCV predefined dictionary name, e.g. ``"DICT_5X5_100"`` (a key of
        :data:`ARUCO_DICTIONARIES`; the board's markers must fit in it).

    The board frame and the corner numbering are those of :class:`Chessboard`
    with ``cols = squares_x - 1`` and ``rows = squares_y - 1``; the markers
    identify each corner, so a partly hidden board is still usable.
    """

    squares_x: int
    squares_y: int
    square_mm: float
    marker_mm: float
    dictionary: str = "DICT_5X5_100"

    def __post_init__(self) -> None:
        if int(self.squares_x) < 3 or int(self.squares_y) < 3:
            raise ValueError(
                f"a ChArUco board needs at least 3x3 squares, got {self.squares_x}x{self.squares_y}"
            )
        object.__setattr__(self, "squares_x", int(self.squares_x))
        object.__setattr__(self, "squares_y", int(self.squares_y))
        _check_corners(self.squares_x - 1, self.squares_y - 1, least=2)
        if self.dictionary not in ARUCO_DICTIONARIES:
            raise ValueError(
                f"unknown ArUco dictionary {self.dictionary!r} (OpenCV's predefined ones: "
                f"{', '.join(ARUCO_DICTIONARIES)})"
            )
        n_markers = self.squares_x * self.squares_y // 2
        if n_markers > ARUCO_DICTIONARIES[self.dictionary]:
            raise ValueError(
                f"a ChArUco board of {self.squares_x}x{self.squares_y} squares holds {n_markers} markers, "
                f"more than the {ARUCO_DICTIONARIES[self.dictionary]} of {self.dictionary}"
            )
        sq = _check_positive(self.square_mm, "square_mm")
        mk = _check_positive(self.marker_mm, "marker_mm")
        if mk >= sq:
            raise ValueError(f"marker_mm ({mk}) must be smaller than square_mm ({sq})")
        object.__setattr__(self, "square_mm", sq)
        object.__setattr__(self, "marker_mm", mk)

    @property
    def chessboard(self) -> Chessboard:
        """The underlying chessboard (inner corners and frame)."""
        return Chessboard(self.squares_x - 1, self.squares_y - 1, self.square_mm)

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame, shape ((sx-1)(sy-1), 3), mm, row-major."""
        return self.chessboard.object_points()


def as_board(board, square_mm: float | None = None, what: str = "board") -> Chessboard | CharucoBoard:
    """The board a function was given: a :class:`Chessboard`, a :class:`CharucoBoard`, or a
    chessboard's size ``"COLSxROWS"`` (inner corners, as the command line's ``--board``) with
    its ``square_mm``.

    Parameters
    ----------
    board : Chessboard, CharucoBoard or str
    square_mm : float, optional
        Side of a square, mm: needed with a size given as text (poses and calibration views
        are in mm), and when given with a board object it must be that board's.
    what : str
        The argument's name, for the messages (``"board"``, ``"fixed_board"``).

    Raises
    ------
    ValueError
        Naming the argument and saying what was expected: text that is not ``COLSxROWS``,
        a size without ``square_mm``, a square size that disagrees with the board's, or
        something that is not a board.
    """
    if isinstance(board, Chessboard | CharucoBoard):
        if square_mm is not None and not np.isclose(float(square_mm), board.square_mm):
            raise ValueError(
                f"{what}: square_mm={square_mm:g} but the board's squares are {board.square_mm:g} mm"
            )
        return board
    if isinstance(board, str):
        try:
            cols, rows = parse_board_size(board)
        except ValueError as e:
            raise ValueError(f"{what} {board!r}: {e}") from None
        if square_mm is None:
            raise ValueError(
                f"{what} {board!r}: a board given by its size also needs its square size, e.g. "
                f"{what}={board!r}, square_mm=25.0 (mm), or {what}=Chessboard({cols}, {rows}, 25.0)"
            )
        return Chessboard(cols, rows, square_mm)
    raise ValueError(
        f"{what}: expected a Chessboard, a CharucoBoard or a size 'COLSxROWS' with square_mm, "
        f"got {type(board).__name__}"
    )
