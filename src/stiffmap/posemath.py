"""Pose maths of a board seen by a camera: the pose, its perturbation, its projection and Jacobian.

Every estimator of a board's pose in ``stiffmap.vision`` (corners, photometric refinement)
and the renderer of ``stiffmap.sim`` agree on what follows (``docs/conventions.md``, "Pose
uncertainty"):

- a board's pose is ``board2cam``, a rigid transform (checked by
  :func:`~stiffmap.geometry.as_transform`, see :func:`check_pose`), seen from the front
  when its z axis points away from the camera (:func:`faces_camera`);
- a small change of pose is (dt, dr): t <- t + dt, R <- Exp(dr) R, both in the camera
  frame (:func:`perturb_pose`, with the one exponential,
  :func:`~stiffmap.geometry.matrix_from_rotvec`); covariances of poses are over (t, r);
- the projection of board points and its Jacobian with respect to (dt, dr)
  (:func:`projection_jacobian`), and the homography from rays to the board plane
  (:func:`ray2board_homography`);
- a measured pose with its covariance and quality is a :class:`BoardPose` (a
  :class:`PoseEstimate` whose pose is ``board2cam``; a rig's fused pose, in the rig frame, is
  :class:`~stiffmap.vision.fuse.FusedPose` with ``board2rig``); the share of the
  camera calibration in it comes from :func:`calibration_sensitivity` (how the fitted pose
  follows an error of the camera's parameters).

Why a module of its own, in the bottom layer beside ``geometry`` and ``camera``: a
board's pose is a rigid transform (``geometry``) and its projection goes through the
lens model (``camera``), so it needs both and belongs to neither; and both ``vision``
(detection, corner poses, photometric refinement, calibration) and ``sim`` use it, so it
cannot live in either. It is pure NumPy: OpenCV stays in ``vision`` and ``sim``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .camera import CameraModel
from .geometry import as_transform, matrix_from_rotvec

__all__ = [
    "PoseEstimate",
    "BoardPose",
    "calibration_sensitivity",
    "check_pose",
    "faces_camera",
    "perturb_pose",
    "point_jacobian",
    "projection_jacobian",
    "ray2board_homography",
    "skew",
]


@dataclass(frozen=True)
class PoseEstimate(ABC):
    """A board's measured pose: its covariance and the fit's quality. The pose itself is a
    field of the subclass, named by its frame: :attr:`BoardPose.board2cam` (a camera's) or
    :attr:`FusedPose.board2rig <stiffmap.vision.fuse.FusedPose>` (a rig's, fused from its
    cameras'); :attr:`board2frame` is either, for code that takes both.

    Attributes
    ----------
    cov : ndarray, shape (6, 6)
        Covariance over (t (mm), r (rad)), the perturbation of :func:`perturb_pose`: the
        total, the fit's own noise plus :attr:`cov_calibration`.
    rms_px : float
        Reprojection RMS over the corners, px (sqrt of the mean of ex^2 + ey^2).
    n_corners : int
    residuals_px : ndarray, shape (n_corners, 2)
        Observed minus projected corner positions, px.
    sigma_px : float
        Estimated corner noise per axis, sqrt(sum e^2 / (2 n - 6)), px.
    condition : float
        Condition number of J^T J with t in mm and r in rad scaled by the
        distance (large: a poorly determined pose, e.g. a tiny board).
    iterations : int
        Gauss-Newton iterations.
    method : str
        ``"corners"`` (reprojection of the detected corners) or ``"photometric"``
        (:func:`~stiffmap.vision.photometric.refine_pose_photometric`: a model of the
        blurred board fitted to its pixels; ``cov`` and ``condition`` are then the
        photometric fit's, ``rms_px``, ``residuals_px`` and ``sigma_px`` the corners'
        reprojection errors at that pose).
    photometric : PhotometricFit or None
        Quality of the photometric fit (residual RMS in DN, pixels used, blur...).
    fallback : str or None
        Why a photometric refinement that was asked for was not used (the pose is
        then the corner-based one).
    calibration_jacobian : ndarray, shape (6, n) or None
        A = d(t, r) / d(camera parameters) (:func:`calibration_sensitivity`, the order of
        :attr:`~stiffmap.camera.CameraModel.param_names`): how the pose follows an error of
        the calibration. The error is common to every pose taken with the camera:
        propagate it through A, never as independent noise.
    cov_calibration : ndarray, shape (6, 6) or None
        The calibration's share of ``cov``, A cov_c A^T; None when the camera's
        uncertainty is unknown (no ``cov`` or ``std`` in its ``camera.json``).
    """

    cov: np.ndarray
    rms_px: float
    n_corners: int
    residuals_px: np.ndarray
    sigma_px: float
    condition: float
    iterations: int
    method: str = "corners"
    photometric: Any = None
    fallback: str | None = None
    calibration_jacobian: np.ndarray | None = None
    cov_calibration: np.ndarray | None = None

    @property
    def cov_noise(self) -> np.ndarray:
        """The fit's own share of ``cov`` (independent from image to image), 6x6."""
        return self.cov if self.cov_calibration is None else self.cov - self.cov_calibration

    @property
    def t_std_calibration_mm(self) -> np.ndarray:
        """1-sigma of the translation due to the calibration alone, shape (3,), mm (NaN: unknown)."""
        if self.cov_calibration is None:
            return np.full(3, np.nan)
        return np.sqrt(np.maximum(np.diag(self.cov_calibration)[:3], 0.0))

    @property
    def t_std_mm(self) -> np.ndarray:
        """1-sigma of the translation, shape (3,), mm."""
        return np.sqrt(np.diag(self.cov)[:3])

    @property
    def r_std_rad(self) -> np.ndarray:
        """1-sigma of the rotation vector, shape (3,), rad."""
        return np.sqrt(np.diag(self.cov)[3:])

    @property
    @abstractmethod
    def board2frame(self) -> np.ndarray:
        """The pose, mm, in the frame of what measured it: a camera's (``board2cam``) or a
        rig's (``board2rig``); the covariances are over the (t, r) perturbation in that frame."""


@dataclass(frozen=True)
class BoardPose(PoseEstimate):
    """Pose of a board in the camera frame, with its covariance and quality (:class:`PoseEstimate`).

    Attributes
    ----------
    board2cam : ndarray, shape (4, 4), mm
        The pose (a keyword argument).
    """

    board2cam: np.ndarray = field(kw_only=True)

    @property
    def board2frame(self) -> np.ndarray:
        return self.board2cam


def check_pose(a2b, name: str = "board2cam") -> np.ndarray:
    """One rigid transform, checked by :func:`~stiffmap.geometry.as_transform`, as a new array.

    Parameters
    ----------
    a2b : array_like, shape (4, 4), mm
    name : str
        Used in error messages.

    Returns
    -------
    ndarray, shape (4, 4), float64 (a copy)

    Raises
    ------
    ValueError
        Not a single (4, 4) rigid transform (shape, finiteness, last row, rotation block).
    """
    T = as_transform(a2b, name)
    if T.shape != (4, 4):
        raise ValueError(f"{name} must be one (4, 4) transform, got shape {T.shape}")
    return np.array(T)


def faces_camera(board2cam: np.ndarray) -> bool:
    """True when the camera sees the board's front: its z axis (into the board) points away."""
    T = np.asarray(board2cam, dtype=np.float64)
    return float(T[:3, 2] @ T[:3, 3]) > 0


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [v]x of vectors (..., 3) -> (..., 3, 3): [v]x w = v x w."""
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1] = -v[..., 2]
    S[..., 0, 2] = v[..., 1]
    S[..., 1, 0] = v[..., 2]
    S[..., 1, 2] = -v[..., 0]
    S[..., 2, 0] = -v[..., 1]
    S[..., 2, 1] = v[..., 0]
    return S


def point_jacobian(T: np.ndarray, point) -> np.ndarray:
    """How a point moved by a pose follows the pose's (t, r) left perturbation.

    For p = R q + t (``T`` = (R, t), ``point`` q in T's source frame, mm), returns
    d(p, r) / d(t, r) = [[I, -[R q]x], [0, I]], shape (6, 6): the translation of the point (mm)
    and the rotation (rad), both in T's target frame (:func:`perturb_pose`).
    """
    A = np.eye(6)
    A[:3, 3:] = -skew(np.asarray(T, dtype=np.float64)[:3, :3] @ np.asarray(point, dtype=np.float64))
    return A


def perturb_pose(board2cam: np.ndarray, delta) -> np.ndarray:
    """The pose moved by a small (dt, dr): t <- t + dt, R <- Exp(dr) R (camera frame).

    Parameters
    ----------
    board2cam : ndarray, shape (4, 4), mm
    delta : array_like, shape (>= 6,)
        (dt (3, mm), dr (3, rad)); further entries (other parameters of a fit) are ignored.

    Returns
    -------
    ndarray, shape (4, 4)
        A new array.
    """
    T = board2cam
    Tn = T.copy()
    Tn[:3, 3] = T[:3, 3] + delta[:3]
    Tn[:3, :3] = matrix_from_rotvec(delta[3:6]) @ T[:3, :3]
    return Tn


def ray2board_homography(board2cam: np.ndarray) -> np.ndarray:
    """H^-1 for the board plane's homography H = [r1, r2, t] of ``board2cam`` = [R | t].

    A ray (x/z, y/z, 1) meets the board plane at (X, Y, 1) ~ H^-1 (x/z, y/z, 1) (mm).
    The inverse of the columns (a, b, c) = (r1, r2, t) as the rows (b x c, c x a, a x b) over
    a . (b x c) = r3 . t, the board plane's distance from the camera's centre, on floats (the
    photometric model takes one per evaluation).

    Parameters
    ----------
    board2cam : array_like, shape (4, 4), mm

    Returns
    -------
    ndarray, shape (3, 3)

    Raises
    ------
    ValueError
        The board's plane passes through the camera's centre (seen edge-on).
    """
    (a0, b0, _, c0), (a1, b1, _, c1), (a2, b2, _, c2) = np.asarray(board2cam, dtype=np.float64)[:3].tolist()
    bc = (b1 * c2 - b2 * c1, b2 * c0 - b0 * c2, b0 * c1 - b1 * c0)
    ca = (c1 * a2 - c2 * a1, c2 * a0 - c0 * a2, c0 * a1 - c1 * a0)
    ab = (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
    det = a0 * bc[0] + a1 * bc[1] + a2 * bc[2]
    if det == 0.0 or not math.isfinite(det):
        raise ValueError("the board's plane passes through the camera's centre (the board is seen edge-on)")
    return np.array([bc, ca, ab]) * (1.0 / det)


def projection_jacobian(
    board2cam, object_points, camera: CameraModel, *, validate: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Projected pixels of board points and their Jacobian with respect to the pose.

    A board point q moves by dX = dt - [R q]x dr in the camera frame, and its pixel by
    J = diag(fx, fy) D(x) P(X) [I, -[R q]x], with P the Jacobian of the perspective
    division and D that of the lens distortion at the point.

    Parameters
    ----------
    board2cam : array_like, shape (4, 4), mm
    object_points : array_like, shape (m, 3), mm
        Points in the board frame.
    camera : CameraModel
    validate : bool
        Check ``board2cam`` (:func:`check_pose`). A fit that builds its poses by
        :func:`perturb_pose` from a checked one skips it in its iterations.

    Returns
    -------
    uv : ndarray, shape (m, 2), px
    J : ndarray, shape (m, 2, 6)
        d(u, v) / d(t, r) with the perturbation t <- t + dt, R <- Exp(dr) R
        (camera frame; ``docs/conventions.md``).
    """
    T = check_pose(board2cam) if validate else np.asarray(board2cam, dtype=np.float64)
    q = np.asarray(object_points, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(f"expected object_points (m, 3), got {q.shape}")
    Rq = q @ T[:3, :3].T
    X = Rq + T[:3, 3]
    Z = X[:, 2]
    if np.any(Z <= 0):
        raise ValueError("board points behind the camera")
    xy = X[:, :2] / Z[:, None]
    xd, Jd = camera.distort_with_jacobian(xy)
    f = np.array([camera.fx, camera.fy])
    uv = xd * f + [camera.cx, camera.cy]
    P = np.zeros((len(q), 2, 3))
    P[:, 0, 0] = 1 / Z
    P[:, 1, 1] = 1 / Z
    P[:, 0, 2] = -X[:, 0] / Z**2
    P[:, 1, 2] = -X[:, 1] / Z**2
    dX = np.concatenate([np.broadcast_to(np.eye(3), (len(q), 3, 3)), -skew(Rq)], axis=2)  # (m, 3, 6)
    J = f[None, :, None] * (Jd @ P @ dX)
    return uv, J


def calibration_sensitivity(
    board2cam, object_points, camera: CameraModel, weights=None, tangents=None
) -> np.ndarray:
    """How a pose fitted to board points follows an error of the camera's parameters.

    The pose minimises sum w e^2 with e the reprojection error of the points; by implicit
    differentiation of its optimality condition (first order, residuals neglected),
    A = d(t, r) / dc = -(J_p^T W J_p)^-1 J_p^T W J_c, with J_p the projection Jacobian of
    the pose (:func:`projection_jacobian`) and J_c that of the camera's parameters c
    (:meth:`~stiffmap.camera.CameraModel.projection_param_jacobian`, points held fixed in
    the camera frame).

    Parameters
    ----------
    board2cam : array_like, shape (4, 4), mm
    object_points : array_like, shape (m, 3), mm
        The fitted points, board frame.
    camera : CameraModel
    weights : array_like, shape (m,), optional
        Per-point weights (default equal).
    tangents : array_like, shape (m, 3), optional
        For points on edges (a photometric fit): the edge's direction in the board frame. Only
        the residual across the edge's image counts then (an edge pins nothing along itself).

    Returns
    -------
    ndarray, shape (6, n)
        Rows (t (mm), r (rad)) as in :func:`perturb_pose`; columns
        :attr:`~stiffmap.camera.CameraModel.param_names`.
    """
    T = check_pose(board2cam)
    q = np.asarray(object_points, dtype=np.float64)
    _, Jp = projection_jacobian(T, q, camera, validate=False)
    X = q @ T[:3, :3].T + T[:3, 3]
    Jc = camera.projection_param_jacobian(X[:, :2] / X[:, 2:3])
    w = np.ones(len(q)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if tangents is not None:
        # The edge's image direction (d uv / d q along it = the translation columns of J_p on
        # R tangent) and its normal; residuals projected on the normal.
        tg = np.asarray(tangents, dtype=np.float64) @ T[:3, :3].T
        ti = np.einsum("mij,mj->mi", Jp[:, :, :3], tg)
        ti /= np.linalg.norm(ti, axis=1, keepdims=True)
        nrm = np.stack([-ti[:, 1], ti[:, 0]], axis=1)
        Jp = np.einsum("mi,mij->mj", nrm, Jp)[:, None, :]
        Jc = np.einsum("mi,mij->mj", nrm, Jc)[:, None, :]
    Jp2 = (Jp * w[:, None, None]).reshape(-1, 6)
    N = Jp2.T @ Jp.reshape(-1, 6)
    return -np.linalg.solve(N, Jp2.T @ Jc.reshape(-1, Jc.shape[-1]))
