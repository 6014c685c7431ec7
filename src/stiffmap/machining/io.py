"""Files of ``stiffmap compensate``: the program (G-code or a CSV of points), a force file, and the outputs.

Formats (``docs/machining.md``):

- **Program**: RS274/NGC G-code (:mod:`~stiffmap.machining.gcode`), UTF-8 or any 8-bit
  encoding (read and written back byte for byte as Latin-1 when it is not UTF-8), its
  line endings kept.
- **Points** (``.csv``): columns ``x, y, z`` (mm; ``z`` optional for a planar mechanism)
  and optionally ``fx, fy[, fz]`` (N): the force at each point; the tool feeds in a
  straight line from each point to the next.
- **Force file** (``--force-file``, for a G-code program): one row per feed move (G1, G2,
  G3) in program order, columns ``line`` (its line number in the program) and
  ``fx, fy[, fz]`` (N, base frame): the force along that move.

Every problem is an :class:`~stiffmap.errors.InputError` naming the file, the line and the
field. Outputs are written atomically (:func:`stiffmap.io.atomic_write_text`), after the
whole compensation has succeeded: a failed run writes nothing.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_write_bytes, read_csv_columns
from ..loads import MAX_FORCE_N
from ..stiffness import MAX_POSITION_MM
from .gcode import Program, parse_program

__all__ = [
    "ProgramText",
    "read_program",
    "read_points_path",
    "read_force_file",
    "write_text",
    "is_points_file",
]


@dataclass(frozen=True)
class ProgramText:
    """A program file's text and how to write it back (its encoding)."""

    text: str
    encoding: str


def is_points_file(path: str | os.PathLike) -> bool:
    """A CSV of points (by its extension ``.csv``), rather than G-code."""
    return Path(path).suffix.lower() == ".csv"


def _read_text(path: str | os.PathLike) -> ProgramText:
    src = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", source=src) from None
    if b"\x00" in raw:
        raise InputError("holds NUL bytes: not a text program (a binary file, or UTF-16 text?)", source=src)
    try:
        return ProgramText(raw.decode("utf-8-sig"), "utf-8")
    except UnicodeDecodeError:
        return ProgramText(raw.decode("latin-1"), "latin-1")


def read_program(path: str | os.PathLike, *, pass_through: bool = False) -> tuple[Program, ProgramText]:
    """Read and parse a G-code program (:func:`~stiffmap.machining.gcode.parse_program`).

    Raises
    ------
    InputError
        The file cannot be read, holds no move, or a line cannot be compensated (named).
    """
    t = _read_text(path)
    prog = parse_program(t.text, str(path), pass_through=pass_through)
    if not prog.moves:
        raise InputError("holds no move (G0, G1, G2, G3): nothing to compensate", source=str(path))
    return prog, t


def read_points_path(path: str | os.PathLike, dim: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """A CSV of points: positions (N, 3) mm, forces (N, 3) N or None, and each row's file line.

    Raises
    ------
    InputError
        A missing column, a bad cell (its line named), fewer than two points.
    """
    need = ["x", "y"] + (["z"] if dim == 3 else [])
    t = read_csv_columns(path, need, [c for c in ("z", "fx", "fy", "fz") if c not in need])
    n = len(t)
    if n < 2:
        raise InputError(f"{n} point(s): a path needs at least two", source=str(path))
    t.check_magnitude(["x", "y", "z"], MAX_POSITION_MM, "mm", "position")
    t.check_magnitude(["fx", "fy", "fz"], MAX_FORCE_N, "N", "force")
    P = np.zeros((n, 3))
    for k, c in enumerate("xyz"):
        if t.has(c):
            P[:, k] = t.columns[c]
    F = None
    if t.has("fx") or t.has("fy"):
        if not (t.has("fx") and t.has("fy")):
            raise InputError(
                "force columns: give both fx and fy (N), and fz for a spatial robot", source=str(path)
            )
        F = np.zeros((n, 3))
        for k, c in enumerate(("fx", "fy", "fz")):
            if t.has(c):
                F[:, k] = t.columns[c]
    return P, F, t.lines


def read_force_file(path: str | os.PathLike, feed_lines: np.ndarray) -> np.ndarray:
    """Forces (N, base frame) of the feed moves, one row each, matched by their program line.

    Parameters
    ----------
    path : path-like
    feed_lines : ndarray of int, shape (M,)
        The program's line of each feed move, in order.

    Returns
    -------
    ndarray, shape (M, 3), N

    Raises
    ------
    InputError
        Rows that do not match the program's feed moves (count or line), a bad cell.
    """
    t = read_csv_columns(path, ["line", "fx", "fy"], ["fz"])
    src = str(path)
    t.check_magnitude(["fx", "fy", "fz"], MAX_FORCE_N, "N", "force")
    lines = t.columns["line"]
    M = int(feed_lines.size)
    if len(t) != M:
        raise InputError(
            f"{len(t)} force row(s), but the program has {M} feed move(s) (G1/G2/G3): give one row per "
            "feed move, in program order",
            source=src,
        )
    bad = np.flatnonzero(lines != feed_lines)
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"line {t.lines[i]}, column 'line': {lines[i]:g}, but feed move {i + 1} of the program is on "
            f"line {feed_lines[i]}",
            source=src,
        )
    F = np.zeros((M, 3))
    F[:, 0], F[:, 1] = t.columns["fx"], t.columns["fy"]
    if t.has("fz"):
        F[:, 2] = t.columns["fz"]
    return F


def write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write a text file atomically in the given encoding (the program's own)."""
    atomic_write_bytes(path, text.encode(encoding))
