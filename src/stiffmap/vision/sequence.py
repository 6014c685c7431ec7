"""Poses of the mobile (and fixed) target along a sequence of images of one robot position.

:class:`PoseTracker` measures image after image: the corners of the previous
image seed the next and are only refined (:func:`~stiffmap.vision.tracking.track_board`);
the full detection runs for the first image and whenever refinement fails its
consistency check. With a fixed target and its known pose on the robot base,
each image also gives ``mobile2base`` (reference paper, eq. 1) with its
covariance. An image that fails (unreadable, wrong size, board not found) gives
an :class:`ImageMeasurement` with ``error`` set, and the sequence goes on.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..camera import CameraModel, UndistortionError
from ..errors import InputError
from ..geometry import as_transform, invert_transform
from ..posemath import BoardPose, skew
from .board_plane import detection_mask
from .detect import Board, BoardDetection, detect_boards
from .images import check_image_size, read_image
from .pose import check_refine, estimate_pose

__all__ = ["ImageMeasurement", "PoseTracker", "measure_sequence", "mobile2base_from_poses"]


@dataclass(frozen=True)
class ImageMeasurement:
    """What one image gave.

    Attributes
    ----------
    image : str
        File name (or a label for arrays).
    mobile, fixed : BoardPose or None
        Poses of the mobile and fixed targets in the camera frame.
    mobile2base : ndarray, shape (4, 4) or None
        The mobile target in the robot base frame (fixed target and
        ``fixed2base`` given), mm.
    mobile2base_cov : ndarray, shape (6, 6) or None
        Its covariance (t, r in the base frame; fixed and mobile target noise, and the
        calibration's share propagated through both poses at once).
    mobile2base_calibration_jacobian : ndarray, shape (6, n) or None
        d(t, r of mobile2base) / d(camera parameters): the calibration's error moves the
        fixed and the mobile target's poses together.
    calibration_cov : ndarray, shape (n, n) or None
        The camera's calibration covariance (``CameraModel.calibration_cov``) the poses'
        ``cov_calibration`` were propagated from (None: unknown).
    mobile_detection, fixed_detection : BoardDetection or None
    timings : dict of str to float
        Seconds spent: ``read``, ``detect``, ``pose``, ``total``.
    error : str or None
        Why the image gave no measurement (then the poses are None).
    """

    image: str
    mobile: BoardPose | None = None
    fixed: BoardPose | None = None
    mobile2base: np.ndarray | None = None
    mobile2base_cov: np.ndarray | None = None
    mobile2base_calibration_jacobian: np.ndarray | None = None
    calibration_cov: np.ndarray | None = None
    mobile_detection: BoardDetection | None = None
    fixed_detection: BoardDetection | None = None
    timings: dict[str, float] = field(default_factory=dict)
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def mobile2cam(self) -> np.ndarray | None:
        return None if self.mobile is None else self.mobile.board2cam

    @property
    def mobile2cam_cov(self) -> np.ndarray | None:
        return None if self.mobile is None else self.mobile.cov

    @property
    def fixed2cam(self) -> np.ndarray | None:
        return None if self.fixed is None else self.fixed.board2cam

    @property
    def fixed2cam_cov(self) -> np.ndarray | None:
        return None if self.fixed is None else self.fixed.cov

    @property
    def cam2base(self) -> np.ndarray | None:
        """cam2base through this image's fixed target (None without one)."""
        if self.mobile2base is None or self.mobile is None:
            return None
        return self.mobile2base @ invert_transform(self.mobile.board2cam)

    @property
    def tracked(self) -> bool:
        """True when every target was tracked (no full detection)."""
        dets = [d for d in (self.mobile_detection, self.fixed_detection) if d is not None]
        return bool(dets) and all(d.tracked for d in dets)


def mobile2base_from_poses(mobile2cam, cov_mobile, fixed2cam, cov_fixed, fixed2base):
    """The mobile target in the base frame through the fixed target, with covariance.

    mobile2base = fixed2base . inv(fixed2cam) . mobile2cam (reference paper, eq. 1).
    With G = cam2base, b = R_G (t_fixed - t_mobile) and the (t, r) left
    perturbations of ``docs/conventions.md``:

        d t_mb = R_G d t_m - R_G d t_f - [b]x R_G d r_f
        d r_mb = R_G d r_m - R_G d r_f

    ``fixed2base`` is taken as exact.

    Parameters
    ----------
    mobile2cam, fixed2cam, fixed2base : array_like, shape (4, 4), mm
    cov_mobile, cov_fixed : array_like, shape (6, 6)

    Returns
    -------
    mobile2base : ndarray, shape (4, 4)
    cov : ndarray, shape (6, 6)
    """
    M = as_transform(mobile2cam, "mobile2cam")
    F = as_transform(fixed2cam, "fixed2cam")
    B = as_transform(fixed2base, "fixed2base")
    Cm = np.asarray(cov_mobile, dtype=np.float64)
    Cf = np.asarray(cov_fixed, dtype=np.float64)
    if Cm.shape != (6, 6) or Cf.shape != (6, 6):
        raise ValueError(f"covariances must be (6, 6), got {Cm.shape} and {Cf.shape}")
    G, Jm, Jf = _mobile2base_jacobians(M, F, B)
    cov = Jm @ Cm @ Jm.T + Jf @ Cf @ Jf.T
    return G @ M, 0.5 * (cov + cov.T)


def _mobile2base_jacobians(M: np.ndarray, F: np.ndarray, B: np.ndarray):
    """cam2base and d(mobile2base)/d(mobile2cam), d(mobile2base)/d(fixed2cam) (see above)."""
    G = B @ invert_transform(F)
    RG = G[:3, :3]
    b = RG @ (F[:3, 3] - M[:3, 3])
    Jm = np.zeros((6, 6))
    Jm[:3, :3] = RG
    Jm[3:, 3:] = RG
    Jf = np.zeros((6, 6))
    Jf[:3, :3] = -RG
    Jf[:3, 3:] = -skew(b) @ RG
    Jf[3:, 3:] = -RG
    return G, Jm, Jf


class PoseTracker:
    """Measure target poses image after image for one robot position.

    Parameters
    ----------
    camera : CameraModel
    mobile_board : Chessboard or CharucoBoard
        The target on the moving platform.
    fixed_board : Chessboard or CharucoBoard, optional
        The target on the robot base (a different size from the mobile one).
    fixed2base : array_like, shape (4, 4), optional
        Known pose of the fixed target in the robot base frame, mm.
    scale : int, optional
        Reduction factor of the coarse search (default automatic).
    track : bool
        Refine the previous image's corners before any full detection (default True).
    camera_source : str
        Name of the camera file, for the image-size message.
    refine : {"auto", "photometric", "corners"}
        Pose refinement (:func:`~stiffmap.vision.pose.estimate_pose`): ``"auto"``
        (default) is ``"photometric"`` for chessboards (a model of the blurred board
        fitted to its pixels, with the other board's area left out; the corner pose is
        kept when that fit fails its checks, ``BoardPose.fallback``) and ``"corners"``
        for ChArUco boards.
    refine_fixed : {"auto", "photometric", "corners"}, optional
        Refinement of the fixed target's pose (default: as ``refine``). A campaign
        averages the fixed target over a position's images and uses it only to orient
        the displacements, so corner poses are precise enough there and faster.
    """

    def __init__(
        self,
        camera: CameraModel,
        mobile_board: Board,
        fixed_board: Board | None = None,
        fixed2base=None,
        *,
        scale: int | None = None,
        track: bool = True,
        camera_source: str = "camera.json",
        refine: str = "auto",
        refine_fixed: str | None = None,
    ) -> None:
        check_refine(refine)
        if refine_fixed is not None:
            check_refine(refine_fixed)
        if fixed2base is not None and fixed_board is None:
            raise ValueError("fixed2base needs fixed_board (the target whose pose on the base it gives)")
        self.camera = camera
        self.boards: list[Board] = [mobile_board] + ([fixed_board] if fixed_board is not None else [])
        self.fixed2base = None if fixed2base is None else as_transform(fixed2base, "fixed2base")
        self.scale = scale
        self.track = track
        self.camera_source = camera_source
        self.refine = refine
        self.refine_fixed = refine if refine_fixed is None else refine_fixed
        self._prev: list[BoardDetection | None] = [None] * len(self.boards)
        self._ref: list[BoardDetection | None] = [None] * len(self.boards)
        self._poses: list[np.ndarray | None] = [None] * len(self.boards)

    def reset(self) -> None:
        """Forget the previous image (the next one gets a full detection)."""
        self._prev = [None] * len(self.boards)
        self._poses = [None] * len(self.boards)

    def measure(self, image, name: str | None = None) -> ImageMeasurement:
        """Measure one image (a path or a uint8 array).

        Returns
        -------
        ImageMeasurement
            With ``error`` set (and the tracker reset) when the image could not
            be used (unreadable, another size, no board, or the lens model of the camera
            cannot be inverted where the board is); never raises for a bad image.
        """
        t0 = time.perf_counter()
        if isinstance(image, (str, os.PathLike)):
            label = str(image) if name is None else name
        else:
            label = "<array>" if name is None else name
        timings: dict[str, float] = {}
        try:
            if isinstance(image, (str, os.PathLike)):
                img = read_image(image)
            else:
                img = np.asarray(image)
            timings["read"] = time.perf_counter() - t0
            check_image_size(img, self.camera.image_size, source=label, camera_source=self.camera_source)
            t1 = time.perf_counter()
            dets = detect_boards(
                img,
                self.boards,
                previous=self._prev if self.track else None,
                reference=self._ref,
                camera=self.camera,
                scale=self.scale,
                source=label,
            )
            t2 = time.perf_counter()
            poses = []
            for k, (d, b) in enumerate(zip(dets, self.boards, strict=True)):
                init = self._poses[k] if d.tracked else None
                # The other boards' areas (squares and a white margin of up to 1.2 squares) are
                # left out of a photometric fit.
                others = [
                    detection_mask(o, margin_sq=2.2)
                    for j, o in enumerate(dets)
                    if j != k and o.n_corners >= 4
                ]
                poses.append(
                    estimate_pose(
                        d,
                        b,
                        self.camera,
                        initial=init,
                        source=label,
                        image=img,
                        refine=self.refine if k == 0 else self.refine_fixed,
                        exclude=others,
                    )
                )
            t3 = time.perf_counter()
        except InputError as e:
            self.reset()
            timings["total"] = time.perf_counter() - t0
            return ImageMeasurement(image=label, timings=timings, error=str(e.with_source(label)))
        except UndistortionError as e:
            # The lens model of camera.json cannot be inverted where this image needs it.
            self.reset()
            timings["total"] = time.perf_counter() - t0
            return ImageMeasurement(
                image=label, timings=timings, error=f"{label}: with {self.camera_source}: {e}"
            )
        self._prev = list(dets)
        self._ref = list(dets)
        self._poses = [p.board2cam for p in poses]
        mobile = poses[0]
        fixed = poses[1] if len(poses) > 1 else None
        m2b = m2b_cov = m2b_A = None
        if fixed is not None and self.fixed2base is not None:
            # The poses' own noise is independent; the calibration's error moves both at once.
            m2b, m2b_cov = mobile2base_from_poses(
                mobile.board2cam, mobile.cov_noise, fixed.board2cam, fixed.cov_noise, self.fixed2base
            )
            if mobile.calibration_jacobian is not None and fixed.calibration_jacobian is not None:
                _, Jm, Jf = _mobile2base_jacobians(mobile.board2cam, fixed.board2cam, self.fixed2base)
                m2b_A = Jm @ mobile.calibration_jacobian + Jf @ fixed.calibration_jacobian
                Sc = self.camera.calibration_cov
                if Sc is not None:
                    m2b_cov = m2b_cov + m2b_A @ Sc @ m2b_A.T
        timings.update(detect=t2 - t1, pose=t3 - t2, total=time.perf_counter() - t0)
        return ImageMeasurement(
            image=label,
            mobile=mobile,
            fixed=fixed,
            mobile2base=m2b,
            mobile2base_cov=m2b_cov,
            mobile2base_calibration_jacobian=m2b_A,
            calibration_cov=self.camera.calibration_cov,
            mobile_detection=dets[0],
            fixed_detection=dets[1] if len(dets) > 1 else None,
            timings=timings,
        )


def measure_sequence(
    images: Iterable,
    camera: CameraModel,
    mobile_board: Board,
    fixed_board: Board | None = None,
    fixed2base=None,
    *,
    names: Sequence[str] | None = None,
    scale: int | None = None,
    track: bool = True,
    camera_source: str = "camera.json",
    refine: str = "auto",
    refine_fixed: str | None = None,
) -> list[ImageMeasurement]:
    """Measure a sequence of images of one robot position (see :class:`PoseTracker`).

    Parameters
    ----------
    images : iterable of path or ndarray (h, w) uint8
    camera : CameraModel
    mobile_board, fixed_board : Chessboard or CharucoBoard
    fixed2base : array_like, shape (4, 4), optional
    names : sequence of str, optional
        Labels of array images.
    scale : int, optional
    track : bool
    camera_source : str
        Name of the camera file, for the image-size message.
    refine, refine_fixed : {"auto", "photometric", "corners"}
        Pose refinement of the mobile and of the fixed target (see :class:`PoseTracker`).

    Returns
    -------
    list of ImageMeasurement
        One per image, in order; failed images have ``error`` set.
    """
    tracker = PoseTracker(
        camera,
        mobile_board,
        fixed_board,
        fixed2base,
        scale=scale,
        track=track,
        camera_source=camera_source,
        refine=refine,
        refine_fixed=refine_fixed,
    )
    out = []
    for k, im in enumerate(images):
        out.append(tracker.measure(im, None if names is None else names[k]))
    return out
