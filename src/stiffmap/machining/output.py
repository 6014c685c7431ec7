"""A compensation written back: the program's moves as pieces, and rows of a CSV of points.

:func:`program_pieces` turns a :class:`~stiffmap.machining.compensate.Compensation` into
the :class:`~stiffmap.machining.gcode.Piece` lists that
:func:`~stiffmap.machining.gcode.render_program` writes in place of each move; every other
line of the program stays as it was. :func:`point_rows` gives the commanded points of a
CSV path, one row per output point.
"""

from __future__ import annotations

import numpy as np

from .compensate import Compensation
from .gcode import LINE, Piece, Program
from .path import Toolpath

__all__ = ["program_pieces", "point_rows", "output_points"]


def program_pieces(
    program: Program, path: Toolpath, comp: Compensation, corrected: tuple[int, ...]
) -> tuple[dict[int, list[Piece]], dict[int, tuple[int, ...]]]:
    """The pieces that replace each compensated move, and the axes each writes.

    A compensated move writes the corrected axes (x, y for a planar mechanism; x, y, z
    otherwise) and the axes its line named; a corner adds a straight piece to the next
    cut's start.

    Returns
    -------
    outputs : dict of int to list of Piece
    axes : dict of int to tuple of int
    """
    outputs: dict[int, list[Piece]] = {}
    axes: dict[int, tuple[int, ...]] = {}
    for m, mp in comp.pieces.items():
        mv = program.moves[m]
        kind = mv.kind
        pcs = []
        for j in range(1, mp.s.size):
            c = None if mp.centres is None else mp.centres[j - 1]
            pcs.append(Piece(kind, mp.points[j], c))
        if m in comp.transitions:
            pcs.append(Piece(LINE, comp.transitions[m]))
        outputs[m] = pcs
        named = {"XYZ".index(a) for a in mv.axes}
        axes[m] = tuple(sorted(set(corrected) | named | _changed(path, m)))
    return outputs, axes


def _changed(path: Toolpath, m: int) -> set[int]:
    """Axes whose value changes along move m (a ramp's z on a planar mechanism; both axes of an
    arc's plane, which change along it even where its ends agree: a G18 arc from z 0 to z 0)."""
    moved = {k for k in range(3) if path.start[m, k] != path.end[m, k]}
    if path.is_arc[m]:
        moved |= {int(path.axes[m, 0]), int(path.axes[m, 1])}
    return moved


def output_points(comp: Compensation) -> tuple[np.ndarray, np.ndarray]:
    """Every output point in order: the moves' pieces' ends and the corners.

    Returns
    -------
    move : ndarray of int, shape (N,)
        The move each point belongs to.
    points : ndarray, shape (N, 3), mm, program frame
    """
    moves, pts = [], []
    for m in sorted(comp.pieces):
        mp = comp.pieces[m]
        first = 0 if not moves else 1
        pts.append(mp.points[first:])
        moves.append(np.full(mp.points.shape[0] - first, m))
        if m in comp.transitions:
            pts.append(comp.transitions[m][None])
            moves.append(np.array([m]))
    if not pts:
        return np.zeros(0, dtype=np.intp), np.zeros((0, 3))
    return np.concatenate(moves), np.vstack(pts)


def point_rows(comp: Compensation, path: Toolpath, n_points: int) -> np.ndarray:
    """The commanded points of a CSV path (moves between consecutive points), in order.

    Parameters
    ----------
    comp : Compensation
    path : Toolpath
        From :func:`~stiffmap.machining.path.toolpath_from_points` (n_points - 1 moves).
    n_points : int

    Returns
    -------
    ndarray, shape (M, 4)
        Columns: x, y, z (mm, commanded), and the 1-based row of the input point each
        output point ends at (0 for points added between two input points).
    """
    rows = []
    for m in range(n_points - 1):
        mp = comp.pieces[m]
        if m == 0:
            rows.append(np.append(mp.points[0], 1.0))
        for j in range(1, mp.s.size):
            rows.append(np.append(mp.points[j], float(m + 2) if j == mp.s.size - 1 else 0.0))
    return np.array(rows).reshape(-1, 4)
