"""Two cameras looking at a board from about 60 degrees apart, with exact ground truth.

The rig of the fused-pose tests and of ``benchmarks/bench_vision_rig.py`` (the test-bed's own
rig arrives with ``sim.scene``): camera 1 is the rig frame, looking along its z axis at a
point ``distance_mm`` away; camera 2 looks at the same point from ``angle_deg`` about the rig's
y axis, to the right (+x), at the same distance. The board faces the bisector of the two
lines of sight, so each camera sees it tilted by about half the angle.
"""

from __future__ import annotations

import numpy as np

from helpers.board_scenes import look_at_pose
from stiffmap.camera import CameraModel
from stiffmap.geometry import matrix_from_rotvec
from stiffmap.rig import Rig, RigCamera
from stiffmap.targets import Chessboard


def _ry(angle_deg: float) -> np.ndarray:
    return matrix_from_rotvec([0.0, np.radians(angle_deg), 0.0])


def _looking_at(point: np.ndarray, distance_mm: float, angle_deg: float) -> np.ndarray:
    """A camera pose in the rig frame: turned by -angle about y, its axis through ``point``."""
    T = np.eye(4)
    T[:3, :3] = _ry(-angle_deg)
    T[:3, 3] = point - distance_mm * T[:3, 2]
    return T


def stereo_rig(
    camera: CameraModel,
    *,
    distance_mm: float = 650.0,
    angle_deg: float = 60.0,
    names: tuple[str, str] = ("left", "right"),
    camera2: CameraModel | None = None,
) -> Rig:
    """Two cameras (``camera`` and ``camera2``, default the same) whose lines of sight meet
    ``distance_mm`` in front of the first one, ``angle_deg`` apart (the second to the right).

    The rig carries no covariance: its cameras' own (none for a camera without ``cov``/``std``)
    and exact ``cam2rig``.
    """
    point = np.array([0.0, 0.0, distance_mm])
    c2 = _looking_at(point, distance_mm, angle_deg)
    return Rig((RigCamera(names[0], camera, np.eye(4)), RigCamera(names[1], camera2 or camera, c2)))


def board_in_rig(
    board: Chessboard,
    *,
    distance_mm: float = 650.0,
    angle_deg: float = 60.0,
    tilt_deg=(0.0, 0.0, 0.0),
    offset_mm=(0.0, 0.0),
) -> np.ndarray:
    """``board2rig``: the board's centre near the point both cameras look at, facing the bisector.

    ``tilt_deg`` and ``offset_mm`` as in :func:`helpers.board_scenes.look_at_pose`, in the frame
    of a virtual camera on the bisector.
    """
    point = np.array([0.0, 0.0, distance_mm])
    mid = _looking_at(point, distance_mm, angle_deg / 2)
    return mid @ look_at_pose(distance_mm, board, tilt_deg=tilt_deg, offset_mm=offset_mm)


def board2cams(rig: Rig, board2rig: np.ndarray) -> list[np.ndarray]:
    """The board's pose in each camera's frame, inv(cam2rig_k) . board2rig."""
    return [np.linalg.inv(c.cam2rig) @ board2rig for c in rig.cameras]


def rig_camera() -> CameraModel:
    """A 1280x960 camera with some barrel distortion (fx 2600 px: a 650 mm scene at test speed)."""
    return CameraModel((1280, 960), 2600.0, 2602.0, 641.5, 478.0, (-0.08, 0.06, 0.0003, -0.0002, 0.0))
