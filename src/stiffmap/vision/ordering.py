"""Canonical order of a chessboard's corner grid (``docs/conventions.md``, "Targets").

The grid a detector returns is re-indexed so that the board frame is right-handed (z
into the board) and square (i, j) is black when i + j is even. When the colours cannot
decide (``cols + rows`` even, square boards) the ordering follows continuity with a
reference detection, else the board's x axis is taken as the one pointing most to the
image's right; the colours then still say the board's colour *phase*: on such a board
the right-handed orderings all put square (0, 0) on the same colour, black or white
depending on how the board was printed, and the photometric model needs to know which.
"""

from __future__ import annotations

import numpy as np

from ..targets import Chessboard
from .board_plane import sample_bilinear
from .detection import BoardDetection, DetectionError

__all__ = ["canonical_order"]


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
    v = sample_bilinear(image, centres)
    even = ((ii + jj) % 2) == 0
    return float(v[even].mean() - v[~even].mean()) if (~even).any() else float(v[even].mean())


def canonical_order(
    image: np.ndarray, grid: np.ndarray, board: Chessboard, contrast: float, reference: BoardDetection | None
) -> tuple[np.ndarray, str, int]:
    """Canonical (rows, cols, 2) grid, what decided it, and the colour phase (0 or 1).

    The phase is 1 when, in the grid returned, the squares with i + j even are clearly
    white (:attr:`~stiffmap.vision.detection.BoardDetection.phase`).
    """
    g, how = _order(image, grid, contrast, reference)
    score = _parity_score(image, g)
    phase = int(score > 0 and abs(score) > 0.3 * max(contrast, 1.0))
    return g, how, phase


def _order(
    image: np.ndarray, grid: np.ndarray, contrast: float, reference: BoardDetection | None
) -> tuple[np.ndarray, str]:
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
