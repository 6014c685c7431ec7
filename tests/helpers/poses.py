"""Poses written out for the tests, independent of stiffmap's code.

``rpy_matrix``: URDF's convention R = Rz(yaw) Ry(pitch) Rx(roll) (radians).
``rps_pose``: a pose a 3-RPS platform reaches (mm, radians).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), angles in rad, written out."""
    cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def rps_pose(z: float, roll: float, pitch: float, attach, axes) -> np.ndarray:
    """A pose (x, y, z mm, roll, pitch, yaw rad) the 3-RPS reaches at height ``z`` and that roll
    and pitch: x, y and yaw such that every platform joint (``attach``, platform frame, mm) lies
    in its leg's plane (normal ``axes``, base frame)."""

    def planes(v):
        R = rpy_matrix(roll, pitch, v[2])
        return [(np.array([v[0], v[1], z]) + R @ a) @ w for a, w in zip(attach, axes, strict=True)]

    sol = least_squares(planes, [0.0, 0.0, 0.0], xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.abs(sol.fun).max() < 1e-10
    return np.array([sol.x[0], sol.x[1], z, roll, pitch, sol.x[2]])
