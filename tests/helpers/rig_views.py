"""Rigs of two cameras rendered by the test-bed with known truth, for the rig calibration tests.

Two kinds, both 640x480 cameras with a 9x6 board of 30 mm squares (the public stereo sets'
format, e.g. the OpenCV / Bouguet left/right samples):

- ``"60deg"``: the test-bed's default rig (:func:`stiffmap.sim.scene.two_camera_rig`),
  two cameras 60 degrees apart looking at a point 650 mm away;
- ``"100mm"``: two similar cameras about 100 mm apart, nearly parallel, as the Matlab
  toolbox's stereo example (om = [0.0061, 0.0041, -0.0036] rad, T = [-99.85, 0.82, 0.44] mm).

:func:`rendered_rig` renders the views of :func:`stiffmap.sim.calibration_views.rig_calibration_views`
through each camera and finds the board in every image (cached per process: a rig of 15
views is about 4 s). :func:`noisy_detections` gives exact corners plus Gaussian noise
instead (no rendering), for statistics over many draws.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from stiffmap.camera import CameraModel
from stiffmap.errors import InputError
from stiffmap.geometry import invert_transform, matrix_from_rotvec, transform_from
from stiffmap.rig import Rig, RigCamera
from stiffmap.sim.calibration_views import RigView, render_rig_view, rig_calibration_views
from stiffmap.sim.scene import two_camera_rig
from stiffmap.targets import Chessboard
from stiffmap.vision import BoardDetection, detect_board

BOARD = Chessboard(9, 6, 30.0)
#: Margin printed around the squares, mm.
MARGIN_MM = 20.0
LEFT = CameraModel((640, 480), 533.0, 533.2, 341.6, 234.3, (-0.289, 0.103, 0.001, -0.0003, 0.0))
RIGHT = CameraModel((640, 480), 537.0, 536.6, 326.5, 249.3, (-0.289, 0.107, -0.0008, 0.0002, 0.0))
#: The Matlab toolbox's stereo example: right camera wrt left (X_right = R(om) X_left + T).
OM_100MM = np.array([0.0061, 0.0041, -0.0036])
T_100MM = np.array([-99.85, 0.82, 0.44])


def true_rig(kind: str) -> Rig:
    if kind == "60deg":
        return two_camera_rig(LEFT, 650.0, 60.0, right_camera=RIGHT)
    if kind == "100mm":
        rig2right = transform_from(matrix_from_rotvec(OM_100MM), T_100MM)
        return Rig(
            (RigCamera("left", LEFT, np.eye(4)), RigCamera("right", RIGHT, invert_transform(rig2right)))
        )
    raise ValueError(kind)


@dataclass(frozen=True)
class RenderedRig:
    """A rig's calibration views rendered and searched: ``images[k][v]``, ``detections[k][v]``."""

    rig: Rig
    views: tuple[RigView, ...]
    images: tuple[tuple[np.ndarray | None, ...], ...]
    detections: tuple[tuple[BoardDetection | str | None, ...], ...]

    @property
    def sizes(self) -> list[tuple[int, int]]:
        return [c.camera.image_size for c in self.rig.cameras]


@functools.cache
def rig_views(kind: str, seed: int, n_views: int = 15) -> tuple[RigView, ...]:
    return tuple(
        rig_calibration_views(
            true_rig(kind), n_views, board=BOARD, margin_mm=MARGIN_MM, rng=np.random.default_rng(seed)
        )
    )


@functools.cache
def rendered_rig(kind: str, seed: int, n_views: int = 15) -> RenderedRig:
    rig = true_rig(kind)
    views = rig_views(kind, seed, n_views)
    images = [[None] * len(views) for _ in rig.cameras]
    dets: list[list] = [[None] * len(views) for _ in rig.cameras]
    for i, v in enumerate(views):
        for k, r in enumerate(render_rig_view(rig, v, board=BOARD, margin_mm=MARGIN_MM, seed=seed)):
            if r is None:
                continue
            images[k][i] = r.image
            try:
                dets[k][i] = detect_board(r.image, BOARD)
            except InputError as e:
                dets[k][i] = e.detail
    return RenderedRig(rig, views, tuple(map(tuple, images)), tuple(map(tuple, dets)))


def noisy_detections(rig: Rig, views, sigma_px: float, rng: np.random.Generator, board=BOARD) -> list[list]:
    """Exact corners of every view in every camera that takes it, plus Gaussian noise (px per axis)."""
    q = board.object_points()
    out: list[list] = [[None] * len(views) for _ in rig.cameras]
    for i, v in enumerate(views):
        for k in v.cameras:
            T = v.board2cam(rig, k)
            uv = rig.cameras[k].camera.project(q @ T[:3, :3].T + T[:3, 3])
            uv = uv + sigma_px * rng.standard_normal(uv.shape)
            out[k][i] = BoardDetection(board, uv, np.arange(len(q)), np.zeros(len(q)))
    return out
