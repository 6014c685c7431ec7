"""What finding a board in an image gives: :class:`BoardDetection`, and :class:`DetectionError`.

The result type of every detector of :mod:`stiffmap.vision.detect` (chessboard search,
ChArUco markers, tracking), the error they raise, and how boards are named in messages.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..targets import CharucoBoard, Chessboard

__all__ = ["Board", "BoardDetection", "DetectionError", "board_label", "grid_of"]

Board = Chessboard | CharucoBoard


class DetectionError(InputError):
    """A board could not be found or used in an image.

    Attributes
    ----------
    reason : str
        ``"not_found"`` (no board of that size), ``"wrong_size"`` (the printed
        board has more corners than the size given), ``"partial"`` (only part of
        the board is visible or usable), ``"ambiguous"`` (boards that cannot be
        told apart).
    found : list of (BoardDetection or None) or None
        Set by :func:`~stiffmap.vision.detect.detect_boards`: the boards of the call that were
        found before it failed (None where not), in the order they were asked for.
    larger : LargerBoard or None
        With ``reason == "wrong_size"``: the printed board the image shows instead
        (:class:`~stiffmap.vision.chessboard.LargerBoard`: its size, and whether it was seen
        whole), when it could be followed.
    """

    def __init__(
        self, message: str, *, source: str | None = None, reason: str = "not_found", larger=None
    ) -> None:
        super().__init__(message, source=source)
        self.reason = reason
        self.found: list | None = None
        self.larger = larger

    def with_source(self, source: str) -> DetectionError:
        if self.source:
            return self
        return DetectionError(self.detail, source=source, reason=self.reason, larger=self.larger)


def board_label(board: Board) -> str:
    """``"8x6 chessboard"`` or ``"ChArUco 9x7 squares (8x6 corners)"``."""
    if isinstance(board, CharucoBoard):
        cb = board.chessboard
        return f"ChArUco {board.squares_x}x{board.squares_y} squares ({cb.cols}x{cb.rows} corners)"
    return f"{board.cols}x{board.rows} chessboard"


def grid_of(board: Board) -> Chessboard:
    """The chessboard of inner corners of a board (a ChArUco board's own)."""
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
        right), ``"markers"`` (ChArUco), ``"tracked"`` or ``"photometric"`` (followed by the
        photometric fit alone: ``corners`` projected at its pose, ``residual_px`` NaN; see
        :func:`~stiffmap.vision.pose.follow_pose`).
    rejected : ndarray of int
        Canonical ids of corners found but rejected by the homography check.
    seconds : float
        Time spent, s.
    phase : int
        Colour phase of the printed squares in the canonical frame: 0 when square
        (i, j) is black for i + j even (``docs/conventions.md``), 1 when it is white.
        Only a board whose two right-handed orderings have the same colours (odd
        numbers of inner corners both ways, or even both ways) can have phase 1:
        which diagonal of its corners is black depends on how it was printed.
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
    phase: int = 0

    @property
    def n_corners(self) -> int:
        """Number of corners kept."""
        return int(self.ids.size)

    @property
    def complete(self) -> bool:
        """True when every inner corner of the board was kept."""
        return self.n_corners == grid_of(self.board).n_corners

    @property
    def rms_residual_px(self) -> float:
        """RMS of the homography residuals, px."""
        return float(np.sqrt(np.mean(self.residual_px**2))) if self.residual_px.size else float("nan")

    def object_points(self) -> np.ndarray:
        """Board-frame coordinates of the kept corners, shape (m, 3), mm."""
        return grid_of(self.board).object_points()[self.ids]
