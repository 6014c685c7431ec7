"""A platform that turns in a campaign's report: the model's maps at the campaign's orientation,
and over orientations at one position, measured beside modelled.

A campaign of a ``dim = 6`` robot (a hexapod, a 3-RPS) holds its platform at the orientations
of ``positions.poses`` (or level). The report's dense map over the measured planes is drawn
with the platform at the orientation every position shares (level when they do not share one:
:func:`shared_orientation`); :func:`orientation_map` gives the model over a roll-pitch grid at
one position (where the campaign measured the most orientations), the smallest principal
stiffness of the K the campaign identifies (the forces hung at ``loads.point_mm``) and of
K_rot (a pure moment's), with the orientations measured there and their identified K.
"""

from __future__ import annotations

import numpy as np

from ..campaign.platform import platform_map
from ..campaign.positions import campaign_poses
from ..campaign.spec import CampaignSpec
from ..models.poses import poses_from
from . import data as contract

__all__ = ["shared_orientation", "map_poses", "orientation_map", "ORIENTATION_GRID"]

#: The roll-pitch grid of :func:`orientation_map`: this many angles per axis, over the campaign's
#: span of roll and pitch widened to at least +-ORIENTATION_SPAN_DEG.
ORIENTATION_GRID = 15
ORIENTATION_SPAN_DEG = 10.0


def shared_orientation(spec: CampaignSpec) -> np.ndarray:
    """The roll, pitch, yaw (degrees) every position of ``positions.poses`` shares; 0 (level)
    when they do not share one or are given without orientations."""
    deg = None if spec.positions is None else spec.positions.orientations_deg()
    if deg is None or not np.all(deg == deg[0]):
        return np.zeros(3)
    return deg[0].copy()


def map_poses(spec: CampaignSpec, points) -> np.ndarray:
    """Poses (n, 6; rad) of a dense map's points (n, 3) mm at :func:`shared_orientation`."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.c_[P, np.tile(np.radians(shared_orientation(spec)), (P.shape[0], 1))]


def _centre(poses: np.ndarray) -> int:
    """The row whose position holds the most distinct orientations (the first of a tie)."""
    keys = [tuple(np.round(p[:3], 6)) for p in poses]
    counts = [
        len({tuple(np.round(q[3:], 9)) for k, q in zip(keys, poses, strict=True) if k == c}) for c in keys
    ]
    return int(np.argmax(counts))


def orientation_map(
    model, spec: CampaignSpec, positions, numbers, measured_min_principal
) -> contract.OrientationMap:
    """The model over roll and pitch at one of the campaign's positions, measured beside it.

    Parameters
    ----------
    model : Mechanism
        With ``dim = 6``.
    spec : CampaignSpec
    positions : array_like, shape (n, 3), mm
        The measured positions (the store's rows).
    numbers : sequence of int
        Their 1-based numbers in campaign.toml.
    measured_min_principal : array_like, shape (n,), N/mm
        Their identified K's smallest principal stiffness (NaN: failed).
    """
    poses = campaign_poses(spec, positions, numbers)
    i = _centre(poses)
    at = np.all(np.abs(poses[:, :3] - poses[i, :3]) < 1e-6, axis=1)
    deg = np.degrees(poses[at, 3:])
    span = [max(ORIENTATION_SPAN_DEG, float(np.max(np.abs(deg[:, j])))) for j in (0, 1)]
    roll = np.linspace(-span[0], span[0], ORIENTATION_GRID)
    pitch = np.linspace(-span[1], span[1], ORIENTATION_GRID)
    yaw = float(np.median(deg[:, 2]))
    R, P = np.meshgrid(roll, pitch)  # row j: pitch j
    grid = np.radians(np.c_[R.ravel(), P.ravel(), np.full(R.size, yaw)])
    lever = spec.loads.point_mm or (0.0, 0.0, 0.0)
    mm = platform_map(model, poses_from(poses[i, :3], grid), lever)
    shape = (pitch.size, roll.size)
    rot = np.where(mm.valid, mm.min_principal_rot, np.nan)
    return contract.OrientationMap(
        position=poses[i, :3],
        yaw_deg=yaw,
        roll_deg=roll,
        pitch_deg=pitch,
        min_principal=np.where(mm.valid, mm.min_principal, np.nan).reshape(shape),
        min_principal_rot=rot.reshape(shape),
        measured_rpy_deg=deg,
        measured_min_principal=np.asarray(measured_min_principal, dtype=np.float64)[at],
    )
