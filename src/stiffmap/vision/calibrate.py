"""Camera calibration from views of a planar board (Zhang's method through OpenCV).

:func:`calibrate_camera` takes the board detections of several views, runs
OpenCV's ``calibrateCameraExtended`` (Zhang's closed form, then Levenberg-
Marquardt over intrinsics, distortion and every view's pose) and returns a
:class:`CalibrationResult`: the :class:`~stiffmap.camera.CameraModel` with the
1-sigma standard deviation of each parameter (from the Jacobian at the optimum
and the residual variance), the reprojection RMS, the residual standard
deviation per axis and the RMS of every view. Views whose RMS exceeds
``outlier_factor`` times the median (and ``outlier_min_px``) are left out one at
a time, worst first, with the reason recorded.

The full covariance of the intrinsics and distortion (:func:`calibration_covariance`,
``camera.cov``): OpenCV gives only their standard deviations, so it is computed here from the
reprojection Jacobian of every used view (``cv2.projectPoints``), each view's pose eliminated
by its Schur complement, times the residual variance sum e^2 / (2 N - p) (N corners, p free
parameters with 6 per view): its diagonal is OpenCV's ``stdDeviationsIntrinsics`` squared
(to 1e-8 on Bouguet's views, k3 and fix-k3 models). For the rational and thin-prism models,
whose coefficients the views often determine only in combination, OpenCV's pseudo-inverse
drops the undetermined directions; this covariance keeps them (large variances of k4..k6
along directions that move no corner of the calibrated field, so harmless for a pose).

A fisheye or strong wide-angle lens (``model="fisheye"``: OpenCV's fisheye model,
:mod:`stiffmap.lens`) is calibrated by OpenCV's ``fisheye.calibrate`` (the same least squares
over intrinsics, the four coefficients and every view's pose, skew held at zero); its
standard deviations and covariance come from :func:`model_calibration_covariance`, the same
Schur complement computed from stiffmap's own NumPy Jacobians of the camera model (which
give the pinhole models' covariance to 1e-6 too), and its views' residuals from the NumPy
projection. OpenCV's optimum is the model's: Gauss-Newton steps of the NumPy model from it
move no parameter by more than 1e-9 (on the udacity set).

:meth:`CalibrationResult.matlab_text` prints the result the way the Camera
Calibration Toolbox for Matlab does (values +/- three standard deviations), so
its users can compare.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import CameraModel, invertible_field
from ..errors import InputError
from ..geometry import matrix_from_rotvec
from ..posemath import projection_jacobian
from ..targets import as_board
from .detection import Board, BoardDetection, grid_of
from .pnp import solve_pnp

__all__ = [
    "ViewResult",
    "CalibrationResult",
    "calibrate_camera",
    "calibration_covariance",
    "covariance_from_information",
    "lens_model",
    "model_calibration_covariance",
    "fisheye_advice",
    "calibration_problems",
    "fixed_params",
    "grouped_reasons",
    "matlab_camera_lines",
    "usable_views",
    "DIST_MODELS",
    "MATLAB_NOTE",
]

#: Distortion models: name -> number of coefficients. ``fisheye`` is OpenCV's fisheye model
#: (camera.json's ``model`` ``"fisheye"``); the others are the pinhole polynomial's variants.
DIST_MODELS = {"k3": 5, "fix-k3": 5, "rational": 8, "thin-prism": 12, "fisheye": 4}


def lens_model(model: str) -> str:
    """The camera's lens model (:data:`stiffmap.camera.LENS_MODELS`) of a distortion model."""
    return "fisheye" if model == "fisheye" else "opencv"


_MIN_VIEW_CORNERS = 6


@dataclass(frozen=True)
class ViewResult:
    """One calibration image.

    Attributes
    ----------
    image : str
    used : bool
    rms_px : float
        Reprojection RMS of the view with the final camera (NaN when it had no
        detection).
    reason : str
        Why it was not used ("" when used).
    n_corners : int
    board2cam : ndarray, shape (4, 4) or None
        The view's pose (used views).
    corners_px : ndarray, shape (k, 2), px, or None
        The corners found in the view (where the views put corners: the report's coverage map).
    residuals_px : ndarray, shape (k, 2), px, or None
        Their reprojection residuals (observed - projected) with the final camera.
    """

    image: str
    used: bool
    rms_px: float
    reason: str
    n_corners: int = 0
    board2cam: np.ndarray | None = None
    corners_px: np.ndarray | None = None
    residuals_px: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The ``camera.json`` ``views`` entry (corners rounded to 1e-3 px, residuals to 1e-4 px)."""
        d = {
            "image": self.image,
            "used": self.used,
            "rms_px": None if not math.isfinite(self.rms_px) else self.rms_px,
            "reason": self.reason,
        }
        if self.corners_px is not None and self.residuals_px is not None:
            d["corners_px"] = np.round(self.corners_px, 3).tolist()
            d["residuals_px"] = np.round(self.residuals_px, 4).tolist()
        return d


@dataclass(frozen=True)
class CalibrationResult:
    """Result of :func:`calibrate_camera`.

    Attributes
    ----------
    camera : CameraModel
        With ``std`` (OpenCV's), ``cov`` (:func:`calibration_covariance`), ``rms_px``,
        ``residual_std_px`` and ``views`` filled.
    views : tuple of ViewResult
    residuals_px : ndarray, shape (N, 2)
        Observed minus projected corners of the used views, px.
    model : str
        Distortion model (a key of :data:`DIST_MODELS`).
    n_used : int
    lens_advice : str
        When the polynomial model is not one to one over the whole image and OpenCV's
        fisheye model, fitted to the same views, covers more of it: one sentence saying so,
        with both RMS (:func:`fisheye_advice`); else "".
    problems : tuple of (str, str)
        What makes the calibration suspect beyond camera.json's checks
        (:func:`calibration_problems`): (key, message) pairs, empty when none.
    """

    camera: CameraModel
    views: tuple[ViewResult, ...]
    residuals_px: np.ndarray
    model: str
    n_used: int
    lens_advice: str = ""
    problems: tuple[tuple[str, str], ...] = ()

    def to_dict(self) -> dict:
        """The ``camera.json`` object."""
        return self.camera.to_dict()

    def matlab_text(self) -> str:
        """The result as the Camera Calibration Toolbox for Matlab prints it (+/- 3 sigma)."""
        return "\n".join(
            [
                "Calibration results after optimization (with uncertainties):",
                "",
                *matlab_camera_lines(self.camera),
                "",
                MATLAB_NOTE,
            ]
        )


#: The last line of the Matlab toolbox's printout.
MATLAB_NOTE = (
    "Note: The numerical errors are approximately three times the standard deviations (for reference)."
)


def matlab_camera_lines(camera: CameraModel, suffix: str = "") -> list[str]:
    """A camera's intrinsics as the Camera Calibration Toolbox for Matlab prints them (+/- 3 sigma).

    Parameters
    ----------
    camera : CameraModel
        Its ``std`` gives the +/- (0 where unknown), its ``residual_std_px`` the pixel error.
    suffix : str
        Appended to the toolbox's names (``fc_left``...), as its stereo printout does.

    Returns
    -------
    list of str
        The lines ``Focal Length: fc = [...]`` to ``Pixel error: err = [...]``.
    """
    c = camera
    s = c.std or {}
    sd = list(s.get("dist", [0.0] * len(c.dist)))

    def f(x: float) -> str:
        return f"{x:.5f}"

    def label(title: str, name: str) -> str:
        # The toolbox right-aligns its names at column 25 (plus the suffix).
        name += suffix
        return title + " " * max(1, 25 + len(suffix) - len(title) - len(name)) + name

    # The toolbox's fisheye mode prints its four theta coefficients as kc.
    n_kc = 4 if c.model == "fisheye" else 5
    kc = list(c.dist[:n_kc]) + [0.0] * (n_kc - min(n_kc, len(c.dist)))
    skc = (sd[:n_kc] + [0.0] * n_kc)[:n_kc]
    rs = c.residual_std_px or (float("nan"), float("nan"))
    lines = [
        f"{label('Focal Length:', 'fc')} = [ {f(c.fx)}   {f(c.fy)} ] +/- "
        f"[ {f(3 * s.get('fx', 0))}   {f(3 * s.get('fy', 0))} ]",
        f"{label('Principal point:', 'cc')} = [ {f(c.cx)}   {f(c.cy)} ] +/- "
        f"[ {f(3 * s.get('cx', 0))}   {f(3 * s.get('cy', 0))} ]",
        f"{label('Skew:', 'alpha_c')} = [ 0.00000 ] +/- [ 0.00000  ]   "
        "=> angle of pixel axes = 90.00000 +/- 0.00000 degrees",
        f"{label('Distortion:', 'kc')} = [ "
        + "   ".join(f(k) for k in kc)
        + " ] +/- [ "
        + "   ".join(f(3 * k) for k in skc)
        + " ]",
        f"{label('Pixel error:', 'err')} = [ {f(rs[0])}   {f(rs[1])} ]",
    ]
    if c.model != "fisheye" and len(c.dist) > 5:
        lines.insert(
            4,
            "Higher-order terms (k4, k5, k6[, s1..s4]) = [ "
            + "   ".join(f(k) for k in c.dist[5:])
            + " ] +/- [ "
            + "   ".join(f(3 * k) for k in sd[5:])
            + " ]",
        )
    return lines


def _flags(model: str) -> int:
    if model == "k3":
        return 0
    if model == "fix-k3":
        return cv2.CALIB_FIX_K3
    if model == "rational":
        return cv2.CALIB_RATIONAL_MODEL
    if model == "thin-prism":
        return cv2.CALIB_RATIONAL_MODEL | cv2.CALIB_THIN_PRISM_MODEL
    raise ValueError(f"model must be one of {sorted(DIST_MODELS)}, got {model!r}")


def _fisheye_flag(name: str) -> int:
    """An OpenCV fisheye calibration flag (``cv2.fisheye.X`` before OpenCV 5, ``cv2.X`` since)."""
    return int(getattr(cv2.fisheye, name, None) or getattr(cv2, name))


def _run_fisheye(obj, img, image_size):
    """``cv2.fisheye.calibrate`` (skew fixed at 0) and the views' RMS, as :func:`_run` returns them.

    The 1 sigma are NaN here: :func:`calibrate_camera` takes them from the covariance
    (:func:`model_calibration_covariance`, on the corners in float64).
    """
    flags = _fisheye_flag("CALIB_RECOMPUTE_EXTRINSIC") | _fisheye_flag("CALIB_FIX_SKEW")
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    o = [np.asarray(x, dtype=np.float64).reshape(1, -1, 3) for x in obj]
    i = [np.asarray(x, dtype=np.float64).reshape(1, -1, 2) for x in img]
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
            o, i, image_size, np.eye(3), np.zeros(4), flags=flags, criteria=crit
        )
    except cv2.error as e:
        raise InputError(
            "OpenCV's fisheye calibration failed on these views "
            f"({str(e).strip().splitlines()[-1][:160]}): more views, or views that fill more of the image?"
        ) from None
    finally:
        cv2.setNumThreads(threads)
    dist = np.asarray(D, dtype=np.float64).ravel()[:4]
    cam = CameraModel(image_size, K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(dist), model="fisheye")
    poses = [_pose_matrix(rv, tv) for rv, tv in zip(rvecs, tvecs, strict=True)]
    per_view = np.array([_view_rms(cam, q, uv, T) for q, uv, T in zip(obj, img, poses, strict=True)])
    return K, dist, rvecs, tvecs, np.full(8, np.nan), per_view


def _pose_matrix(rv, tv) -> np.ndarray:
    """board2cam (4x4) of OpenCV's rotation and translation vectors."""
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotvec(np.asarray(rv, dtype=np.float64).ravel())
    T[:3, 3] = np.asarray(tv, dtype=np.float64).ravel()
    return T


def _view_rms(camera: CameraModel, object_points, corners, board2cam) -> float:
    """Reprojection RMS of a view with the NumPy camera model, px."""
    q = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(corners, dtype=np.float64).reshape(-1, 2) - camera.project(
        q @ board2cam[:3, :3].T + board2cam[:3, 3]
    )
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def _run(obj, img, image_size, model):
    if model == "fisheye":
        return _run_fisheye(obj, img, image_size)
    nd = DIST_MODELS[model]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    # On one thread: OpenCV's parallel sums make the result differ in the last digits from
    # run to run (1e-10 of fx), and the same views must give the same camera.json.
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        rms, K, dist, rvecs, tvecs, sd_int, _sd_ext, per_view = cv2.calibrateCameraExtended(
            obj, img, image_size, None, np.zeros(nd), flags=_flags(model), criteria=crit
        )
    finally:
        cv2.setNumThreads(threads)
    return K, np.asarray(dist, dtype=np.float64).ravel()[:nd], rvecs, tvecs, sd_int.ravel(), per_view.ravel()


def fixed_params(model: str) -> tuple[int, ...]:
    """Indices (in the camera's parameter order) the model holds fixed."""
    return (8,) if model == "fix-k3" else ()


def model_calibration_covariance(
    camera: CameraModel, object_points, image_points, board2cams, fixed=()
) -> np.ndarray:
    """:func:`calibration_covariance` from stiffmap's own Jacobians of the camera model (any lens).

    Parameters
    ----------
    camera : CameraModel
        The calibrated camera (its :attr:`~stiffmap.camera.CameraModel.param_names`).
    object_points, image_points : sequence of ndarray, shapes (m_v, 3) mm and (m_v, 2) px
        The used views' board points and detected corners.
    board2cams : sequence of ndarray, shape (4, 4)
        The views' poses, mm.
    fixed : sequence of int
        Indices of parameters held fixed (0 variance).

    Returns
    -------
    ndarray, shape (n, n)
        Over :attr:`~stiffmap.camera.CameraModel.param_names` (px and unitless).

    Notes
    -----
    J_c is :meth:`~stiffmap.camera.CameraModel.projection_param_jacobian`, J_e the pose's
    :func:`~stiffmap.posemath.projection_jacobian` (a perturbation (t, r) instead of OpenCV's
    rotation vector: the Schur complement does not depend on how the pose is parametrised).
    """
    n = len(camera.param_names)
    S = np.zeros((n, n))
    sse = 0.0
    n_res = 0
    for q, uv, T in zip(object_points, image_points, board2cams, strict=True):
        q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
        uv_p, Jp = projection_jacobian(T, q, camera, validate=False)
        X = q @ T[:3, :3].T + T[:3, 3]
        Jc = camera.projection_param_jacobian(X[:, :2] / X[:, 2:3]).reshape(-1, n)
        Je = Jp.reshape(-1, 6)
        e = np.asarray(uv, dtype=np.float64).reshape(-1, 2) - uv_p
        sse += float(np.sum(e**2))
        n_res += e.size
        S += Jc.T @ Jc - Jc.T @ Je @ np.linalg.solve(Je.T @ Je, Je.T @ Jc)
    free = [i for i in range(n) if i not in set(fixed)]
    dof = n_res - len(free) - 6 * len(board2cams)
    s2 = sse / dof if dof > 0 else float("nan")
    return covariance_from_information(S, s2, free)


def calibration_covariance(object_points, image_points, camera_matrix, dist, rvecs, tvecs, fixed=()):
    """Covariance of the intrinsics and distortion of a calibration, with the views' poses eliminated.

    Parameters
    ----------
    object_points, image_points : sequence of ndarray, shapes (m_v, 3) mm and (m_v, 2) px
        The used views' board points and detected corners.
    camera_matrix : ndarray, shape (3, 3)
    dist : ndarray, shape (n_d,)
    rvecs, tvecs : sequence of ndarray, shape (3,)
        The views' poses (OpenCV's).
    fixed : sequence of int
        Indices of parameters held fixed (0 variance).

    Returns
    -------
    cov : ndarray, shape (4 + n_d, 4 + n_d)
        Over (fx, fy, cx, cy, dist...) (px and unitless).

    Notes
    -----
    With J_c, J_e the per-view Jacobians of the corners (px) with respect to the camera
    parameters c and the view's pose e, the information of c is
    S = sum_v J_c^T J_c - J_c^T J_e (J_e^T J_e)^-1 J_e^T J_c (the Schur complement of the
    poses), and cov = s^2 S^-1 with s^2 = sum e^2 / (2 N - p), p = free parameters of c plus
    6 per view. S is inverted after scaling to unit diagonal (it spans px and unitless terms).
    """
    dist = np.asarray(dist, dtype=np.float64).ravel()
    n = 4 + dist.size
    S = np.zeros((n, n))
    sse = 0.0
    n_res = 0
    for o, im, rv, tv in zip(object_points, image_points, rvecs, tvecs, strict=True):
        o = np.asarray(o, dtype=np.float64).reshape(-1, 3)
        p, J = cv2.projectPoints(
            o, np.asarray(rv, np.float64), np.asarray(tv, np.float64), camera_matrix, dist
        )
        e = np.asarray(im, dtype=np.float64).reshape(-1, 2) - p.reshape(-1, 2)
        sse += float(np.sum(e**2))
        n_res += e.size
        Je, Jc = J[:, :6], J[:, 6 : 6 + n]
        S += Jc.T @ Jc - Jc.T @ Je @ np.linalg.solve(Je.T @ Je, Je.T @ Jc)
    free = [i for i in range(n) if i not in set(fixed)]
    dof = n_res - len(free) - 6 * len(rvecs)
    s2 = sse / dof if dof > 0 else float("nan")
    return covariance_from_information(S, s2, free)


#: Least eigenvalue of the unit-diagonal information matrix, as a share of its largest, that
#: :func:`covariance_from_information` inverts as it is (double precision's rounding of J^T J).
EIGEN_FLOOR = 1e-15


def covariance_from_information(S: np.ndarray, s2: float, free) -> np.ndarray:
    """s^2 S^-1 over the free parameters (zero rows and columns for the fixed ones).

    Parameters
    ----------
    S : ndarray, shape (n, n)
        Information matrix J^T J (nuisance parameters eliminated), of parameters of mixed
        units: inverted after scaling to unit diagonal, its eigenvalues floored (see Notes).
    s2 : float
        Residual variance, px^2.
    free : sequence of int
        Indices of the free parameters.

    Returns
    -------
    ndarray, shape (n, n), symmetric, positive semi-definite

    Notes
    -----
    J^T J has no negative eigenvalue, but the one computed (with each view's pose eliminated)
    can: the rational model's k1..k6 on Bouguet's views, which the views determine only in
    combination, gave the scaled matrix eigenvalues -4e-12 and 8e-11 (largest 8.3), and a
    pseudo-inverse then gave k2 a variance of -1.15 and k5 -0.95. Eigenvalues below the
    computation's rounding noise -- twice the most negative one, and at least
    :data:`EIGEN_FLOOR` times the largest -- are raised to it: a direction the data leave
    undetermined gets the large variance that noise allows (finite, positive), rather than a
    negative one, an infinite one or none (a pseudo-inverse's zero).
    """
    free = list(free)
    n = S.shape[0]
    Sf = S[np.ix_(free, free)]
    d = np.sqrt(np.maximum(np.diag(Sf), 0.0))
    d = np.where(d > 0, d, 1.0)  # a parameter that moves no corner: undetermined, floored below
    A = Sf / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (A + A.T))
    w = np.maximum(w, max(EIGEN_FLOOR * w[-1], -2.0 * w[0]))
    inv = (V / w) @ V.T / np.outer(d, d)
    C = np.zeros((n, n))
    C[np.ix_(free, free)] = s2 * inv
    return 0.5 * (C + C.T)


def grouped_reasons(names: Sequence[str], reasons: Sequence[str], shown: int = 3) -> list[str]:
    """Images that share a reason, as one line per reason: ``"a.png, b.png (2 images): why"``.

    Parameters
    ----------
    names, reasons : sequence of str
        One per image; an empty reason is left out.
    shown : int
        Names written out per reason (the others counted: ``"a.png, b.png ... (16 images)"``).

    Returns
    -------
    list of str
        In the order each reason first occurs.
    """
    groups: dict[str, list[str]] = {}
    for n, r in zip(names, reasons, strict=True):
        if r:
            groups.setdefault(r, []).append(n)
    out = []
    for r, ns in groups.items():
        if len(ns) == 1:
            out.append(f"{ns[0]}: {r}")
            continue
        head = ", ".join(ns[:shown]) + (f" ... {ns[-1]}" if len(ns) > shown else "")
        out.append(f"{head} ({len(ns)} images): {r}")
    return out


def usable_views(detections: Sequence[BoardDetection | str], board: Board) -> tuple[list[str], list[int]]:
    """Which views can enter a calibration, and why the others cannot.

    A view is usable when it has a detection of ``board``'s grid with at least 6 corners.

    Returns
    -------
    reasons : list of str
        Per view, "" when usable, else why not (a string given instead of a detection is
        the reason).
    usable : list of int
        Indices of the usable views.
    """
    grid = grid_of(board)
    reasons = [""] * len(detections)
    usable = []
    for k, d in enumerate(detections):
        if isinstance(d, BoardDetection):
            if grid_of(d.board) != grid:
                reasons[k] = f"detection is of a different board ({d.board})"
            elif d.n_corners < _MIN_VIEW_CORNERS:
                reasons[k] = f"only {d.n_corners} corners"
            else:
                usable.append(k)
        else:
            reasons[k] = str(d) or "no detection"
    return reasons, usable


def solve_view_pose(camera: CameraModel, object_points, corners) -> np.ndarray | None:
    """A view's board2cam (4x4, mm) from its corners with a calibrated camera (``cv2.solvePnP``).

    ``object_points`` (m, 3) mm in the board frame, ``corners`` (m, 2) px; None when OpenCV finds
    no pose (a detection always has one), or when a corner has no ray (beyond the lens model's
    field).
    """
    ok, rv, tv = solve_pnp(camera, object_points, corners)
    if not ok:  # pragma: no cover - a detection always has a pose
        return None
    return _pose_matrix(rv, tv)


def with_calibration_results(
    camera: CameraModel, sd: np.ndarray, residuals_px: np.ndarray, views: Sequence[dict], cov: np.ndarray
) -> CameraModel:
    """``camera`` with what ``camera.json`` says of its calibration.

    Parameters
    ----------
    camera : CameraModel
        The calibrated parameters.
    sd : ndarray, shape (4 + n_d,)
        1-sigma of (fx, fy, cx, cy) in px and of the distortion coefficients (unitless).
    residuals_px : ndarray, shape (N, 2)
        Observed minus projected corners of the used views, px (their RMS and per-axis std).
    views : sequence of dict
        The ``views`` entries (:meth:`ViewResult.to_dict`).
    cov : ndarray, shape (4 + n_d, 4 + n_d)
        Covariance of the parameters.
    """
    sd = np.asarray(sd, dtype=np.float64).ravel()
    R = np.asarray(residuals_px, dtype=np.float64)
    std = {
        "fx": float(sd[0]),
        "fy": float(sd[1]),
        "cx": float(sd[2]),
        "cy": float(sd[3]),
        "dist": [float(x) for x in sd[4 : 4 + len(camera.dist)]],
    }
    return CameraModel(
        camera.image_size,
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        camera.dist,
        std=std,
        rms_px=float(np.sqrt(np.mean(np.sum(R**2, axis=1)))),
        residual_std_px=(float(np.std(R[:, 0], ddof=1)), float(np.std(R[:, 1], ddof=1))),
        views=tuple(views),
        cov=cov,
        model=camera.model,
    )


def _view_names(names, n_views: int) -> list[str]:
    names = [f"view{k + 1}" for k in range(n_views)] if names is None else [str(x) for x in names]
    if len(names) != n_views:
        raise ValueError(f"names has {len(names)} entries for {n_views} detections")
    return names


def _enough_views(detections, board, names, min_views: int):
    """:func:`usable_views`' reasons and usable views; too few raise, naming why."""
    reasons, usable = usable_views(detections, board)
    if len(usable) < min_views:
        detail = "; ".join(grouped_reasons(names, reasons))
        raise InputError(
            f"calibration needs at least {min_views} views with the board found, got {len(usable)}"
            + (f" ({detail})" if detail else "")
        )
    return reasons, usable


def _fit_leaving_out_outliers(
    detections, obj_all, usable, reasons, size, model, outlier_factor, outlier_min_px, min_views
):
    """OpenCV's calibration on the usable views, the worst outlier view left out (its reason
    set) and the calibration again, at most a third of the views: the views used and the fit
    (K, dist, rvecs, tvecs, sd_int)."""
    used = list(usable)
    max_out = len(usable) // 3
    while True:
        obj = [obj_all[detections[k].ids].astype(np.float32) for k in used]
        img = [detections[k].corners.astype(np.float32) for k in used]
        K, dist, rvecs, tvecs, sd_int, per_view = _run(obj, img, size, model)
        med = float(np.median(per_view))
        worst = int(np.argmax(per_view))
        limit = max(outlier_factor * med, outlier_min_px)
        if per_view[worst] > limit and len(usable) - len(used) < max_out and len(used) > min_views:
            k = used.pop(worst)
            reasons[k] = (
                f"outlier: view RMS {per_view[worst]:.3f} px > {outlier_factor:g} x median {med:.3f} px"
            )
            continue
        return used, (K, dist, rvecs, tvecs, sd_int)


def _view_results(cam, detections, names, reasons, obj_all, pose_of):
    """Every view's result with the final camera (pose, residuals, RMS), and the residuals of
    the views used (``pose_of``: view -> its fitted (rvec, tvec))."""
    res_used = []
    views = []
    for k in range(len(detections)):
        d = detections[k]
        if not isinstance(d, BoardDetection):
            views.append(ViewResult(names[k], False, float("nan"), reasons[k]))
            continue
        if k in pose_of:
            rv, tv = pose_of[k]
            T = np.eye(4)
            T[:3, :3] = matrix_from_rotvec(np.asarray(rv, dtype=np.float64).ravel())
            T[:3, 3] = np.asarray(tv, dtype=np.float64).ravel()
        else:
            T = solve_view_pose(cam, obj_all[d.ids], d.corners)
            if T is None:  # pragma: no cover - a detection always has a pose
                views.append(ViewResult(names[k], False, float("nan"), reasons[k], d.n_corners))
                continue
            rv, tv = cv2.Rodrigues(T[:3, :3])[0], T[:3, 3]
        e = d.corners - _project_view(cam, obj_all[d.ids], rv, tv)
        rms_v = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
        if k in pose_of:
            res_used.append(e)
        views.append(ViewResult(names[k], k in pose_of, rms_v, reasons[k], d.n_corners, T, d.corners, e))
    return views, res_used


def _intrinsics_covariance(cam, obj, img, fit, model: str):
    """The calibration's covariance and the intrinsics' standard deviations (OpenCV's for its
    own lens model, else from the model's covariance)."""
    K, dist, rvecs, tvecs, sd_int = fit
    if cam.model == "opencv":
        return calibration_covariance(obj, img, K, dist, rvecs, tvecs, fixed_params(model)), sd_int
    poses = [_pose_matrix(rv, tv) for rv, tv in zip(rvecs, tvecs, strict=True)]
    cov = model_calibration_covariance(cam, obj, img, poses, fixed_params(model))
    return cov, np.sqrt(np.maximum(np.diag(cov), 0.0))


# Longer than ~80 lines for its interface: 9 settings and their documentation take ~50 lines;
# the body (~30 lines) checks, fits leaving out outliers, and assembles the result from helpers.
def calibrate_camera(
    detections: Sequence[BoardDetection | str],
    board: Board,
    image_size: tuple[int, int],
    *,
    names: Sequence[str] | None = None,
    model: str = "k3",
    outlier_factor: float = 3.0,
    outlier_min_px: float = 0.3,
    min_views: int = 3,
    square_mm: float | None = None,
) -> CalibrationResult:
    """Calibrate a camera from board detections in several views.

    Parameters
    ----------
    detections : sequence of BoardDetection or str
        One entry per image: its detection, or the reason it has none
        (e.g. the message of the detection error).
    board : Chessboard or CharucoBoard
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (:func:`~stiffmap.targets.as_board`).
    image_size : (int, int)
        [w, h] of the images, px.
    names : sequence of str, optional
        Image names (default ``view1``, ``view2``...).
    model : str
        ``"k3"`` (k1, k2, p1, p2, k3; default), ``"fix-k3"`` (k3 = 0, as the Matlab
        toolbox's default), ``"rational"`` (+ k4, k5, k6), ``"thin-prism"``
        (+ s1..s4), or ``"fisheye"`` (OpenCV's fisheye model, k1..k4 of the angle off axis:
        a fisheye or strong wide-angle lens).
    outlier_factor : float
        A view is an outlier when its RMS exceeds ``outlier_factor`` times the
        median view RMS and ``outlier_min_px``; outliers are left out one at a
        time, worst first (at most a third of the views).
    outlier_min_px : float
        See ``outlier_factor``, px.
    min_views : int
        Fewest usable views.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    InputError
        Fewer than ``min_views`` usable views (the message lists why each failed).
    """
    board = as_board(board, square_mm, "board")
    if model not in DIST_MODELS:
        raise ValueError(f"model must be one of {sorted(DIST_MODELS)}, got {model!r}")
    names = _view_names(names, len(detections))
    w, h = (int(v) for v in image_size)
    grid = grid_of(board)
    reasons, usable = _enough_views(detections, board, names, min_views)
    obj_all = grid.object_points()
    used, fit = _fit_leaving_out_outliers(
        detections, obj_all, usable, reasons, (w, h), model, outlier_factor, outlier_min_px, min_views
    )
    K, dist, rvecs, tvecs, _ = fit
    nd = DIST_MODELS[model]
    cam = CameraModel((w, h), K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(dist), model=lens_model(model))
    # Residuals and per-view RMS of every detected view with the final camera.
    pose_of = {k: (rvecs[i], tvecs[i]) for i, k in enumerate(used)}
    views, res_used = _view_results(cam, detections, names, reasons, obj_all, pose_of)
    R = np.concatenate(res_used)
    obj = [obj_all[detections[k].ids] for k in used]
    img = [detections[k].corners for k in used]
    cov, sd_int = _intrinsics_covariance(cam, obj, img, fit, model)
    camera = with_calibration_results(cam, sd_int[: 4 + nd], R, [v.to_dict() for v in views], cov)
    advice = fisheye_advice(camera, obj, img) if model != "fisheye" else ""
    problems = calibration_problems(camera, [detections[k] for k in used], [views[k].rms_px for k in used])
    return CalibrationResult(
        camera=camera,
        views=tuple(views),
        residuals_px=R,
        model=model,
        n_used=len(used),
        lens_advice=advice,
        problems=problems,
    )


def fisheye_advice(camera: CameraModel, object_points, image_points) -> str:
    """Whether OpenCV's fisheye model would serve a camera whose polynomial folds within the image.

    Parameters
    ----------
    camera : CameraModel
        A calibrated pinhole camera (``model="opencv"``).
    object_points, image_points : sequence of ndarray, shapes (m_v, 3) mm and (m_v, 2) px
        The views it was calibrated from.

    Returns
    -------
    str
        "" when ``camera``'s model is one to one over the whole image, or the fisheye model
        (fitted here to the same views) covers no more of it or cannot be fitted; else one
        sentence with both models' RMS and how much of the image the fisheye model covers.
    """
    share = invertible_field(camera).image_share()
    if camera.model != "opencv" or share >= 1.0:
        return ""
    try:
        K, dist, rvecs, tvecs, _, _ = _run_fisheye(object_points, image_points, camera.image_size)
    except InputError:
        return ""
    fish = CameraModel(camera.image_size, K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(dist), model="fisheye")
    fish_share = invertible_field(fish).image_share()
    if fish_share <= share:
        return ""
    e = np.concatenate(
        [
            np.asarray(uv, dtype=np.float64).reshape(-1, 2) - _project_view(fish, q, rv, tv)
            for q, uv, rv, tv in zip(object_points, image_points, rvecs, tvecs, strict=True)
        ]
    )
    rms = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
    where = "the whole image" if fish_share >= 1.0 else f"{100 * fish_share:.1f} % of the image"
    return (
        f"OpenCV's fisheye model (calibrate --fisheye) fits the same views with RMS {rms:.3f} px "
        f"(this model {camera.rms_px:.3f} px) and is one to one over {where} (this model "
        f"{100 * share:.1f} %)"
    )


def _project_view(camera: CameraModel, object_points, rvec, tvec) -> np.ndarray:
    """Pixels (m, 2) of a view's board points: ``cv2.projectPoints`` for the pinhole models, else NumPy."""
    q = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    if camera.model == "opencv":
        proj, _ = cv2.projectPoints(q, rvec, tvec, camera.matrix, camera.dist_array)
        return proj.reshape(-1, 2)
    T = _pose_matrix(rvec, tvec)
    return camera.project(q @ T[:3, :3].T + T[:3, 3])


#: A calibration is suspect when its median view RMS exceeds this many times the median RMS of
#: the views' corners about a smooth board (the detection's own fit, no camera) ...
VIEW_RMS_FACTOR = 5.0
#: ... and this many px (corner noise and lens-model error stay well below on real cameras:
#: 0.1-0.5 px on the four real sets of ``../shared/data``).
VIEW_RMS_FLOOR_PX = 1.0


def calibration_problems(
    camera: CameraModel, detections: Sequence[BoardDetection], view_rms_px: Sequence[float]
) -> tuple[tuple[str, str], ...]:
    """What makes a calibration suspect although each parameter is plausible.

    - The views fit the camera model far worse than their corners fit a smooth board (median
      view RMS above :data:`VIEW_RMS_FACTOR` times the median of the detections' own
      ``rms_residual_px`` and :data:`VIEW_RMS_FLOOR_PX`): grids that are not the board's
      (a wrong board size), or a camera model that cannot describe the lens.
    - The lens model folds over where the views saw corners (:func:`~stiffmap.camera.invertible_field`):
      it is not one to one in the very field it was fitted to. Beyond the corners it may fold
      (a polynomial extrapolated): poses then use no pixel there, which is said, not flagged.

    Parameters
    ----------
    camera : CameraModel
    detections : sequence of BoardDetection
        The used views' detections.
    view_rms_px : sequence of float
        Their reprojection RMS with ``camera``, px.

    Returns
    -------
    tuple of (key, message)
    """
    out = []
    own = [d.rms_residual_px for d in detections if np.isfinite(d.rms_residual_px)]
    med_view = float(np.median(view_rms_px)) if len(view_rms_px) else float("nan")
    med_own = float(np.median(own)) if own else float("nan")
    if med_view > max(VIEW_RMS_FLOOR_PX, VIEW_RMS_FACTOR * med_own):
        out.append(
            (
                "views",
                f"the views fit the camera model to {med_view:.3g} px (median view RMS) where their "
                f"corners fit a smooth board to {med_own:.3g} px: these grids are not what the model "
                "describes (a wrong board size, mis-detected corners, or a lens this model cannot follow)",
            )
        )
    corners = np.concatenate([d.corners for d in detections]) if detections else np.zeros((0, 2))
    field = invertible_field(camera)
    if field.folds and corners.size:
        outside = ~field.contains_pixels(corners)
        if outside.any():
            out.append(
                (
                    "dist",
                    f"the lens model folds over where the views saw corners ({int(outside.sum())} of "
                    f"{len(corners)} corners lie beyond its invertible field: {field.describe()}): "
                    "not a lens's distortion (too few views near the image's edges, or a wrong model)",
                )
            )
    return tuple(out)
