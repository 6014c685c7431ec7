"""How to cut with a six-axis arm: the free rotation (spin) of the tool about its own axis.

A milling tool is symmetric about its axis, so a task leaves the arm's rotation about the
tool axis free: every spin psi (the tool orientation R turned by Rz(psi) about the
program's z axis, the tool axis of a three-axis program, through the tool point) cuts the
same part, with a different arm configuration and a different deflection. (With the tool
point on the last joint's axis, the spin only turns that joint and changes nothing; a
tool held off the flange's axis, as an angled head holds it, moves the whole arm.) At the
program's knots (the start of the first move and every move's end) the deflection
|delta| is evaluated for candidate spins every :data:`SPIN_STEP_DEG` degrees (the
configuration solved along the program for each, one branch; a spin that puts a joint
beyond its limits, out of reach or near a singularity is excluded); a dynamic programme
then picks one spin per knot that minimises the sum of |delta|^4 (which weighs the worst
points most) while the spin changes by at most :data:`MAX_CHANGE_DEG` from one knot to the
next (smoothly). Along a move the spin varies linearly between its ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .field import ArmField
from .forces import ForceSpec, force_at
from .path import Toolpath

__all__ = ["SpinPlan", "choose_spin", "SPIN_STEP_DEG", "MAX_CHANGE_DEG"]

SPIN_STEP_DEG = 15.0
MAX_CHANGE_DEG = 30.0
#: Candidate spins span this range, degrees.
SPIN_RANGE_DEG = (-180.0, 180.0)


#: Segments each feed move is cut into for the choice (rapids: one).
SEGMENTS_PER_MOVE = 4


@dataclass(frozen=True)
class SpinPlan:
    """The spin along the program, piecewise linear between knots.

    Attributes
    ----------
    offset : ndarray of int, shape (n,)
        Index of each move's first knot (its start); its last is ``offset + count``.
    count : ndarray of int, shape (n,)
        Segments of each move.
    knots : ndarray, shape (K,), rad
        Spin at the knots (program order; a move's end is the next one's start).
    points : ndarray, shape (K, 3), mm
        The knots (program frame).
    deflection : ndarray, shape (K,), mm
        |delta| at the knots with the chosen spins.
    fixed : ndarray, shape (K,), mm
        |delta| at the knots with spin 0 (the tool orientation given).
    """

    offset: np.ndarray
    count: np.ndarray
    knots: np.ndarray
    points: np.ndarray
    deflection: np.ndarray
    fixed: np.ndarray

    def spin_of(self, m, s) -> np.ndarray:
        """Spin (rad) at parameters ``s`` of moves ``m``: linear between the move's knots."""
        m = np.asarray(m, dtype=np.intp)
        x = np.asarray(s, dtype=float) * self.count[m]
        j = np.minimum(np.floor(x).astype(np.intp), self.count[m] - 1)
        k = self.offset[m] + j
        return self.knots[k] + (x - j) * (self.knots[k + 1] - self.knots[k])


def _knots(path: Toolpath, forces: ForceSpec):
    """Knots along the program: (move, s) in order, each move's segments, the force at each knot
    (at a move's end: the larger of the two moves' forces there)."""
    n = len(path)
    count = np.where(path.feed, SEGMENTS_PER_MOVE, 1).astype(np.intp)
    offset = np.concatenate([[0], np.cumsum(count)[:-1]])
    m = np.concatenate([[0], np.repeat(np.arange(n), count)])
    j = np.concatenate([[0], np.concatenate([np.arange(1, c + 1) for c in count])])
    s = j / np.concatenate([[1], np.repeat(count, count)])
    F = force_at(path, forces, m, s)
    starts = offset  # knot index of each move's start
    Fs = force_at(path, forces, np.arange(n), np.zeros(n))
    take = np.linalg.norm(Fs, axis=1) > np.linalg.norm(F[starts], axis=1)
    F[starts[take]] = Fs[take]
    return offset, count, path.point(m, s), F


def choose_spin(fld: ArmField, path: Toolpath, forces: ForceSpec) -> SpinPlan:
    """The spins that deflect least, smoothly (module docstring).

    Raises
    ------
    InputError
        When no smooth choice keeps every knot reachable.
    """
    offset, count, P, F = _knots(path, forces)
    K = P.shape[0]
    cand = np.radians(np.arange(SPIN_RANGE_DEG[0], SPIN_RANGE_DEG[1], SPIN_STEP_DEG))
    cost = np.full((cand.size, K), np.inf)
    mag = np.full((cand.size, K), np.nan)
    for j, psi in enumerate(cand):
        res = fld(P, F, None, np.full(K, psi))
        ok = res.valid & (np.nan_to_num(res.conditioning, nan=0.0) >= 0.05)
        d = np.linalg.norm(res.delta, axis=1)
        mag[j, ok] = d[ok]
        cost[j, ok] = d[ok] ** 4
    pick = _dynamic_programme(cost, cand)
    if pick is None:
        raise InputError(
            "--free-tool-spin: no smooth choice of spins keeps every point of the program reachable"
        )
    zero = int(np.argmin(np.abs(cand)))
    return SpinPlan(offset, count, cand[pick], P, mag[pick, np.arange(K)], mag[zero])


def _dynamic_programme(cost: np.ndarray, cand: np.ndarray) -> np.ndarray | None:
    """Indices of candidates per knot minimising the summed cost, |change| <= MAX_CHANGE_DEG."""
    k, n = cost.shape
    diff = np.abs(cand[:, None] - cand[None, :])  # no wrap: the last joint would wind up
    allowed = diff <= math.radians(MAX_CHANGE_DEG) + 1e-12
    acc = cost[:, 0].copy()
    back = np.zeros((k, n), dtype=np.intp)
    for i in range(1, n):
        tot = np.where(allowed, acc[None, :], np.inf)  # [to, from]
        back[:, i] = np.argmin(tot, axis=1)
        acc = tot[np.arange(k), back[:, i]] + cost[:, i]
    if not np.any(np.isfinite(acc)):
        return None
    pick = np.zeros(n, dtype=np.intp)
    pick[-1] = int(np.argmin(acc))
    for i in range(n - 1, 0, -1):
        pick[i - 1] = back[pick[i], i]
    return pick
