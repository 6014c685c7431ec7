"""Toolpath geometry: straight and circular (helical) moves as arrays, evaluated at parameters.

A :class:`Toolpath` holds n moves in the program's frame (mm). Move m runs from
``start[m]`` (parameter s = 0) to ``end[m]`` (s = 1):

- a straight move (rapid or feed): ``p(s) = start + s (end - start)``;
- an arc in plane (a, b) with normal axis n (G17: x, y, z; G18: z, x, y; G19: y, z, x):
  ``theta(s) = theta0 + s sweep``, radius ``r(s) = r0 + s (r1 - r0)`` (the programmed
  start and end radii, equal within the reader's tolerance), the normal coordinate
  linear in s (a helix): ``p_a = c_a + r cos theta``, ``p_b = c_b + r sin theta``.
  G3 (counter-clockwise seen from +n) has a positive sweep, G2 a negative one; a full
  circle (start = end) turns once.

Every function is vectorised over (move index, parameter) pairs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .gcode import ARC_CCW, ARC_CW, PLANE_AXES, RAPID, Move

__all__ = ["Toolpath", "toolpath_from_moves", "toolpath_from_points", "arc_frame"]


@dataclass(frozen=True)
class Toolpath:
    """n moves as arrays (program frame, mm).

    Attributes
    ----------
    kind : ndarray of int, shape (n,)
        0 rapid, 1 line, 2 clockwise arc, 3 counter-clockwise arc.
    line : ndarray of int, shape (n,)
        The program's line (or the CSV's line) of each move, for messages.
    start, end : ndarray, shape (n, 3), mm
    axes : ndarray of int, shape (n, 3)
        Columns (a, b, n) of x, y, z for each move's plane (arcs; lines (0, 1, 2)).
    centre : ndarray, shape (n, 2), mm
        Arc centre in (a, b) (NaN for lines).
    theta0, sweep : ndarray, shape (n,), rad
        Start angle and signed angle turned (0 for lines).
    r0, r1 : ndarray, shape (n,), mm
        Start and end radius (0 for lines).
    known : ndarray of bool, shape (n, 3)
        Whether each axis of the end is known (the program may leave one unknown after
        G28/G30/G53).
    """

    kind: np.ndarray
    line: np.ndarray
    start: np.ndarray
    end: np.ndarray
    axes: np.ndarray
    centre: np.ndarray
    theta0: np.ndarray
    sweep: np.ndarray
    r0: np.ndarray
    r1: np.ndarray
    known: np.ndarray

    def __len__(self) -> int:
        return int(self.kind.size)

    @property
    def known_start(self) -> np.ndarray:
        """Whether each axis of each move's start is known, shape (n, 3)."""
        return np.vstack([np.ones((1, 3), dtype=bool), self.known[:-1]]) if len(self) else self.known

    @property
    def feed(self) -> np.ndarray:
        """Feed moves (G1, G2, G3), which carry the cutting force."""
        return self.kind != RAPID

    @property
    def is_arc(self) -> np.ndarray:
        return (self.kind == ARC_CW) | (self.kind == ARC_CCW)

    def point(self, m, s) -> np.ndarray:
        """Programmed points ``p_m(s)``, shape (N, 3), mm, for moves ``m`` (N,) at ``s`` (N,)."""
        m = np.asarray(m, dtype=np.intp)
        s = np.asarray(s, dtype=np.float64)
        p = self.start[m] + s[:, None] * (self.end[m] - self.start[m])
        arc = self.is_arc[m]
        if np.any(arc):
            ma, sa = m[arc], s[arc]
            th = self.theta0[ma] + sa * self.sweep[ma]
            r = self.r0[ma] + sa * (self.r1[ma] - self.r0[ma])
            ax = self.axes[ma]
            rows = np.arange(ma.size)
            q = p[arc]
            q[rows, ax[:, 0]] = self.centre[ma, 0] + r * np.cos(th)
            q[rows, ax[:, 1]] = self.centre[ma, 1] + r * np.sin(th)
            p[arc] = q
        return p

    def tangent(self, m, s) -> np.ndarray:
        """Unit direction of travel ``dp/ds / |dp/ds|``, shape (N, 3) (zero for a null move)."""
        m = np.asarray(m, dtype=np.intp)
        s = np.asarray(s, dtype=np.float64)
        d = self.end[m] - self.start[m]
        arc = self.is_arc[m]
        if np.any(arc):
            ma, sa = m[arc], s[arc]
            th = self.theta0[ma] + sa * self.sweep[ma]
            r = self.r0[ma] + sa * (self.r1[ma] - self.r0[ma])
            dr = self.r1[ma] - self.r0[ma]
            w = self.sweep[ma]
            ax = self.axes[ma]
            rows = np.arange(ma.size)
            q = d[arc]
            q[rows, ax[:, 0]] = dr * np.cos(th) - r * w * np.sin(th)
            q[rows, ax[:, 1]] = dr * np.sin(th) + r * w * np.cos(th)
            d[arc] = q
        n = np.linalg.norm(d, axis=1)
        return np.divide(d, n[:, None], out=np.zeros_like(d), where=n[:, None] > 0)

    def length(self) -> np.ndarray:
        """Length of each move, mm (a helix's: its turn and its rise)."""
        chord = np.linalg.norm(self.end - self.start, axis=1)
        arc = self.is_arc
        L = chord.copy()
        if np.any(arc):
            rm = 0.5 * (self.r0[arc] + self.r1[arc])
            rows = np.arange(len(self))[arc]
            rise = self.end[rows, self.axes[arc, 2]] - self.start[rows, self.axes[arc, 2]]
            L[arc] = np.hypot(np.abs(self.sweep[arc]) * rm, rise)
        return L

    def distance(self, m, q) -> np.ndarray:
        """Distance (mm) from points ``q`` (N, 3) to their moves ``m`` (N,): to the segment, or to
        the arc (the nearest of its points at the point's angle, turn by turn, and its ends: an
        upper bound of the distance to a helix, exact for a planar arc)."""
        m = np.asarray(m, dtype=np.intp)
        q = np.asarray(q, dtype=np.float64)
        a, b = self.start[m], self.end[m]
        d = b - a
        dd = np.einsum("ij,ij->i", d, d)
        t = np.clip(np.einsum("ij,ij->i", q - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        out = np.linalg.norm(q - (a + t[:, None] * d), axis=1)
        arc = self.is_arc[m]
        if np.any(arc):
            out[arc] = self._arc_distance(m[arc], q[arc])
        return out

    def _arc_distance(self, m: np.ndarray, q: np.ndarray) -> np.ndarray:
        ax = self.axes[m]
        rows = np.arange(m.size)
        phi = np.arctan2(q[rows, ax[:, 1]] - self.centre[m, 1], q[rows, ax[:, 0]] - self.centre[m, 0])
        w = self.sweep[m]
        best = np.minimum(np.linalg.norm(q - self.start[m], axis=1), np.linalg.norm(q - self.end[m], axis=1))
        for k in (-1, 0, 1, 2):
            s = (phi + 2 * math.pi * k - self.theta0[m]) / np.where(w != 0, w, 1.0)
            inside = (s >= 0) & (s <= 1)
            if np.any(inside):
                p = self.point(m[inside], s[inside])
                best[inside] = np.minimum(best[inside], np.linalg.norm(q[inside] - p, axis=1))
        return best


def arc_frame(plane: int) -> tuple[int, int, int]:
    """The (a, b, n) axes of G17, G18 or G19."""
    return PLANE_AXES[plane]


def _arc_params(start, end, centre, axes, kind) -> tuple[float, float, float, float]:
    """theta0, sweep, r0, r1 of one arc."""
    a, b, _ = axes
    t0 = math.atan2(start[b] - centre[b], start[a] - centre[a])
    t1 = math.atan2(end[b] - centre[b], end[a] - centre[a])
    r0 = math.hypot(start[a] - centre[a], start[b] - centre[b])
    r1 = math.hypot(end[a] - centre[a], end[b] - centre[b])
    full = math.hypot(end[a] - start[a], end[b] - start[b]) <= 1e-9 * max(r0, 1.0)
    if kind == ARC_CCW:
        sw = (t1 - t0) % (2 * math.pi)
        sw = 2 * math.pi if full or sw == 0 else sw
    else:
        sw = (t0 - t1) % (2 * math.pi)
        sw = -(2 * math.pi if full or sw == 0 else sw)
    return t0, sw, r0, r1


def toolpath_from_moves(moves: tuple[Move, ...] | list[Move]) -> Toolpath:
    """The :class:`Toolpath` of a program's moves (:class:`~stiffmap.machining.gcode.Move`).

    The first move starts wherever the machine stands when the program begins: a feed move
    there is taken as an approach (a rapid, carrying no force), not as a cut.
    """
    n = len(moves)
    kind = np.array([mv.kind for mv in moves], dtype=np.intp).reshape(n)
    start = np.array([mv.start for mv in moves], dtype=float).reshape(n, 3)
    end = np.array([mv.end for mv in moves], dtype=float).reshape(n, 3)
    axes = np.tile(np.arange(3), (n, 1))
    centre = np.full((n, 2), np.nan)
    theta0, sweep, r0, r1 = (np.zeros(n) for _ in range(4))
    for i, mv in enumerate(moves):
        if mv.centre is None:
            continue
        ax = PLANE_AXES[mv.plane]
        axes[i] = ax
        centre[i] = mv.centre[ax[0]], mv.centre[ax[1]]
        theta0[i], sweep[i], r0[i], r1[i] = _arc_params(mv.start, mv.end, mv.centre, ax, mv.kind)
    known = np.array([mv.known for mv in moves], dtype=bool).reshape(n, 3)
    if n and kind[0] != RAPID:
        # The first move starts wherever the machine stands: not a cut but an approach, which
        # (as a rapid) goes to the next cut's compensated start.
        kind[0] = RAPID
        centre[0] = np.nan
        theta0[0] = sweep[0] = r0[0] = r1[0] = 0.0
        axes[0] = np.arange(3)
    line = np.array([mv.line for mv in moves], dtype=np.intp).reshape(n)
    return Toolpath(kind, line, start, end, axes, centre, theta0, sweep, r0, r1, known)


def toolpath_from_points(points, lines=None) -> Toolpath:
    """Feed lines through points (N, 3) mm: move i runs from point i to point i + 1.

    Parameters
    ----------
    points : array_like, shape (N, 3), mm
    lines : array_like of int, shape (N,), optional
        The file line of each point; move i is named by its end's line.
    """
    P = np.asarray(points, dtype=float)
    n = P.shape[0] - 1
    ln = np.arange(2, n + 2) if lines is None else np.asarray(lines, dtype=np.intp)[1:]
    z = np.zeros(n)
    return Toolpath(
        kind=np.ones(n, dtype=np.intp),
        line=ln,
        start=P[:-1].copy(),
        end=P[1:].copy(),
        axes=np.tile(np.arange(3), (n, 1)),
        centre=np.full((n, 2), np.nan),
        theta0=z,
        sweep=z.copy(),
        r0=z.copy(),
        r1=z.copy(),
        known=np.ones((n, 3), dtype=bool),
    )
