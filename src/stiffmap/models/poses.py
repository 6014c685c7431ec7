"""Poses of a platform that turns (``dim = 6``): orientations given as text, grids of poses.

A pose is x, y, z (mm) and roll, pitch, yaw (rad inside stiffmap, degrees at the boundary;
R = Rz(yaw) Ry(pitch) Rx(roll), URDF's convention). A machining user maps a robot's
stiffness over positions at one orientation of the tool, and over orientations (the tool
tilted) at one position: :func:`orientations_from_text` reads ``R,P,Y`` where each angle is
a value or a range ``START:STOP:N`` (degrees), :func:`poses_from` joins positions and
orientations into poses.
"""

from __future__ import annotations

import math

import numpy as np

from .presets import MAX_GRID_POINTS

__all__ = ["MAX_ANGLE_DEG", "MAX_ORIENTATIONS", "MAX_POSES", "orientations_from_text", "poses_from"]

#: Largest roll, pitch or yaw a pose may hold, degrees.
MAX_ANGLE_DEG = 180.0
#: Most orientations a text may give.
MAX_ORIENTATIONS = 100_000
#: Most poses positions and orientations may join into (a grid's limit: a map of a million poses
#: of a hexapod takes hours).
MAX_POSES = MAX_GRID_POINTS

_NAMES = ("roll", "pitch", "yaw")


def _angle(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{what}: {text!r} is not a number of degrees") from None
    if not math.isfinite(v) or abs(v) > MAX_ANGLE_DEG:
        raise ValueError(f"{what}: {text} deg is not within +-{MAX_ANGLE_DEG:g} deg")
    return v


def _axis(text: str, name: str) -> np.ndarray:
    """One angle's values (degrees): ``V`` or ``START:STOP:N``."""
    parts = text.strip().split(":")
    if len(parts) == 1:
        return np.array([_angle(parts[0], name)])
    if len(parts) != 3:
        raise ValueError(f"{name}: {text!r} is neither a value nor START:STOP:N (degrees)")
    a, b = _angle(parts[0], f"{name} start"), _angle(parts[1], f"{name} stop")
    try:
        n = int(parts[2])
    except ValueError:
        raise ValueError(f"{name}: N = {parts[2]!r} is not a whole number") from None
    if not 1 <= n <= MAX_ORIENTATIONS:
        raise ValueError(f"{name}: N = {n} is not between 1 and {MAX_ORIENTATIONS}")
    return np.linspace(a, b, n)


def orientations_from_text(text: str) -> np.ndarray:
    """Orientations from ``R,P,Y`` (degrees), each a value or a range ``START:STOP:N``.

    Parameters
    ----------
    text : str
        E.g. ``0,0,0``, ``5,-3,10`` or ``-10:10:5,-10:10:5,0`` (a grid of 25 tilts).

    Returns
    -------
    ndarray, shape (M, 3), rad
        Roll, pitch, yaw; roll varying fastest, then pitch, then yaw.

    Raises
    ------
    ValueError
        Naming the angle and what is expected (three comma-separated angles within
        +-180 deg, at most :data:`MAX_ORIENTATIONS` orientations).
    """
    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(
            f"{text!r}: expected roll,pitch,yaw in degrees (three comma-separated values, each a value "
            "or START:STOP:N; e.g. 0,10,0 or -10:10:5,0,0)"
        )
    axes = [_axis(p, nm) for p, nm in zip(parts, _NAMES, strict=True)]
    count = math.prod(a.size for a in axes)
    if count > MAX_ORIENTATIONS:
        raise ValueError(f"{text!r} gives {count} orientations; at most {MAX_ORIENTATIONS}")
    yaw, pitch, roll = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.radians(np.stack([roll.ravel(), pitch.ravel(), yaw.ravel()], axis=1))


def poses_from(positions, orientations) -> np.ndarray:
    """Every position at every orientation.

    Parameters
    ----------
    positions : array_like, shape (N, 3), mm
    orientations : array_like, shape (M, 3), rad
        Roll, pitch, yaw.

    Returns
    -------
    ndarray, shape (M * N, 6)
        Poses, the positions varying fastest: row ``k N + i`` is position i at orientation k
        (a map over positions at each orientation in turn).

    Raises
    ------
    ValueError
        When they join into more than :data:`MAX_POSES` poses (the counts named).
    """
    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    A = np.asarray(orientations, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] * A.shape[0] > MAX_POSES:
        raise ValueError(
            f"gives {P.shape[0]} positions at {A.shape[0]} orientations, {P.shape[0] * A.shape[0]} poses; "
            f"at most {MAX_POSES}"
        )
    return np.concatenate([np.tile(P, (A.shape[0], 1)), np.repeat(A, P.shape[0], axis=0)], axis=1)
