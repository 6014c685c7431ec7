"""A simulated campaign measured from its exported true corners, without images.

Each image's board poses come from OpenCV's solvePnP on the true corners (plus noise, if
asked); the campaign runner's own derivation turns them into displacements and K per
position, to compare with ``truth.json`` (the test-bed's round trip, tests and benchmark).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from stiffmap.camera import CameraModel
from stiffmap.campaign.derive import derive_position
from stiffmap.campaign.measure import ImageRow
from stiffmap.campaign.positions import plan
from stiffmap.campaign.records import StiffnessRecord
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import record_of
from stiffmap.campaign.truth import load_truth
from stiffmap.geometry import matrix_from_rotvec, transform_from
from stiffmap.targets import Chessboard


def pnp_pose(obj: np.ndarray, uv: np.ndarray, camera: CameraModel) -> np.ndarray:
    """board2cam from corners by OpenCV's solvePnP, refined by Levenberg-Marquardt."""
    ok, rvec, tvec = cv2.solvePnP(obj, uv, camera.matrix, camera.dist_array)
    assert ok
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
    rvec, tvec = cv2.solvePnPRefineLM(obj, uv, camera.matrix, camera.dist_array, rvec, tvec, crit)
    return transform_from(matrix_from_rotvec(rvec.ravel()), tvec.ravel())


def pnp_image_row(name: str, uv_mobile: np.ndarray, uv_fixed: np.ndarray, mobile_board, fixed_board, camera):
    """The campaign runner's ``ImageRow`` of one image, both board poses by :func:`pnp_pose`.

    Parameters
    ----------
    uv_mobile, uv_fixed : ndarray, shape (n, 2), px
        Corners of the mobile and fixed boards, in the boards' canonical order.
    mobile_board, fixed_board : Chessboard
    camera : CameraModel
    """
    return ImageRow(
        name,
        True,
        mobile2cam=pnp_pose(mobile_board.object_points(), uv_mobile, camera),
        mobile_cov=np.zeros((6, 6)),  # not used by the identification
        fixed2cam=pnp_pose(fixed_board.object_points(), uv_fixed, camera),
        fixed_cov=np.zeros((6, 6)),
    )


def derive_from_true_corners(root, noise_px: float = 0.0, seed: int = 0):
    """Measure a simulated campaign from its exported corners: the runner's derivation per position.

    Each image's board poses come from solvePnP on the true corners (plus Gaussian
    noise of ``noise_px``, px); displacements and K come from the campaign runner's own
    derivation (``stiffmap.campaign.derive.derive_position``: cam2base from the mean
    fixed-board pose of the position, displacement of ``point_mm`` in the base frame,
    the compliance estimator).

    Returns
    -------
    truth : the campaign's ``truth.json`` (``stiffmap.campaign.truth.load_truth``)
    loads : list of LoadCase (N, base frame)
    derived : list of (PositionTask, derivation result) per position
    """
    spec = load_spec(root)
    truth = load_truth(root)
    cam = truth.camera
    fb = Chessboard.parse(spec.targets.fixed.board, spec.targets.fixed.square_mm)
    mb = Chessboard.parse(spec.targets.mobile.board, spec.targets.mobile.square_mm)
    rng = np.random.default_rng(seed)
    rows = {}
    for f, c in truth.corners().items():
        uv_m = c["mobile"]["corners_px"] + rng.normal(scale=noise_px, size=c["mobile"]["corners_px"].shape)
        uv_f = c["fixed"]["corners_px"] + rng.normal(scale=noise_px, size=c["fixed"]["corners_px"].shape)
        rows[f] = pnp_image_row(f, uv_m, uv_f, mb, fb, cam)
    loads = spec.loads.resolve(spec.g)
    derived = []
    for task in plan(spec, root):
        task = dataclasses.replace(task, missing=())  # the images need not exist for this path
        derived.append((task, derive_position(task, rows, loads, spec, "compliance", "", "")))
    return truth, loads, derived


def round_trip_from_true_corners(root, noise_px: float = 0.0, seed: int = 0):
    """K per position from the exported corners (:func:`derive_from_true_corners`).

    Returns
    -------
    list of (K, K_std, K_true) per position, N/mm.
    """
    truth, _, derived = derive_from_true_corners(root, noise_px, seed)
    out = []
    for task, res in derived:
        assert res.stiffness["status"] == "ok", res.problems
        out.append(
            (
                record_of(StiffnessRecord, res.stiffness).K,
                record_of(StiffnessRecord, res.stiffness).K_std,
                truth.K[task.index - 1],
            )
        )
    return out
