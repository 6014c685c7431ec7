"""Pose of a board from its detected corners, with the covariance of the pose.

:func:`estimate_pose` starts from OpenCV's IPPE solution for planar targets and
refines ``board2cam`` by Gauss-Newton on the reprojection error, with the
analytic Jacobian of :func:`~stiffmap.posemath.projection_jacobian`.

Covariance (``docs/conventions.md``, "Pose uncertainty"): over (t, r), t the
translation of ``board2cam`` (mm, camera frame) and r a small rotation vector
applied on the left, R = Exp(r) R_hat, also in the camera frame
(:func:`~stiffmap.posemath.perturb_pose`). A board point q then moves by
dX = dt - [R q]x dr in the camera frame, and its pixel by
J_i = diag(fx, fy) D(x) P(X) [I, -[R q]x], with P the Jacobian of the
perspective division and D that of the lens distortion at the point. With the
stacked J (2m x 6) and the residual variance s^2 = sum e^2 / (2m - 6) (corner
noise, assumed independent and equal on both axes), cov_noise = s^2 (J^T J)^-1.

The camera's calibration (``camera.json``'s ``cov``, or its ``std`` as a diagonal) adds
its share: the fitted pose follows an error dc of the camera's parameters as A dc, with
A = -(J^T J)^-1 J^T J_c by implicit differentiation of the fit
(:func:`~stiffmap.posemath.calibration_sensitivity`), so cov = cov_noise + A cov_c A^T.
``BoardPose.calibration_jacobian`` keeps A and ``BoardPose.cov_calibration`` the share:
the calibration's error is common to every pose taken with the camera, so a displacement
(a difference of two poses) propagates it through the difference of their A, not as the
sum of their shares (:mod:`stiffmap.vision.displacement`). The photometric pose's A is the
same implicit derivative for what that fit sees: points along every edge of the board's
squares, outer squares included (the printed border's edges at half weight, half of them
being black), each pinned only across its edge; the pixel weights, the excluded areas and the
fit's nuisance parameters (blur, shading) are left out of it. Against refitting the
photometric pose with a perturbed camera it agrees within 5 % (the corner fit's A, which
sees only the inner corners, is 10 % off in fx and 30 % in k1 there: the edges reach one
square farther out).

With ``refine="photometric"`` (or ``"auto"`` and the image given) the corner
pose is the starting point of :func:`~stiffmap.vision.photometric.refine_pose_photometric`,
which fits a model of the blurred board to the pixels near its edges (several
times more precise along the line of sight); the corner pose is kept, with the
reason in ``BoardPose.fallback``, when that fit fails or disagrees with it.

The pose itself (:class:`~stiffmap.posemath.BoardPose`), its perturbation and its
projection Jacobian live in :mod:`stiffmap.posemath`, shared with the photometric
refinement and the renderer.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import cv2
import numpy as np

from ..camera import CameraModel
from ..geometry import matrix_from_rotvec
from ..posemath import (
    BoardPose,
    PoseEstimate,
    calibration_sensitivity,
    check_pose,
    faces_camera,
    perturb_pose,
    projection_jacobian,
)
from ..targets import Chessboard, as_board
from .detection import Board, BoardDetection, DetectionError, board_label, grid_of
from .photometric import PhotometricError, PhotometricTrack, refine_pose_photometric
from .pnp import solve_pnp

__all__ = [
    "estimate_pose",
    "follow_pose",
    "pose_shift_sigma",
    "with_calibration_share",
    "check_refine",
    "corner_noise_factor",
    "MAX_CORNER_NOISE_FACTOR",
    "MIN_POSE_CORNERS",
    "REFINE_METHODS",
]

#: Fewest corners accepted for a pose (6 unknowns; 2 equations per corner).
MIN_POSE_CORNERS = 4
#: Pose refinements: ``"corners"`` (reprojection of the detected corners) or ``"photometric"``
#: (a model of the blurred board fitted to its pixels, :mod:`stiffmap.vision.photometric`).
REFINE_METHODS = ("corners", "photometric")
#: Largest distance, in combined sigmas (Mahalanobis over the 6 pose parameters), between the
#: photometric and the corner-based pose before the photometric one is refused.
MAX_REFINE_SHIFT_SIGMA = 6.0


#: Largest inflation of a corner pose's noise covariance for its errors' correlation.
MAX_CORNER_NOISE_FACTOR = 5.0


def corner_noise_factor(residuals_px) -> float:
    """How much a corner pose's independent-noise covariance understates its error on real images.

    The corner fit takes each corner's error as independent (cov_noise = s^2 (J^T J)^-1), but on
    a real camera what the lens model, the print and the corner estimator leave is smooth across
    the board: neighbouring corners err alike. With rho the correlation of neighbouring corners'
    residuals (consecutive ones in the canonical row-major order), a mean over m corners has the
    variance of about m / (1 + 4 rho) independent ones (four neighbours each, the design effect
    of a correlated sample); the factor is 1 + 4 rho, within 1..:data:`MAX_CORNER_NOISE_FACTOR`,
    with rho less its own standard deviation under independent errors (1 / sqrt(2 (m - 1)):
    chance correlation of independent errors does not inflate their covariance).
    On OpenCV's stereo samples rho is 0.24-0.56 (factors 2.0-3.2), where the cameras' corner
    poses scattered 3-5 times their independent-noise variance; on the test-bed's rendered
    images (independent noise) it is about 0 (factor 1).

    Parameters
    ----------
    residuals_px : ndarray, shape (m, 2)
        The corners' reprojection residuals at the pose, px, in canonical order.
    """
    e = np.asarray(residuals_px, dtype=np.float64).reshape(-1, 2)
    if len(e) < 8:
        return 1.0
    a, b = e[:-1], e[1:]
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    if not den > 0:
        return 1.0
    # Less one standard deviation of rho under independent errors (1 / sqrt(2 (m - 1)) terms),
    # so that chance correlation does not inflate an independent-noise covariance.
    rho = float(np.sum(a * b) / den) - 1.0 / np.sqrt(a.size)
    return float(np.clip(1.0 + 4.0 * rho, 1.0, MAX_CORNER_NOISE_FACTOR))


def check_refine(refine: str) -> str:
    """Validate a ``refine`` option (``"auto"`` or one of :data:`REFINE_METHODS`)."""
    if refine not in ("auto", *REFINE_METHODS):
        raise ValueError(f"refine must be 'auto', 'corners' or 'photometric', got {refine!r}")
    return refine


def pose_shift_sigma(a: PoseEstimate, b: PoseEstimate) -> float:
    """Mahalanobis distance between two poses of one board, in combined sigmas.

    d^2 = delta^T (cov_a + cov_b)^-1 delta with delta = (t_b - t_a, rotvec(R_b R_a^T))
    (``docs/conventions.md``, pose uncertainty), with the fits' own covariances
    (``cov_noise``): both poses are taken with the same camera (or rig: ``board2frame``), so
    its calibration's error moves them alike.
    """
    d = np.empty(6)
    d[:3] = b.board2frame[:3, 3] - a.board2frame[:3, 3]
    # OpenCV's logarithm, kept rather than geometry.rotvec_from_matrix: it reads rotations
    # below 1e-5 rad as zero (and is less precise just above), so the other would move this
    # check's verdict in edge cases.
    rv, _ = cv2.Rodrigues(b.board2frame[:3, :3] @ a.board2frame[:3, :3].T)
    d[3:] = rv.ravel()
    C = a.cov_noise + b.cov_noise
    try:
        return float(np.sqrt(max(d @ np.linalg.solve(C, d), 0.0)))
    except np.linalg.LinAlgError:
        return float("inf")


# Longer than ~80 lines for its interface: 10 keyword settings and their documentation take ~60
# lines; the body (~25 lines) chooses the refinement and hands over to the helpers below.
def estimate_pose(
    detection: BoardDetection,
    board: Board,
    camera: CameraModel,
    *,
    initial: np.ndarray | None = None,
    max_iter: int = 20,
    source: str | None = None,
    image: np.ndarray | None = None,
    refine: str = "auto",
    exclude=(),
    max_shift_sigma: float = MAX_REFINE_SHIFT_SIGMA,
    track: PhotometricTrack | None = None,
    square_mm: float | None = None,
) -> BoardPose:
    """Pose of a detected board in the camera frame, with its covariance.

    Parameters
    ----------
    detection : BoardDetection
    board : Chessboard or CharucoBoard
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (:func:`~stiffmap.targets.as_board`).
        The board the detection is of (checked against ``detection.board``).
    camera : CameraModel
    initial : ndarray, shape (4, 4), optional
        Starting pose (e.g. the previous image's); default OpenCV's IPPE.
    max_iter : int
        Largest number of Gauss-Newton iterations (corner fit).
    source : str, optional
        Image name for error messages.
    image : ndarray, shape (h, w), uint8, optional
        The image the corners were detected in (needed by the photometric refinement).
    refine : {"auto", "corners", "photometric"}
        ``"corners"``: the reprojection fit of the corners. ``"photometric"``: that pose
        refined by :func:`~stiffmap.vision.photometric.refine_pose_photometric`; when the
        photometric fit fails or lands more than ``max_shift_sigma`` combined sigmas from
        the corner pose, the corner pose is returned with ``fallback`` saying why (also
        for ChArUco boards, which the photometric model does not describe, and when no
        ``image`` is given). ``"auto"`` (default): photometric for a chessboard when
        ``image`` is given, corners otherwise.
    exclude : sequence of array_like, shape (k, 2)
        Polygons (px) the photometric fit leaves out (another board).
    max_shift_sigma : float
        Consistency check of the photometric pose against the corner pose (Mahalanobis
        distance over the six pose parameters with both covariances).
    track : PhotometricTrack, optional
        The board's photometric fit in the previous image of a sequence (a warm start for
        this one; updated, and cleared when the photometric pose is not kept).

    Returns
    -------
    BoardPose
        ``method`` says which refinement gave it; ``cov`` includes the calibration's share
        (``cov_calibration``, with the sensitivity ``calibration_jacobian``).

    Raises
    ------
    DetectionError
        Fewer than 4 corners, or a degenerate layout.
    """
    board = as_board(board, square_mm, "board")
    check_refine(refine)
    corner_only = refine == "corners" or (
        refine == "auto" and (image is None or not isinstance(board, Chessboard))
    )
    bare = _corner_pose(detection, board, camera, initial=initial, max_iter=max_iter, source=source)
    if corner_only:
        return with_calibration_share(bare, detection, camera)

    def kept(reason: str) -> BoardPose:
        # The corner pose's calibration share only when it is the answer (a fallback).
        return replace(with_calibration_share(bare, detection, camera), fallback=reason)

    refused = _not_photometric(image, board, bare)
    if refused is not None:
        return kept(refused)
    photo, why = _whole_or_inner(
        image, board, camera, bare, detection, exclude, source, track, max_shift_sigma
    )
    if photo is None:
        if track is not None:
            track.clear()
        return kept(f"{why}; corner pose kept")
    return _photometric_with_share(photo, bare, detection, camera, board, track)


def _not_photometric(image, board, bare: BoardPose) -> str | None:
    """Why the photometric refinement is not tried (None: it is)."""
    if image is None:
        return "photometric refinement needs the image; corner pose kept"
    if not isinstance(board, Chessboard):
        return "ChArUco boards are not modelled photometrically; corner pose kept"
    if not faces_camera(bare.board2cam):
        return (
            "the corner pose shows the board from behind (its z axis towards the camera: a wrong "
            "camera model?); corner pose kept"
        )
    return None


def _whole_or_inner(image, board, camera, bare, detection, exclude, source, track, max_shift_sigma):
    """The photometric pose of the whole board, else of its inner squares (then kept for the
    track's next fits), or None and why the whole board's fit failed."""
    inner = track is not None and track.inner_only
    photo, why = _photometric(
        image, board, camera, bare, detection, exclude, source, track, inner, max_shift_sigma
    )
    if photo is None and not inner:
        # The whole board's model assumes full outer squares on a white margin: a printed board
        # cut short or framed otherwise fits only its inner squares, which every chessboard has.
        photo, _ = _photometric(
            image, board, camera, bare, detection, exclude, source, track, True, max_shift_sigma
        )
        if photo is not None and track is not None:
            track.inner_only = True
        why = why if photo is None else None
    return photo, why


def _photometric_with_share(photo, bare, detection, camera, board, track) -> BoardPose:
    """The photometric pose with the corner pose's noise covariance in its fit and its
    calibration share (the sensitivity reused from the track while the board barely moves)."""
    if photo.photometric is not None:
        photo = replace(photo, photometric=replace(photo.photometric, corner_cov=bare.cov_noise))
    A = track.sensitivity(camera, board, photo.board2cam) if track is not None else None
    out = with_calibration_share(photo, detection, camera, edges_of=board, sensitivity=A)
    if track is not None and A is None:
        track.keep_sensitivity(photo.board2cam, out.calibration_jacobian, camera, board)
    return out


def _photometric(image, board, camera, bare, detection, exclude, source, track, inner, max_shift_sigma):
    """The photometric pose (None and why not when it fails or is too far from the corner pose)."""
    try:
        photo = refine_pose_photometric(
            image,
            board,
            camera,
            bare.board2cam,
            detection=detection,
            exclude=exclude,
            source=source,
            track=track,
            inner_only=inner,
        )
    except PhotometricError as e:
        return None, e.detail
    # The corner pose with its realistic noise (its errors' correlation: corner_noise_factor).
    corners = replace(bare, cov=bare.cov + (corner_noise_factor(bare.residuals_px) - 1.0) * bare.cov_noise)
    shift = pose_shift_sigma(corners, photo)
    if not shift <= max_shift_sigma:
        return (
            None,
            f"photometric pose {shift:.1f} sigma from the corner pose (more than {max_shift_sigma:g})",
        )
    return photo, None


def follow_pose(
    image: np.ndarray,
    board: Chessboard,
    camera: CameraModel,
    previous: np.ndarray,
    track: PhotometricTrack,
    *,
    exclude=(),
    source: str | None = None,
) -> BoardPose:
    """The board's photometric pose from the previous image's fit alone, no corners measured.

    In a sequence of one robot position, where the board barely moves: the photometric fit
    starts from the previous image's pose, pixel set and linearisation (``track``,
    :func:`~stiffmap.vision.photometric.refine_pose_photometric` with ``warm_only``). It is
    kept only when it passes the photometric fit's own checks (converged, blur, outliers,
    contrast), the board's outline moved by less than
    :data:`~stiffmap.vision.photometric.refine.FOLLOW_PX` px and its residuals did not grow
    (a board that moved far, by a square or more, or a changed scene fails these); the caller
    then measures the corners (:func:`~stiffmap.vision.tracking.track_board`) and runs
    :func:`estimate_pose`. The pose has no corner residuals: ``n_corners`` 0, ``rms_px`` NaN.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8 or uint16
    board : Chessboard
    camera : CameraModel
    previous : ndarray, shape (4, 4), mm
        The board's photometric pose in the previous image (the start).
    track : PhotometricTrack
        The board's fit in the previous image (updated when the fit is kept).
    exclude : sequence of array_like, shape (k, 2)
        Polygons (px) the fit leaves out (another board).
    source : str, optional
        Image name for error messages.

    Returns
    -------
    BoardPose
        As :func:`estimate_pose`'s photometric pose, with the calibration's share.

    Raises
    ------
    PhotometricError
        No warm start, or it failed one of the checks above (``track`` unchanged).
    """
    photo = refine_pose_photometric(
        image,
        board,
        camera,
        previous,
        exclude=exclude,
        source=source,
        track=track,
        warm_only=True,
        inner_only=track.inner_only,
    )
    A = track.sensitivity(camera, board, photo.board2cam)
    out = with_calibration_share(photo, None, camera, edges_of=board, sensitivity=A)
    if A is None:
        track.keep_sensitivity(photo.board2cam, out.calibration_jacobian, camera, board)
    return out


def _edge_samples(board: Chessboard, per_square: int = 8):
    """Points along the edges of a board's squares (cached per board geometry), see _edge_samples_of."""
    return _edge_samples_of(board.square_mm, board.cols, board.rows, per_square)


@functools.lru_cache(maxsize=32)
def _edge_samples_of(s: float, c: int, r: int, per_square: int):
    """Points along the edges of a chessboard's squares (outer squares included), board frame.

    Returns (points (m, 3) mm, tangents (m, 3), weights (m,)): the border's edges at half
    weight (only the black squares' half of it is an edge).
    """
    f = (np.arange(per_square) + 0.5) / per_square
    pts, tan, wt = [], [], []
    for i in range(-1, c + 1):  # lines x = i s, y from -s to r s
        y = (np.arange(-1, r)[:, None] + f[None, :]).ravel() * s
        pts.append(np.c_[np.full_like(y, i * s), y, np.zeros_like(y)])
        tan.append(np.tile([0.0, 1.0, 0.0], (y.size, 1)))
        wt.append(np.full(y.size, 0.5 if i in (-1, c) else 1.0))
    for j in range(-1, r + 1):
        x = (np.arange(-1, c)[:, None] + f[None, :]).ravel() * s
        pts.append(np.c_[x, np.full_like(x, j * s), np.zeros_like(x)])
        tan.append(np.tile([1.0, 0.0, 0.0], (x.size, 1)))
        wt.append(np.full(x.size, 0.5 if j in (-1, r) else 1.0))
    out = np.concatenate(pts), np.concatenate(tan), np.concatenate(wt)
    for a in out:
        a.flags.writeable = False
    return out


def with_calibration_share(
    pose: BoardPose,
    detection: BoardDetection | None,
    camera: CameraModel,
    *,
    edges_of: Chessboard | None = None,
    sensitivity: np.ndarray | None = None,
) -> BoardPose:
    """``pose`` with the camera calibration's sensitivity and share of the covariance added.

    A = :func:`~stiffmap.posemath.calibration_sensitivity` at the pose: over the detected
    corners (a corner fit), or over the edges of the squares of ``edges_of`` (a photometric
    fit). With the camera's ``calibration_cov`` Sigma_c, cov_calibration = A Sigma_c A^T is
    added to ``cov`` (nothing added, ``cov_calibration`` None, when it is unknown).
    ``sensitivity``: A already known (the same board at nearly the same pose, see
    :meth:`~stiffmap.vision.photometric.PhotometricTrack.sensitivity`).
    """
    if sensitivity is not None:
        A = sensitivity
    elif edges_of is None:
        A = calibration_sensitivity(pose.board2cam, detection.object_points(), camera)
    else:
        q, tg, w = _edge_samples(edges_of)
        A = calibration_sensitivity(pose.board2cam, q, camera, weights=w, tangents=tg)
    Sc = camera.calibration_cov
    if Sc is None:
        return replace(pose, calibration_jacobian=A, cov_calibration=None)
    Cc = A @ Sc @ A.T
    Cc = 0.5 * (Cc + Cc.T)
    return replace(pose, cov=pose.cov_noise + Cc, calibration_jacobian=A, cov_calibration=Cc)


def _check_corners(detection: BoardDetection, board: Board, source) -> int:
    """The detection's number of corners, checked: of this board, enough for a pose."""
    if grid_of(detection.board) != grid_of(board):
        raise ValueError(
            f"detection is of a {board_label(detection.board)}, "
            f"but the pose was asked for a {board_label(board)}"
        )
    m = detection.n_corners
    if m < MIN_POSE_CORNERS:
        raise DetectionError(
            f"{board_label(board)}: {m} corners are too few for a pose (at least {MIN_POSE_CORNERS})",
            source=source,
            reason="partial",
        )
    return m


def _start_pose(camera, obj, uv_obs, initial, board, source) -> np.ndarray:
    """The fit's starting pose: ``initial`` when given, else OpenCV's IPPE."""
    if initial is not None:
        return check_pose(initial, "initial")
    ok, rvec, tvec = solve_pnp(camera, obj, uv_obs, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise DetectionError(
            f"{board_label(board)}: no pose fits the corners", source=source, reason="partial"
        )
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotvec(rvec.ravel())
    T[:3, 3] = tvec.ravel()
    return T


def _fit_corners(T, obj, uv_obs, camera, max_iter, board, source):
    """Gauss-Newton on the corners' reprojection error from T: (T, uv, J, iterations), stopped
    before a step that would put points behind the camera or raise the error."""
    uv, J = projection_jacobian(T, obj, camera, validate=False)
    e = (uv - uv_obs).reshape(-1)
    cost = float(e @ e)
    it = 0
    while it < max_iter:
        it += 1
        Jf = J.reshape(-1, 6)
        try:
            delta = -np.linalg.solve(Jf.T @ Jf, Jf.T @ e)
        except np.linalg.LinAlgError:
            raise DetectionError(
                f"{board_label(board)}: the pose is undetermined (degenerate corner layout)",
                source=source,
                reason="partial",
            ) from None
        T_new = perturb_pose(T, delta)
        if np.any((obj @ T_new[:3, :3].T + T_new[:3, 3])[:, 2] <= 0):
            break
        uv_new, J_new = projection_jacobian(T_new, obj, camera, validate=False)
        e_new = (uv_new - uv_obs).reshape(-1)
        cost_new = float(e_new @ e_new)
        if cost_new > cost * (1 + 1e-12) + 1e-18:
            break
        T, uv, J, e, cost = T_new, uv_new, J_new, e_new, cost_new
        if np.abs(delta[:3]).max() < 1e-9 * max(1.0, abs(T[2, 3])) and np.abs(delta[3:]).max() < 1e-12:
            break
    return T, uv, J, it


def _corner_pose(
    detection: BoardDetection,
    board: Board,
    camera: CameraModel,
    *,
    initial: np.ndarray | None,
    max_iter: int,
    source: str | None,
) -> BoardPose:
    """The corner-based pose (reprojection fit), see :func:`estimate_pose`."""
    m = _check_corners(detection, board, source)
    obj = detection.object_points()
    uv_obs = np.asarray(detection.corners, dtype=np.float64)
    T = _start_pose(camera, obj, uv_obs, initial, board, source)
    T, uv, J, it = _fit_corners(T, obj, uv_obs, camera, max_iter, board, source)
    res = uv_obs - uv
    Jf = J.reshape(-1, 6)
    JtJ = Jf.T @ Jf
    dof = 2 * m - 6
    s2 = float(np.sum(res**2) / dof) if dof > 0 else float("nan")
    try:
        cov = s2 * np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:  # pragma: no cover - caught in the iterations
        raise DetectionError(f"{board_label(board)}: the pose is undetermined", source=source) from None
    cov = 0.5 * (cov + cov.T)
    # Condition with rotations expressed as lateral motions at the board's distance.
    D = np.diag([1.0, 1.0, 1.0] + [max(abs(T[2, 3]), 1.0)] * 3)
    Ds = np.linalg.inv(D)
    condition = float(np.linalg.cond(Ds @ JtJ @ Ds))
    # Re-orthonormalise the rotation (numerical drift from repeated products).
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T[:3, :3] = U @ Vt
    pose = BoardPose(
        board2cam=T,
        cov=cov,
        rms_px=float(np.sqrt(np.mean(np.sum(res**2, axis=1)))),
        n_corners=m,
        residuals_px=res,
        sigma_px=float(np.sqrt(s2)) if np.isfinite(s2) else float("nan"),
        condition=condition,
        iterations=it,
    )
    return pose
