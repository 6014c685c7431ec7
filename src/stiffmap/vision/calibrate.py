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

from ..camera import CameraModel
from ..errors import InputError
from ..geometry import matrix_from_rotvec
from .detection import Board, BoardDetection, grid_of

__all__ = ["ViewResult", "CalibrationResult", "calibrate_camera", "DIST_MODELS"]

#: Distortion models: name -> number of coefficients.
DIST_MODELS = {"k3": 5, "fix-k3": 5, "rational": 8, "thin-prism": 12}
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
    """

    image: str
    used: bool
    rms_px: float
    reason: str
    n_corners: int = 0
    board2cam: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The ``camera.json`` ``views`` entry."""
        return {
            "image": self.image,
            "used": self.used,
            "rms_px": None if not math.isfinite(self.rms_px) else self.rms_px,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class CalibrationResult:
    """Result of :func:`calibrate_camera`.

    Attributes
    ----------
    camera : CameraModel
        With ``std``, ``rms_px``, ``residual_std_px`` and ``views`` filled.
    views : tuple of ViewResult
    residuals_px : ndarray, shape (N, 2)
        Observed minus projected corners of the used views, px.
    model : str
        Distortion model (a key of :data:`DIST_MODELS`).
    n_used : int
    """

    camera: CameraModel
    views: tuple[ViewResult, ...]
    residuals_px: np.ndarray
    model: str
    n_used: int

    def to_dict(self) -> dict:
        """The ``camera.json`` object."""
        return self.camera.to_dict()

    def matlab_text(self) -> str:
        """The result as the Camera Calibration Toolbox for Matlab prints it (+/- 3 sigma)."""
        c = self.camera
        s = c.std or {}
        sd = list(s.get("dist", [0.0] * len(c.dist)))

        def f(x: float) -> str:
            return f"{x:.5f}"

        kc = list(c.dist[:5]) + [0.0] * (5 - min(5, len(c.dist)))
        skc = (sd[:5] + [0.0] * 5)[:5]
        rs = c.residual_std_px or (float("nan"), float("nan"))
        lines = [
            "Calibration results after optimization (with uncertainties):",
            "",
            f"Focal Length:          fc = [ {f(c.fx)}   {f(c.fy)} ] +/- "
            f"[ {f(3 * s.get('fx', 0))}   {f(3 * s.get('fy', 0))} ]",
            f"Principal point:       cc = [ {f(c.cx)}   {f(c.cy)} ] +/- "
            f"[ {f(3 * s.get('cx', 0))}   {f(3 * s.get('cy', 0))} ]",
            "Skew:             alpha_c = [ 0.00000 ] +/- [ 0.00000  ]   "
            "=> angle of pixel axes = 90.00000 +/- 0.00000 degrees",
            "Distortion:            kc = [ "
            + "   ".join(f(k) for k in kc)
            + " ] +/- [ "
            + "   ".join(f(3 * k) for k in skc)
            + " ]",
            f"Pixel error:          err = [ {f(rs[0])}   {f(rs[1])} ]",
            "",
            "Note: The numerical errors are approximately three times the standard deviations "
            "(for reference).",
        ]
        if len(c.dist) > 5:
            lines.insert(
                6,
                "Higher-order terms (k4, k5, k6[, s1..s4]) = [ "
                + "   ".join(f(k) for k in c.dist[5:])
                + " ] +/- [ "
                + "   ".join(f(3 * k) for k in sd[5:])
                + " ]",
            )
        return "\n".join(lines)


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


def _run(obj, img, image_size, model):
    nd = DIST_MODELS[model]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, K, dist, rvecs, tvecs, sd_int, _sd_ext, per_view = cv2.calibrateCameraExtended(
        obj, img, image_size, None, np.zeros(nd), flags=_flags(model), criteria=crit
    )
    return K, np.asarray(dist, dtype=np.float64).ravel()[:nd], rvecs, tvecs, sd_int.ravel(), per_view.ravel()


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
) -> CalibrationResult:
    """Calibrate a camera from board detections in several views.

    Parameters
    ----------
    detections : sequence of BoardDetection or str
        One entry per image: its detection, or the reason it has none
        (e.g. the message of the detection error).
    board : Chessboard or CharucoBoard
    image_size : (int, int)
        [w, h] of the images, px.
    names : sequence of str, optional
        Image names (default ``view1``, ``view2``...).
    model : str
        ``"k3"`` (k1, k2, p1, p2, k3; default), ``"fix-k3"`` (k3 = 0, as the Matlab
        toolbox's default), ``"rational"`` (+ k4, k5, k6) or ``"thin-prism"``
        (+ s1..s4).
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
    if model not in DIST_MODELS:
        raise ValueError(f"model must be one of {sorted(DIST_MODELS)}, got {model!r}")
    n_views = len(detections)
    names = [f"view{k + 1}" for k in range(n_views)] if names is None else [str(x) for x in names]
    if len(names) != n_views:
        raise ValueError(f"names has {len(names)} entries for {n_views} detections")
    w, h = (int(v) for v in image_size)
    grid = grid_of(board)
    reasons = [""] * n_views
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
    if len(usable) < min_views:
        detail = "; ".join(f"{names[k]}: {reasons[k]}" for k in range(n_views) if reasons[k])
        raise InputError(
            f"calibration needs at least {min_views} views with the board found, got {len(usable)}"
            + (f" ({detail})" if detail else "")
        )
    obj_all = grid.object_points()
    used = list(usable)
    max_out = len(usable) // 3
    while True:
        obj = [obj_all[detections[k].ids].astype(np.float32) for k in used]
        img = [detections[k].corners.astype(np.float32) for k in used]
        K, dist, rvecs, tvecs, sd_int, per_view = _run(obj, img, (w, h), model)
        med = float(np.median(per_view))
        worst = int(np.argmax(per_view))
        limit = max(outlier_factor * med, outlier_min_px)
        if per_view[worst] > limit and len(usable) - len(used) < max_out and len(used) > min_views:
            k = used.pop(worst)
            reasons[k] = (
                f"outlier: view RMS {per_view[worst]:.3f} px > {outlier_factor:g} x median {med:.3f} px"
            )
            continue
        break
    nd = DIST_MODELS[model]
    cam = CameraModel((w, h), K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(dist))
    # Residuals and per-view RMS of every detected view with the final camera.
    res_used = []
    views = []
    pose_of = {k: (rvecs[i], tvecs[i]) for i, k in enumerate(used)}
    for k in range(n_views):
        d = detections[k]
        if not isinstance(d, BoardDetection):
            views.append(ViewResult(names[k], False, float("nan"), reasons[k]))
            continue
        if k in pose_of:
            rv, tv = pose_of[k]
        else:
            ok, rv, tv = cv2.solvePnP(obj_all[d.ids], d.corners, cam.matrix, cam.dist_array)
            if not ok:  # pragma: no cover - a detection always has a pose
                views.append(ViewResult(names[k], False, float("nan"), reasons[k], d.n_corners))
                continue
        proj, _ = cv2.projectPoints(obj_all[d.ids], rv, tv, cam.matrix, cam.dist_array)
        e = d.corners - proj.reshape(-1, 2)
        T = np.eye(4)
        T[:3, :3] = matrix_from_rotvec(np.asarray(rv, dtype=np.float64).ravel())
        T[:3, 3] = np.asarray(tv, dtype=np.float64).ravel()
        rms_v = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
        if k in pose_of:
            res_used.append(e)
        views.append(ViewResult(names[k], k in pose_of, rms_v, reasons[k], d.n_corners, T))
    R = np.concatenate(res_used)
    std = {
        "fx": float(sd_int[0]),
        "fy": float(sd_int[1]),
        "cx": float(sd_int[2]),
        "cy": float(sd_int[3]),
        "dist": [float(x) for x in sd_int[4 : 4 + nd]],
    }
    camera = CameraModel(
        (w, h),
        cam.fx,
        cam.fy,
        cam.cx,
        cam.cy,
        cam.dist,
        std=std,
        rms_px=float(np.sqrt(np.mean(np.sum(R**2, axis=1)))),
        residual_std_px=(float(np.std(R[:, 0], ddof=1)), float(np.std(R[:, 1], ddof=1))),
        views=tuple(v.to_dict() for v in views),
    )
    return CalibrationResult(camera=camera, views=tuple(views), residuals_px=R, model=model, n_used=len(used))
