"""Poses of the mobile (and fixed) target along a sequence of images of one robot position.

:class:`PoseTracker` measures image after image: the corners of the previous
image seed the next and are only refined (:func:`~stiffmap.vision.tracking.track_board`);
the full detection runs for the first image and whenever refinement fails its
consistency check. With a fixed target and its known pose on the robot base,
each image also gives ``mobile2base`` (reference paper, eq. 1) with its
covariance. An image that fails (unreadable, wrong size, board not found) gives
an :class:`ImageMeasurement` with ``error`` set, and the sequence goes on.

Several cameras (a :class:`~stiffmap.rig.Rig`): each item of the sequence is then an image
set, one image per camera (a mapping camera name -> path or array, or a sequence in the rig's
order). Each camera is tracked on its own images; each board's poses from the cameras that
saw it are fused into one pose in the rig frame (:func:`~stiffmap.vision.fuse.fuse_poses`),
so ``ImageMeasurement.mobile`` and ``fixed`` are poses in the rig frame (``board2rig``; a
single camera is a rig of one, its own frame; ``board2frame`` reads either, ``cam2base`` reads
rig2base) and the calibration sensitivities are over
``rig.param_names``; ``ImageMeasurement.views`` keeps what each camera gave. A camera whose
image is missing, unreadable, of another size than that camera's, or without the board, is
named in its view's ``error`` and the others go on; a board that no camera saw makes the
measurement's ``error`` (naming each camera's reason). A :class:`~stiffmap.camera.CameraModel`
is measured as the rig of that one camera, through the same code: its poses, errors and
covariances are those of the camera alone.
"""

from __future__ import annotations

import os
import time
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..camera import CameraModel, UndistortionError
from ..errors import InputError
from ..geometry import as_transform, invert_transform
from ..posemath import BoardPose, skew
from ..rig import Rig
from ..targets import Chessboard, as_board
from .board_plane import detection_mask
from .detect import Board, BoardDetection, DetectionError, board_label, detect_boards
from .fuse import FusedPose, fuse_poses
from .images import check_image_size, read_image
from .photometric import PhotometricError, PhotometricTrack
from .pose import check_refine, estimate_pose, follow_pose
from .tracking import followed_detection

__all__ = [
    "CameraView",
    "FALLBACK_CATEGORIES",
    "ImageMeasurement",
    "PoseTracker",
    "fallback_category",
    "measure_sequence",
    "mobile2base_from_poses",
    "photometric_counts",
    "photometric_summary",
]


@dataclass(frozen=True)
class CameraView:
    """What one camera of a rig gave for one image set.

    Attributes
    ----------
    camera : str
        The camera's name in the rig.
    image : str
        Its image's file name (or a label for arrays).
    mobile, fixed : BoardPose or None
        The targets' poses in this camera's frame (its own corner numbering), None where it
        did not see them.
    mobile_detection, fixed_detection : BoardDetection or None
    timings : dict of str to float
        Seconds spent on this camera's image: ``read``, ``detect``, ``pose``, ``total``.
    error : str or None
        Why this camera gave no pose of a target (its image missing, unreadable, of another
        size than the camera's, a target not found...); None when it gave every target's.
    """

    camera: str
    image: str
    mobile: BoardPose | None = None
    fixed: BoardPose | None = None
    mobile_detection: BoardDetection | None = None
    fixed_detection: BoardDetection | None = None
    timings: dict[str, float] = field(default_factory=dict)
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


@dataclass(frozen=True)
class ImageMeasurement:
    """What one image (or, with a rig, one image set) gave.

    Attributes
    ----------
    image : str
        File name (or a label for arrays; for a rig, the set's label).
    mobile, fixed : BoardPose or None
        Poses of the mobile and fixed targets in the camera frame; with a rig, in the rig
        frame, fused from every camera that saw them (:class:`~stiffmap.vision.fuse.FusedPose`:
        ``board2rig``; ``board2frame`` whatever the frame).
    mobile2base : ndarray, shape (4, 4) or None
        The mobile target in the robot base frame (fixed target and
        ``fixed2base`` given), mm.
    mobile2base_cov : ndarray, shape (6, 6) or None
        Its covariance (t, r in the base frame; fixed and mobile target noise, and the
        calibration's share propagated through both poses at once).
    mobile2base_calibration_jacobian : ndarray, shape (6, n) or None
        d(t, r of mobile2base) / d(camera parameters) (with a rig, ``rig.param_names``): the
        calibration's error moves the fixed and the mobile target's poses together.
    calibration_cov : ndarray, shape (n, n) or None
        The calibration covariance the poses' ``cov_calibration`` were propagated from
        (``CameraModel.calibration_cov``, or ``Rig.calibration_cov``; None: unknown).
    mobile_detection, fixed_detection : BoardDetection or None
        With a rig, those of the first camera (in the rig's order) that saw the target; every
        camera's are in ``views``.
    timings : dict of str to float
        Seconds spent: ``read``, ``detect``, ``pose``, ``total`` (with a rig, summed over the
        cameras, plus ``fuse``).
    error : str or None
        Why the image gave no measurement (then the poses are None).
    views : tuple of CameraView
        What each camera gave (one entry for a single camera).
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
    views: tuple[CameraView, ...] = ()

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def mobile2cam(self) -> np.ndarray | None:
        return None if self.mobile is None else self.mobile.board2frame

    @property
    def mobile2cam_cov(self) -> np.ndarray | None:
        return None if self.mobile is None else self.mobile.cov

    @property
    def fixed2cam(self) -> np.ndarray | None:
        return None if self.fixed is None else self.fixed.board2frame

    @property
    def fixed2cam_cov(self) -> np.ndarray | None:
        return None if self.fixed is None else self.fixed.cov

    @property
    def cam2base(self) -> np.ndarray | None:
        """cam2base (with a rig: rig2base) through this image's fixed target (None without one)."""
        if self.mobile2base is None or self.mobile is None:
            return None
        return self.mobile2base @ invert_transform(self.mobile.board2frame)

    @property
    def rig2base(self) -> np.ndarray | None:
        """The rig frame in the base frame (:attr:`cam2base`; the first camera's frame)."""
        return self.cam2base

    @property
    def tracked(self) -> bool:
        """True when every target was tracked (no full detection) in every camera that saw it."""
        dets = [
            d
            for v in (self.views or (self,))
            for d in (v.mobile_detection, v.fixed_detection)
            if d is not None
        ]
        return bool(dets) and all(d.tracked for d in dets)

    @property
    def consistency_warnings(self) -> tuple[str, ...]:
        """The fused poses' warnings that the cameras disagree (a wrong rig file, a moved camera)."""
        return tuple(
            p.consistency_warning
            for p in (self.mobile, self.fixed)
            if isinstance(p, FusedPose) and p.consistency_warning
        )


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


class _ViewResult:
    """One camera's outcome inside :meth:`PoseTracker.measure` (poses per board, or why not)."""

    __slots__ = ("label", "poses", "dets", "errors", "timings", "error")

    def __init__(self, label: str, n_boards: int) -> None:
        self.label = label
        self.poses: list[BoardPose | None] = [None] * n_boards
        self.dets: list[BoardDetection | None] = [None] * n_boards
        self.errors: list[str | None] = [None] * n_boards
        self.timings: dict[str, float] = {}
        self.error: str | None = None

    def fail(self, message: str) -> _ViewResult:
        self.error = message
        self.errors = [message] * len(self.errors)
        return self


class PoseTracker:
    """Measure target poses image after image for one robot position.

    Parameters
    ----------
    camera : CameraModel or Rig
        One camera, or several (each image is then an image set, one image per camera: see
        :meth:`measure`). A camera is measured as the rig of that one camera.
    mobile_board : Chessboard or CharucoBoard
        The target on the moving platform.
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (:func:`~stiffmap.targets.as_board`).
    fixed_board : Chessboard or CharucoBoard, optional
        The target on the robot base (a different size from the mobile one); as text
        ``"COLSxROWS"`` with ``fixed_square_mm``.
    fixed2base : array_like, shape (4, 4), optional
        Known pose of the fixed target in the robot base frame, mm.
    scale : int, optional
        Reduction factor of the coarse search (default automatic).
    track : bool
        Refine the previous image's corners before any full detection (default True).
    camera_source : str
        Name of the camera (or rig) file, for the image-size message.
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
        camera: CameraModel | Rig,
        mobile_board: Board,
        fixed_board: Board | None = None,
        fixed2base=None,
        *,
        scale: int | None = None,
        track: bool = True,
        camera_source: str = "camera.json",
        refine: str = "auto",
        refine_fixed: str | None = None,
        square_mm: float | None = None,
        fixed_square_mm: float | None = None,
    ) -> None:
        mobile_board = as_board(mobile_board, square_mm, "mobile_board")
        fixed_board = None if fixed_board is None else as_board(fixed_board, fixed_square_mm, "fixed_board")
        check_refine(refine)
        if refine_fixed is not None:
            check_refine(refine_fixed)
        if fixed2base is not None and fixed_board is None:
            raise ValueError("fixed2base needs fixed_board (the target whose pose on the base it gives)")
        if isinstance(camera, Rig):
            self.rig = camera
        elif isinstance(camera, CameraModel):
            self.rig = Rig.single(camera)
        else:
            raise TypeError(f"camera must be a CameraModel or a Rig, got {type(camera).__name__}")
        self.camera = self.rig.cameras[0].camera
        self.boards: list[Board] = [mobile_board] + ([fixed_board] if fixed_board is not None else [])
        self.fixed2base = None if fixed2base is None else as_transform(fixed2base, "fixed2base")
        self.scale = scale
        self.track = track
        self.camera_source = camera_source
        self.refine = refine
        self.refine_fixed = refine if refine_fixed is None else refine_fixed
        nc, nb = len(self.rig), len(self.boards)
        self._prev: list[list[BoardDetection | None]] = [[None] * nb for _ in range(nc)]
        self._ref: list[list[BoardDetection | None]] = [[None] * nb for _ in range(nc)]
        self._poses: list[list[np.ndarray | None]] = [[None] * nb for _ in range(nc)]
        # Whether each board's last pose was photometric (the next image may follow it alone).
        self._followable: list[list[bool]] = [[False] * nb for _ in range(nc)]
        self._fused: list[np.ndarray | None] = [None] * nb
        # Each board's last photometric fit in each camera: the next image's fit starts from it
        # (``_warm_start`` False: every fit from the start, for the speed benchmark's comparison).
        self._photo = [[PhotometricTrack() for _ in range(nb)] for _ in range(nc)]
        self._warm_start = True
        # The platform's states (load cases) seen so far: the mobile board's tracking state in
        # each camera when it last was in each (see ``measure(state=...)``).
        self._state: Hashable | None = None
        self._saved: dict[Hashable, list[tuple]] = {}

    def reset(self) -> None:
        """Forget the previous image (the next one gets a full detection in every camera)."""
        for k in range(len(self.rig)):
            self._reset_camera(k)
        self._state = None
        self._saved.clear()

    def _enter_state(self, state: Hashable | None) -> None:
        """Make the mobile board's tracking state that of the last image in ``state``.

        The current state is kept for when the platform comes back to it; a state not seen
        before starts from the last image's corners with a fresh photometric fit.
        """
        if state is None or state == self._state:
            return
        nc = len(self.rig)
        if self._state is not None:
            self._saved[self._state] = [
                (self._prev[k][0], self._poses[k][0], self._followable[k][0], self._photo[k][0])
                for k in range(nc)
            ]
        back = self._saved.pop(state, None)
        for k in range(nc):
            if back is not None and self._prev[k][0] is not None and back[k][0] is not None:
                self._prev[k][0], self._poses[k][0], self._followable[k][0], self._photo[k][0] = back[k]
            else:  # first time in this state (or a camera that lost the board since): corners first
                self._followable[k][0] = False
                self._photo[k][0] = PhotometricTrack()
        self._state = state

    def _reset_camera(self, k: int) -> None:
        self._prev[k] = [None] * len(self.boards)
        self._poses[k] = [None] * len(self.boards)
        self._followable[k] = [False] * len(self.boards)
        for t in self._photo[k]:
            t.clear()

    def _camera_source(self, k: int) -> str:
        """The camera's file for messages: the camera file, or the rig file and the camera's name."""
        if len(self.rig) == 1:
            return self.camera_source
        return f"{self.camera_source} (camera {self.rig.names[k]!r})"

    def _split(self, images, name: str | None) -> tuple[list, list[str], str]:
        """The image of each camera (None: not given), their labels and the set's label."""
        rig = self.rig
        n = len(rig)

        def is_image(x) -> bool:
            return isinstance(x, (str, os.PathLike, np.ndarray))

        if isinstance(images, Mapping):
            unknown = [str(c) for c in images if c not in rig.names]
            if unknown:
                raise ValueError(
                    f"image set names camera(s) {', '.join(map(repr, unknown))} not in the rig "
                    f"(cameras: {', '.join(rig.names)})"
                )
            items = [images.get(c) for c in rig.names]
        elif n == 1 and not (isinstance(images, (list, tuple)) and len(images) == 1 and is_image(images[0])):
            items = [images]  # one camera: the image itself (a path or anything array-like)
        elif isinstance(images, Sequence) and not is_image(images) and len(images) == n:
            items = list(images)
        else:
            raise ValueError(
                f"a rig of {n} camera(s) needs one image per camera: a mapping camera name -> image, "
                f"or a sequence of {n} in the rig's order ({', '.join(rig.names)})"
            )

        def own(x) -> str | None:
            if isinstance(x, (str, os.PathLike)):
                return str(x)
            return None

        if n == 1:
            x = items[0]
            label = name if name is not None else (own(x) or "<array>")
            return items, [label], label
        present = [own(x) for x in items]
        if name is not None:
            set_label = name
        else:
            set_label = " + ".join(
                p if p is not None else f"{'<array>' if x is not None else '<none>'} ({c})"
                for p, x, c in zip(present, items, rig.names, strict=True)
            )
        labels = [
            p if p is not None else (f"{set_label} ({c})" if x is not None else set_label)
            for p, x, c in zip(present, items, rig.names, strict=True)
        ]
        return items, labels, set_label

    def measure(self, image, name: str | None = None, state: Hashable | None = None) -> ImageMeasurement:
        """Measure one image (a path or a uint8 array), or, with a rig, one image set.

        Parameters
        ----------
        image : path, ndarray (h, w) uint8, mapping or sequence
            One camera: a path or an array. A rig: a mapping camera name -> path or array
            (a camera left out or given None has no image in this set), or a sequence of one
            per camera in the rig's order.
        name : str, optional
            Label of the image (set) in the result and the messages.
        state : hashable, optional
            The platform's state in this image (a campaign's load case: 0 unloaded, k the
            k-th load). The mobile board is tracked from the last image in the same state,
            where it stood within the robot's repeatability: with repeated load cycles it is
            followed by its photometric fit alone instead of being found again at every load
            change. None: from the previous image.

        Returns
        -------
        ImageMeasurement
            With ``error`` set when no camera gave the pose of some target (each camera's
            reason named); a camera whose image could not be used (unreadable, another size,
            no board, or the lens model of the camera cannot be inverted where the board is)
            is reset and named in its view's ``error``. Never raises for a bad image.
        """
        t0 = time.perf_counter()
        items, labels, set_label = self._split(image, name)
        self._enter_state(state)
        results = [self._measure_view(k, items[k], labels[k]) for k in range(len(self.rig))]
        views = self._camera_views(results)
        timings = {key: sum(r.timings.get(key, 0.0) for r in results) for key in ("read", "detect", "pose")}
        missing = [b for b in range(len(self.boards)) if all(r.poses[b] is None for r in results)]
        if missing:
            timings["total"] = time.perf_counter() - t0
            error = self._missing_error(results, missing, set_label)
            return ImageMeasurement(image=set_label, timings=timings, error=error, views=views)
        t1 = time.perf_counter()
        fused = self._fuse(results)
        timings["fuse"] = time.perf_counter() - t1
        mobile = fused[0]
        fixed = fused[1] if len(fused) > 1 else None
        Sc = self.rig.calibration_cov
        m2b, m2b_cov, m2b_A = self._mobile2base(mobile, fixed, Sc)

        def first_detection(b: int) -> BoardDetection | None:
            return next((r.dets[b] for r in results if r.poses[b] is not None), None)

        timings["total"] = time.perf_counter() - t0
        return ImageMeasurement(
            image=set_label,
            mobile=mobile,
            fixed=fixed,
            mobile2base=m2b,
            mobile2base_cov=m2b_cov,
            mobile2base_calibration_jacobian=m2b_A,
            calibration_cov=Sc,
            mobile_detection=first_detection(0),
            fixed_detection=first_detection(1) if len(self.boards) > 1 else None,
            timings=timings,
            views=views,
        )

    def _camera_views(self, results: list[_ViewResult]) -> tuple[CameraView, ...]:
        return tuple(
            CameraView(
                camera=self.rig.names[k],
                image=r.label,
                mobile=r.poses[0],
                fixed=r.poses[1] if len(self.boards) > 1 else None,
                mobile_detection=r.dets[0],
                fixed_detection=r.dets[1] if len(self.boards) > 1 else None,
                timings=r.timings,
                error=r.error or ("; ".join(e for e in r.errors if e) or None),
            )
            for k, r in enumerate(results)
        )

    def _missing_error(self, results: list[_ViewResult], missing: list[int], set_label: str) -> str:
        """Why boards ``missing`` have no pose: the camera's reason, or each camera's for a rig."""
        if len(self.rig) == 1:
            return results[0].error or next(e for e in results[0].errors if e)
        return f"{set_label}: " + "; ".join(
            f"no camera saw the {self._what(b)}: "
            + "; ".join(f"{c}: {r.errors[b]}" for c, r in zip(self.rig.names, results, strict=True))
            for b in missing
        )

    def _fuse(self, results: list[_ViewResult]) -> list:
        """Each board's pose in the rig frame from the cameras that saw it (:func:`fuse_poses`)."""
        fused = []
        for b in range(len(self.boards)):
            seen = {k: r.poses[b] for k, r in enumerate(results) if r.poses[b] is not None}
            f = fuse_poses(
                self.rig, seen, board=self.boards[b], reference=self._fused[b], label=self._what(b)
            )
            self._fused[b] = f.board2rig
            fused.append(f)
        return fused

    def _mobile2base(self, mobile, fixed, Sc):
        """mobile2base, its covariance (the calibration's share with the rig's covariance Sc)
        and its calibration sensitivity (None each without a fixed target and fixed2base)."""
        m2b = m2b_cov = m2b_A = None
        if fixed is not None and self.fixed2base is not None:
            # The poses' own noise is independent; the calibration's error moves both at once.
            m2b, m2b_cov = mobile2base_from_poses(
                mobile.board2frame, mobile.cov_noise, fixed.board2frame, fixed.cov_noise, self.fixed2base
            )
            if mobile.calibration_jacobian is not None and fixed.calibration_jacobian is not None:
                _, Jm, Jf = _mobile2base_jacobians(mobile.board2frame, fixed.board2frame, self.fixed2base)
                m2b_A = Jm @ mobile.calibration_jacobian + Jf @ fixed.calibration_jacobian
                if Sc is not None:
                    m2b_cov = m2b_cov + m2b_A @ Sc @ m2b_A.T
        return m2b, m2b_cov, m2b_A

    def _what(self, b: int) -> str:
        return f"{'mobile' if b == 0 else 'fixed'} target ({board_label(self.boards[b])})"

    def _measure_view(self, k: int, image, label: str) -> _ViewResult:
        """Detect and pose every board in camera ``k``'s image; never raises for a bad image."""
        camera = self.rig.cameras[k].camera
        nb = len(self.boards)
        res = _ViewResult(label, nb)
        t0 = time.perf_counter()
        if image is None:
            self._reset_camera(k)
            res.timings["total"] = 0.0
            return res.fail(f"{label}: no image of camera {self.rig.names[k]!r} in this set")
        try:
            img = read_image(image) if isinstance(image, (str, os.PathLike)) else np.asarray(image)
            res.timings["read"] = time.perf_counter() - t0
            check_image_size(img, camera.image_size, source=label, camera_source=self._camera_source(k))
            t1 = time.perf_counter()
            # Boards followed by their photometric fit alone (None: their corners are measured).
            dets, poses, t_follow = self._follow(k, img, label)
            todo = [b for b in range(nb) if dets[b] is None]
            if todo:
                self._find(k, img, label, dets, todo, res)
            t2 = time.perf_counter()
            self._pose_found(k, img, label, dets, poses, todo)
            res.dets, res.poses = dets, poses
            t3 = time.perf_counter()
            t2 -= t_follow  # the follow's fits are pose time
        except InputError as e:
            return self._view_failed(k, res, t0, str(e.with_source(label)))
        except UndistortionError as e:
            # The lens model of the camera file cannot be inverted where this image needs it.
            return self._view_failed(k, res, t0, f"{label}: with {self._camera_source(k)}: {e}")
        self._remember(k, res)
        res.timings.update(detect=t2 - t1, pose=t3 - t2, total=time.perf_counter() - t0)
        return res

    def _find(
        self, k: int, img: np.ndarray, label: str, dets: list, todo: list[int], res: _ViewResult
    ) -> None:
        """Detect boards ``todo`` in camera ``k``'s image (set in ``dets``), the others' areas
        hidden. With a rig, a camera that found some of them goes on with those (the others'
        errors in ``res``): another camera may see them."""
        hidden = [detection_mask(d) for d in dets if d is not None]
        try:
            found = list(self._detect(k, img, todo, label, hidden))
        except DetectionError as e:
            found = e.found or []
            if len(self.rig) == 1 or not any(d is not None for d in found):
                raise
            found = list(found) + [None] * (len(todo) - len(found))
            for j, b in enumerate(todo):
                if found[j] is None:
                    res.errors[b] = str(e.with_source(label))
        for j, b in enumerate(todo):
            dets[b] = found[j]

    def _pose_found(
        self, k: int, img: np.ndarray, label: str, dets: list, poses: list, todo: list[int]
    ) -> None:
        """The poses (set in ``poses``) of the boards ``todo`` detected in camera ``k``'s image."""
        camera = self.rig.cameras[k].camera
        for b in todo:
            d = dets[b]
            if d is None:
                continue
            init = self._poses[k][b] if d.tracked else None
            if not d.tracked:
                self._photo[k][b].clear()  # a full detection: the photometric fit starts cold
            # The other boards' areas (squares and a white margin of up to 1.2 squares) are
            # left out of a photometric fit.
            others = [
                detection_mask(o, margin_sq=2.2)
                for j, o in enumerate(dets)
                if j != b and o is not None and o.n_corners >= 4
            ]
            poses[b] = estimate_pose(
                d,
                self.boards[b],
                camera,
                initial=init,
                source=label,
                image=img,
                refine=self.refine if b == 0 else self.refine_fixed,
                exclude=others,
                track=self._photo[k][b] if self._warm_start else None,
            )

    def _view_failed(self, k: int, res: _ViewResult, t0: float, message: str) -> _ViewResult:
        """Camera ``k``'s image could not be used: the camera reset, no board in the result."""
        nb = len(self.boards)
        self._reset_camera(k)
        res.timings["total"] = time.perf_counter() - t0
        res.poses = [None] * nb
        res.dets = [None] * nb
        return res.fail(message)

    def _remember(self, k: int, res: _ViewResult) -> None:
        """Keep camera ``k``'s detections and poses for the next image."""
        for b in range(len(self.boards)):
            if res.dets[b] is not None:
                self._prev[k][b] = res.dets[b]
                self._ref[k][b] = res.dets[b]
                self._poses[k][b] = res.poses[b].board2cam
                self._followable[k][b] = res.poses[b].method == "photometric"
            else:
                self._prev[k][b] = None
                self._poses[k][b] = None
                self._followable[k][b] = False

    def _follow(self, k: int, img: np.ndarray, label: str):
        """The boards of camera ``k`` followed by their photometric fit alone (None for the others).

        Each chessboard whose previous pose was photometric (its :class:`PhotometricTrack`
        ready) is fitted from that pose, pixel set and linearisation, without measuring its
        corners (:func:`~stiffmap.vision.pose.follow_pose`). When any board cannot be (the
        corner refinement asked for, a board not tracked, a fit failing its checks: the board
        moved too far, the scene changed), None in its place: the caller tracks its corners
        and fits from them. Returns (detections, poses, seconds spent).
        """
        nb = len(self.boards)
        dets: list[BoardDetection | None] = [None] * nb
        poses: list[BoardPose | None] = [None] * nb
        t0 = time.perf_counter()
        if not (self._warm_start and self.track):
            return dets, poses, 0.0
        camera = self.rig.cameras[k].camera
        prev = self._prev[k]
        masks = [None if d is None or d.n_corners < 4 else detection_mask(d, margin_sq=2.2) for d in prev]
        for b in range(nb):
            refine = self.refine if b == 0 else self.refine_fixed
            if (
                refine == "corners"
                or not isinstance(self.boards[b], Chessboard)
                or masks[b] is None
                or self._poses[k][b] is None
                or not self._followable[k][b]
                or not self._photo[k][b].ready
            ):
                continue
            try:
                poses[b] = follow_pose(
                    img,
                    self.boards[b],
                    camera,
                    self._poses[k][b],
                    self._photo[k][b],
                    exclude=[m for j, m in enumerate(masks) if j != b and m is not None],
                    source=label,
                )
            except PhotometricError:
                continue
            dets[b] = followed_detection(prev[b], poses[b].board2cam, camera, 0.0)
        return dets, poses, time.perf_counter() - t0

    def _detect(
        self, k: int, img: np.ndarray, which: list[int], label: str, hidden=()
    ) -> list[BoardDetection]:
        return detect_boards(
            img,
            [self.boards[b] for b in which],
            previous=[self._prev[k][b] for b in which] if self.track else None,
            reference=[self._ref[k][b] for b in which],
            camera=self.rig.cameras[k].camera,
            scale=self.scale,
            source=label,
            hidden=hidden,
        )


def measure_sequence(
    images: Iterable,
    camera: CameraModel | Rig,
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
    states: Sequence[Hashable] | None = None,
    square_mm: float | None = None,
    fixed_square_mm: float | None = None,
) -> list[ImageMeasurement]:
    """Measure a sequence of images of one robot position (see :class:`PoseTracker`).

    Parameters
    ----------
    images : iterable of path or ndarray (h, w) uint8 (a rig: of image sets)
        With a rig, each item is a mapping camera name -> path or array, or a sequence of
        one per camera in the rig's order (:meth:`PoseTracker.measure`).
    camera : CameraModel or Rig
    mobile_board, fixed_board : Chessboard or CharucoBoard
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (and ``fixed_square_mm``)
        (:func:`~stiffmap.targets.as_board`).
    fixed2base : array_like, shape (4, 4), optional
    names : sequence of str, optional
        Labels of array images (of image sets).
    scale : int, optional
    track : bool
    camera_source : str
        Name of the camera (or rig) file, for the image-size message.
    refine, refine_fixed : {"auto", "photometric", "corners"}
        Pose refinement of the mobile and of the fixed target (see :class:`PoseTracker`).
    states : sequence of hashable, optional
        The platform's state in each image (e.g. its load case; :meth:`PoseTracker.measure`).

    Returns
    -------
    list of ImageMeasurement
        One per image (set), in order; failed ones have ``error`` set.
    """
    mobile_board = as_board(mobile_board, square_mm, "mobile_board")
    fixed_board = None if fixed_board is None else as_board(fixed_board, fixed_square_mm, "fixed_board")
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
        out.append(
            tracker.measure(im, None if names is None else names[k], None if states is None else states[k])
        )
    return out


#: Why a photometric refinement was not kept, by the words of its ``fallback`` (first match).
FALLBACK_CATEGORIES = (
    ("sigma from the corner pose", "disagrees with the corner pose beyond the two fits' uncertainty"),
    ("contrast", "the fitted contrast fades over part of the board"),
    ("did not converge", "did not converge"),
    ("blur", "implausible blur"),
    ("usable pixels", "too few usable pixels"),
    ("do not fit the model", "too many pixels off the model"),
)


def fallback_category(fallback: str) -> str:
    """The category of a photometric fallback (:data:`FALLBACK_CATEGORIES`, else ``"other"``)."""
    for words, category in FALLBACK_CATEGORIES:
        if words in fallback:
            return category
    return "other"


def photometric_counts(ms: Sequence[ImageMeasurement]) -> tuple[int, int, dict[str, int]]:
    """Poses refined photometrically, poses tried, and why the others kept their corner pose.

    Counts every board pose of every camera (a rig's per-camera poses, not the fused ones) whose
    photometric refinement was tried (chessboards with their image).

    Returns
    -------
    kept : int
    tried : int
    why : dict of str to int
        :func:`fallback_category` -> number of poses.
    """
    kept = tried = 0
    why: dict[str, int] = {}
    for m in ms:
        for v in m.views or (m,):
            for p in (v.mobile, v.fixed):
                if p is None:
                    continue
                if p.method == "photometric":
                    kept += 1
                    tried += 1
                elif p.fallback and "corner pose kept" in p.fallback and "ChArUco" not in p.fallback:
                    tried += 1
                    c = fallback_category(p.fallback)
                    why[c] = why.get(c, 0) + 1
    return kept, tried, why


def photometric_summary(ms: Sequence[ImageMeasurement]) -> str | None:
    """One sentence: on how many poses the photometric refinement was kept, and why not on the
    others (None when it was kept on all, or never tried)."""
    kept, tried, why = photometric_counts(ms)
    if tried == 0 or kept == tried:
        return None
    reasons = "; ".join(f"{c}: {n}" for c, n in sorted(why.items(), key=lambda cn: -cn[1]))
    return (
        f"photometric refinement kept on {kept} of {tried} poses; the corner pose, the better "
        f"estimate there, on the other {tried - kept} ({reasons}; --json gives each 'fallback')"
    )
