"""Calibration of a rig of cameras: each camera's intrinsics and its pose in the rig frame.

:func:`calibrate_rig` takes the board detections of several views seen by several cameras
(``detections[k][v]``: camera k's detection of view v, the board standing still while the
cameras take it; a view seen by only some cameras still helps their intrinsics) and returns
a :class:`RigCalibrationResult` whose :class:`~stiffmap.rig.Rig` holds each camera's
intrinsics and distortion and its ``cam2rig`` (the first camera's frame is the rig frame),
with the joint covariance of them all.

Method:

1. each camera alone is calibrated from every view it sees
   (:func:`~stiffmap.vision.calibrate.calibrate_camera`: Zhang's method and OpenCV's
   refinement), which gives its intrinsics and the board's pose ``board2cam_k`` in each of
   its views;
2. ``cam2rig`` of each camera follows from the views it shares with a camera already
   placed (the first camera, or one placed through it): cam_k2cam_j =
   board2cam_j . inv(board2cam_k) per shared view, their robust mean (views whose
   transform lies far from the others' median are left out of the mean); each view's
   board pose in the rig frame, ``board2rig``, is the mean over the cameras that see it.
   A chessboard that looks the same turned by 180 degrees (cols + rows even) may be
   numbered from the other end in one camera (a camera mounted upside down, a board held
   on end): each of camera k's views is taken as numbered or turned, whichever agrees with
   the others, and renumbered before anything else;
3. a bundle adjustment refines everything together: SciPy's ``least_squares`` (trust
   region, analytic sparse Jacobian) over every camera's intrinsics, every ``cam2rig``
   after the first (its (t, r) perturbation, ``docs/conventions.md``) and every view's
   ``board2rig`` (its (t, r) perturbation, rig frame), minimising the reprojection errors
   of every corner in every camera. The Jacobian is assembled from
   :func:`~stiffmap.posemath.projection_jacobian` (whose translation columns are
   d uv / d X_cam) and :meth:`~stiffmap.camera.CameraModel.projection_param_jacobian`;
   the rotation parts go through SO(3)'s left Jacobian so that they are exact at any
   iterate. SciPy rather than OpenCV's ``stereoCalibrate`` / ``calibrateMultiview``: the
   same code serves any number of cameras, views seen by some cameras only, every
   distortion model of :data:`~stiffmap.vision.calibrate.DIST_MODELS`, and it gives the
   Jacobian the covariance needs;
4. views whose RMS in a camera exceeds ``outlier_factor`` times that camera's median view
   RMS (and ``outlier_min_px``) are left out of that camera one at a time, worst first (at
   most a third of a camera's views; a camera keeps ``min_views`` views and its place in
   the rig), as :func:`~stiffmap.vision.calibrate.calibrate_camera` does; the bundle
   adjustment is run again after each;
5. the views' excess dispersion (``Rig.dispersion``): each camera's pose relative to the
   camera it was placed from, view by view (cam_k2rig = cam_j2rig . board2cam_j .
   inv(board2cam_k), each view's corner pose with the final intrinsics), deviates from the
   calibrated ``cam2rig`` by e_v with covariance P_v = E^-1 (Q_j + Q_k) E^-T (Q: each pose's
   covariance as the cameras' consistency test takes it, the corner fit's times
   :func:`~stiffmap.vision.pose.corner_noise_factor`, in the rig frame; E the extrinsic
   Jacobian at the board, :func:`~stiffmap.vision.fuse.extrinsic_jacobian`). What scatters the
   e_v beyond their P_v (a hand-held board moving between unsynchronised exposures, what the
   lens model leaves) is their excess covariance D over ``NAME.tx..rz``
   (:func:`~stiffmap.stats.excess_dispersion`: method of moments, zero when the scatter is
   within its chi-square law, one bad view left out). On OpenCV's stereo samples the e_v
   scatter 2.5 times their P_v (p = 3e-11): D has 1 sigma 0.04 / 0.36 / 0.04 mm and
   1.3 / 0.5 / 0.85 mrad; on the test-bed's renders it is zero.

Covariance: s^2 S^-1 with S the information J^T J of the camera parameters (intrinsics and
``cam2rig`` perturbations) after the views' board poses are eliminated (their Schur
complement, as :func:`~stiffmap.vision.calibrate.calibration_covariance` does for one
camera), and s^2 = sum e^2 / (2 N - p) (N corners, p free parameters, 6 per view
included): over exactly :attr:`~stiffmap.rig.Rig.param_names`. A rig of one camera is that
camera's :func:`~stiffmap.vision.calibrate.calibrate_camera` result (same parameters, same
covariance).

:meth:`RigCalibrationResult.matlab_text` prints the result the way the Camera Calibration
Toolbox for Matlab prints a stereo calibration: each camera's intrinsics, then for each
camera after the first its pose relative to the first as the toolbox's om and T, the
transform from the first camera's frame to its own (X_k = R(om) X_first + T, i.e.
``rig2cam_k``), +/- three standard deviations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..geometry import invert_transform, mean_transform, rotvec_from_matrix
from ..posemath import perturb_pose, projection_jacobian, skew
from ..rig import Rig, RigCamera
from ..stats import excess_dispersion
from ..targets import as_board
from .calibrate import (
    DIST_MODELS,
    MATLAB_NOTE,
    CalibrationResult,
    ViewResult,
    calibrate_camera,
    covariance_from_information,
    fixed_params,
    matlab_camera_lines,
    solve_view_pose,
    usable_views,
    with_calibration_results,
)
from .detection import Board, BoardDetection, grid_of
from .fuse import extrinsic_jacobian
from .pose import corner_noise_factor, estimate_pose

__all__ = ["RigCalibrationResult", "calibrate_rig", "NO_IMAGE", "MIN_SHARED_VIEWS", "matlab_extrinsics"]

#: Reason of a view a camera has no image of (``None`` in ``detections``).
NO_IMAGE = "no image of this view"
#: Fewest views a camera must share with the cameras already placed to be placed in the rig.
MIN_SHARED_VIEWS = 2
#: Bundle adjustment: largest number of evaluations, and the tolerances (relative).
_MAX_NFEV = 200
_TOL = 1e-12
_LSMR_TOL = 1e-14
_LSMR_MAXITER = 5000


@dataclass(frozen=True)
class RigCalibrationResult:
    """Result of :func:`calibrate_rig`.

    Attributes
    ----------
    rig : Rig
        The cameras (each a :class:`~stiffmap.camera.CameraModel` with ``std`` and ``cov``,
        its intrinsics' block of the joint covariance, ``rms_px``, ``residual_std_px`` and
        its ``views``) and their ``cam2rig``; ``cov`` the joint covariance over
        ``rig.param_names``; ``info``: ``model``, ``rms_px`` per camera, ``views`` (per view
        its RMS in each camera, None where not used) and ``outliers`` (view, camera, why).
    views : tuple of tuple of ViewResult
        ``views[k][v]``: camera k's view v (its RMS with the final rig, its ``board2cam``).
    board2rig : tuple of (ndarray, shape (4, 4)) or None
        Per view, the board's pose in the rig frame (None: used by no camera), mm.
    residuals_px : tuple of ndarray, shape (N_k, 2)
        Per camera, observed minus projected corners of its used views, px.
    model : str
        Distortion model (a key of :data:`~stiffmap.vision.calibrate.DIST_MODELS`).
    view_names : tuple of str
    outliers : tuple of (str, str, str)
        (view, camera, reason) of every view left out of a camera as an outlier, in the
        order they were left out.
    """

    rig: Rig
    views: tuple[tuple[ViewResult, ...], ...]
    board2rig: tuple[np.ndarray | None, ...]
    residuals_px: tuple[np.ndarray, ...]
    model: str
    view_names: tuple[str, ...]
    outliers: tuple[tuple[str, str, str], ...] = ()

    @property
    def n_used(self) -> tuple[int, ...]:
        """Views used per camera."""
        return tuple(sum(v.used for v in vs) for vs in self.views)

    def to_dict(self) -> dict:
        """The ``rig.json`` object."""
        return self.rig.to_dict()

    def camera_result(self, k: int) -> CalibrationResult:
        """Camera ``k`` as a one-camera :class:`~stiffmap.vision.calibrate.CalibrationResult`."""
        return CalibrationResult(
            camera=self.rig.cameras[k].camera,
            views=self.views[k],
            residuals_px=self.residuals_px[k],
            model=self.model,
            n_used=self.n_used[k],
        )

    def dispersion_notes(self) -> list[str]:
        """A line per camera after the first whose pose relative to the camera it was placed from
        scattered over the views beyond what their poses predict (step 5 of the module
        docstring): the ratio and the excess kept in the rig for the cameras' agreement test;
        and one naming the views left out of that estimate. None when the views scatter as
        their poses predict (the test-bed's renders)."""
        lines = []
        rel = self.rig.info.get("relative_poses", {})
        for name, r in rel.items():
            s = self.rig.extrinsic_slice(self.rig.index(name))
            sd = np.sqrt(np.maximum(np.diag(self.rig.dispersion[s, s]), 0.0))
            head = (
                f"camera {name}: its pose relative to {r['relative_to']} scattered {r['variance_ratio']:.2g} "
                f"times what the poses of its {r['views']} views predict (p = {r['p_value']:.2g})"
            )
            if sd.any():
                t = " / ".join(f"{x:.3f}" for x in sd[:3])
                rr = " / ".join(f"{1000 * x:.2f}" for x in sd[3:])
                lines.append(
                    f"{head}: its excess, 1 sigma {t} mm and {rr} mrad (tx..rz), is kept in the rig file "
                    "for pose --rig's test of the cameras' agreement"
                )
            if r["left_out"]:
                lines.append(
                    f"camera {name}: view(s) {', '.join(r['left_out'])} left out of that estimate: their "
                    "relative pose is beyond what the others' scatter explains (did the board move between "
                    "the cameras' exposures?)"
                )
        return lines

    def extrinsics_matlab(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Camera ``k``'s pose relative to the first: the Matlab toolbox's om, T and their 1 sigma."""
        return matlab_extrinsics(self.rig, k)

    def matlab_text(self) -> str:
        """The result as the Matlab Camera Calibration Toolbox prints a stereo calibration (+/- 3 sigma)."""
        rig = self.rig
        if len(rig) == 1:
            return self.camera_result(0).matlab_text()
        lines = [
            "Stereo calibration parameters after optimization:"
            if len(rig) == 2
            else "Rig calibration parameters after optimization:",
            "",
        ]
        for c in rig.cameras:
            lines += ["", f"Intrinsic parameters of {c.name} camera:", ""]
            lines += matlab_camera_lines(c.camera, suffix=f"_{c.name}")
            lines.append("")
        first = rig.cameras[0].name

        def f(v) -> str:
            return "   ".join(f"{x:.5f}" for x in v)

        for k in range(1, len(rig)):
            om, T, om_std, T_std = matlab_extrinsics(rig, k)
            lines += [
                "",
                f"Extrinsic parameters (position of {rig.cameras[k].name} camera wrt {first} camera):",
                "",
                f"Rotation vector:             om = [ {f(om)} ] +/- [ {f(3 * om_std)} ]",
                f"Translation vector:           T = [ {f(T)} ] +/- [ {f(3 * T_std)} ]",
                "",
            ]
        lines += ["", MATLAB_NOTE]
        return "\n".join(lines)


def _left_jacobian(phi: np.ndarray) -> np.ndarray:
    """SO(3)'s left Jacobian: Exp(phi + d) = Exp(J_l(phi) d) Exp(phi) to first order in d."""
    theta = float(np.linalg.norm(phi))
    K = skew(phi)
    if theta < 1e-6:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return np.eye(3) + (1.0 - math.cos(theta)) / theta**2 * K + (theta - math.sin(theta)) / theta**3 * (K @ K)


def _left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_left_jacobian`: Log(Exp(d) Exp(phi)) = phi + J_l^-1(phi) d to first order."""
    theta = float(np.linalg.norm(phi))
    K = skew(phi)
    if theta < 1e-6:
        return np.eye(3) - 0.5 * K + K @ K / 12.0
    c = 1.0 / theta**2 - (1.0 + math.cos(theta)) / (2.0 * theta * math.sin(theta))
    return np.eye(3) - 0.5 * K + c * (K @ K)


def matlab_extrinsics(rig: Rig, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Camera ``k``'s pose relative to the first camera as the Matlab toolbox's om and T.

    The toolbox's om, T take points from the first (left) camera's frame to camera k's:
    X_k = R(om) X_first + T, i.e. ``rig2cam_k = inv(cam2rig_k)``. Their standard
    deviations come from the rig's covariance of camera k's ``cam2rig`` perturbation
    (dt, dr) by first-order propagation: with cam2rig = (R_c, t_c), dT = -R_c^T dt -
    R_c^T [t_c]x dr and dom = -J_l^-1(om) R_c^T dr (J_l: SO(3)'s left Jacobian).

    Parameters
    ----------
    rig : Rig
    k : int
        A camera after the first.

    Returns
    -------
    om : ndarray, shape (3,), rad
    T : ndarray, shape (3,), mm
    om_std, T_std : ndarray, shape (3,)
        1 sigma (zeros when the rig has no covariance of that camera's pose).
    """
    if not 0 < k < len(rig):
        raise ValueError(f"camera {k}: the first camera's pose is the rig frame; give 1..{len(rig) - 1}")
    c2r = rig.cameras[k].cam2rig
    r2c = invert_transform(c2r)
    om = rotvec_from_matrix(r2c[:3, :3])
    T = r2c[:3, 3].copy()
    G = _matlab_extrinsics_jacobian(c2r)
    cov = rig.calibration_cov
    if cov is None:
        C = np.zeros((6, 6))
    else:
        s = rig.extrinsic_slice(k)
        C = G @ cov[s, s] @ G.T
    sd = np.sqrt(np.maximum(np.diag(C), 0.0))
    return om, T, sd[:3], sd[3:]


def _matlab_extrinsics_jacobian(cam2rig: np.ndarray) -> np.ndarray:
    """d(om, T) / d(dt, dr) of the perturbation of ``cam2rig`` (6 x 6, see :func:`matlab_extrinsics`)."""
    Rc, tc = cam2rig[:3, :3], cam2rig[:3, 3]
    om = rotvec_from_matrix(Rc.T)
    G = np.zeros((6, 6))
    G[:3, 3:] = -_left_jacobian_inverse(om) @ Rc.T
    G[3:, :3] = -Rc.T
    G[3:, 3:] = -Rc.T @ skew(tc)
    return G


# --------------------------------------------------------------------------- bundle adjustment
@dataclass
class _Problem:
    """What the bundle adjustment fits: cameras, observations, and where the parameters go."""

    cameras: list[CameraModel]
    cam2rig: list[np.ndarray]
    board2rig: dict[int, np.ndarray]
    obs: list[tuple[int, int]]  # (camera, view)
    points: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]  # (q (m, 3) mm, uv (m, 2) px)
    free: list[list[int]]  # per camera, indices of its free parameters


def _layout(p: _Problem) -> tuple[list[int], list[int | None], dict[int, int], int, int]:
    """Column offsets: per camera its free intrinsics, then (after the first) 6 extrinsics; 6 per view."""
    cam_off, ext_off = [], []
    n = 0
    for k in range(len(p.cameras)):
        cam_off.append(n)
        n += len(p.free[k])
        if k > 0:
            ext_off.append(n)
            n += 6
        else:
            ext_off.append(None)
    n_a = n
    views = sorted({v for _, v in p.obs})
    view_off = {}
    for v in views:
        view_off[v] = n
        n += 6
    return cam_off, ext_off, view_off, n_a, n


def _unpack(p: _Problem, x: np.ndarray, layout):
    cam_off, ext_off, view_off, _, _ = layout
    cams, c2r, deltas = [], [], []
    for k, cam in enumerate(p.cameras):
        params = cam.params.copy()
        params[p.free[k]] = x[cam_off[k] : cam_off[k] + len(p.free[k])]
        cams.append(cam.with_params(params))
        if k == 0:
            c2r.append(p.cam2rig[0])
            deltas.append(np.zeros(6))
        else:
            d = x[ext_off[k] : ext_off[k] + 6]
            c2r.append(perturb_pose(p.cam2rig[k], d))
            deltas.append(d)
    b2r, eps = {}, {}
    for v, o in view_off.items():
        e = x[o : o + 6]
        b2r[v] = perturb_pose(p.board2rig[v], e)
        eps[v] = e
    return cams, c2r, deltas, b2r, eps


def _x0(p: _Problem, layout) -> np.ndarray:
    cam_off, _, _, _, n = layout
    x = np.zeros(n)
    for k, cam in enumerate(p.cameras):
        x[cam_off[k] : cam_off[k] + len(p.free[k])] = cam.params[p.free[k]]
    return x


def _evaluate(p: _Problem, x: np.ndarray, layout, jacobian: bool = True):
    """Residuals (projected minus observed, px, (u, v) per corner) and their sparse Jacobian."""
    cam_off, ext_off, view_off, _, n = layout
    cams, c2r, deltas, b2r, eps = _unpack(p, x, layout)
    Jl_ext = [_left_jacobian(d[3:]) for d in deltas]
    Jl_view = {v: _left_jacobian(e[3:]) for v, e in eps.items()}
    res, rows, cols, vals = [], [], [], []
    row0 = 0
    for k, v in p.obs:
        q, uv_obs = p.points[(k, v)]
        cam = cams[k]
        Tc, Tb = c2r[k], b2r[v]
        board2cam = invert_transform(Tc) @ Tb
        uv, Jp = projection_jacobian(board2cam, q, cam, validate=False)
        res.append((uv - uv_obs).reshape(-1))
        m = len(q)
        if not jacobian:
            row0 += 2 * m
            continue
        # d uv / d X_rig = (d uv / d X_cam) R_c^T
        A = Jp[:, :, :3] @ Tc[:3, :3].T  # (m, 2, 3)
        Rq = q @ Tb[:3, :3].T
        Xr = Rq + Tb[:3, 3]
        blocks = []
        Xc = (Xr - Tc[:3, 3]) @ Tc[:3, :3]
        Jc = cam.projection_param_jacobian(Xc[:, :2] / Xc[:, 2:3])[:, :, p.free[k]]
        blocks.append((cam_off[k], Jc))
        if k > 0:
            Je = np.concatenate([-A, (A @ skew(Xr - Tc[:3, 3])) @ Jl_ext[k]], axis=2)
            blocks.append((ext_off[k], Je))
        Jb = np.concatenate([A, -(A @ skew(Rq)) @ Jl_view[v]], axis=2)
        blocks.append((view_off[v], Jb))
        r = row0 + np.arange(2 * m)
        for off, B in blocks:
            B2 = B.reshape(2 * m, -1)
            nc = B2.shape[1]
            rows.append(np.repeat(r, nc))
            cols.append(np.tile(off + np.arange(nc), 2 * m))
            vals.append(B2.reshape(-1))
        row0 += 2 * m
    f = np.concatenate(res)
    if not jacobian:
        return f, None
    from scipy.sparse import coo_matrix  # imported here: SciPy's sparse and optimize take 0.15 s

    J = coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(row0, n)
    ).tocsr()
    return f, J


def _bundle_adjust(p: _Problem) -> _Problem:
    """Refine cameras, ``cam2rig`` and ``board2rig`` together; the problem re-based at the optimum."""
    layout = _layout(p)
    x0 = _x0(p, layout)
    cache: dict = {"key": x0.tobytes(), "value": _evaluate(p, x0, layout)}
    n_res = cache["value"][0].size

    def evaluate(x):
        key = x.tobytes()
        if cache.get("key") != key:
            cache["key"] = key
            try:
                cache["value"] = _evaluate(p, x, layout)
            except ValueError:  # a trial step put a board behind a camera: a step too far
                cache["value"] = (np.full(n_res, 1e6), None)
        return cache["value"]

    from scipy.optimize import least_squares

    sol = least_squares(
        lambda x: evaluate(x)[0],
        x0,
        jac=lambda x: evaluate(x)[1],
        method="trf",
        x_scale="jac",
        tr_solver="lsmr",
        # Each step solved to the last digits (with LSMR's default tolerances the steps are
        # inexact enough that the trust region crawls for hundreds of iterations).
        tr_options={"atol": _LSMR_TOL, "btol": _LSMR_TOL, "maxiter": _LSMR_MAXITER},
        ftol=_TOL,
        xtol=_TOL,
        gtol=_TOL,
        max_nfev=_MAX_NFEV,
    )
    cams, c2r, _, b2r, _ = _unpack(p, sol.x, layout)
    return _Problem(cams, c2r, b2r, p.obs, p.points, p.free)


def _information(p: _Problem):
    """Residuals, and the Schur complement S of the camera parameters (board poses eliminated)."""
    layout = _layout(p)
    _, _, view_off, n_a, _ = layout
    f, J = _evaluate(p, _x0(p, layout), layout)
    J = J.tocsc()
    Ja = J[:, :n_a].toarray()
    S = Ja.T @ Ja
    for o in view_off.values():
        Jb = J[:, o : o + 6]
        Hab = np.asarray(Jb.T @ Ja)
        Hbb = np.asarray((Jb.T @ Jb).toarray())
        S -= Hab.T @ np.linalg.solve(Hbb, Hab)
    return f, S, layout


# ------------------------------------------------------------------------------ set-up
def _robust_mean(transforms: list[np.ndarray]) -> np.ndarray:
    """Mean of rigid transforms, leaving out those far from the others (rotation or translation)."""
    T = np.asarray(transforms)
    if len(T) <= 2:
        return mean_transform(T)
    m = mean_transform(T)
    ang = np.linalg.norm(rotvec_from_matrix(np.einsum("nij,kj->nik", T[:, :3, :3], m[:3, :3])), axis=1)
    dist = np.linalg.norm(T[:, :3, 3] - np.median(T[:, :3, 3], axis=0), axis=1)
    keep = (ang <= max(3.0 * np.median(ang), 1e-3)) & (dist <= max(3.0 * np.median(dist), 0.1))
    return mean_transform(T[keep]) if keep.sum() >= 2 else m


def _placement(used: list[set[int]]) -> tuple[dict[int, int], list[int]]:
    """Cameras placed from the first through shared views (>= MIN_SHARED_VIEWS): parents, order."""
    parent: dict[int, int] = {}
    order = [0]
    placed = {0}
    while True:
        best = None
        for k in range(len(used)):
            if k in placed:
                continue
            for j in order:
                n = len(used[k] & used[j])
                if n >= MIN_SHARED_VIEWS and (best is None or n > best[2]):
                    best = (k, j, n)
        if best is None:
            return parent, order
        parent[best[0]] = best[1]
        order.append(best[0])
        placed.add(best[0])


def _symmetric(board: Board) -> bool:
    """Does the board look the same turned by 180 degrees (a chessboard of cols + rows even)?"""
    grid = grid_of(board)
    return board is grid and (grid.cols + grid.rows) % 2 == 0


def _half_turn(grid) -> np.ndarray:
    """The board-frame map of a half turn about the grid's centre: corner id -> n - 1 - id (4x4)."""
    F = np.diag([-1.0, -1.0, 1.0, 1.0])
    F[:3, 3] = [(grid.cols - 1) * grid.square_mm, (grid.rows - 1) * grid.square_mm, 0.0]  # twice the centre
    return F


def _turned(d: BoardDetection, grid) -> BoardDetection:
    """The detection numbered from the other end (a half turn of the board)."""
    n = grid.cols * grid.rows
    ids = n - 1 - np.asarray(d.ids)
    order = np.argsort(ids)
    return replace(
        d,
        corners=np.asarray(d.corners)[order],
        ids=ids[order],
        residual_px=np.asarray(d.residual_px)[order],
        rejected=np.sort(n - 1 - np.asarray(d.rejected, dtype=int)),
    )


def _views_to_turn(b2c_j, b2c_k, shared: list[int], F: np.ndarray) -> list[int]:
    """Views of camera k whose numbering, turned by half a turn, agrees with camera j's.

    Each shared view gives camera k's pose relative to j two ways (k's numbering as it is, or
    turned); only the right ones agree with each other (the turned ones differ by a half turn
    about each view's own board centre). The hypothesis of one view that most others agree
    with (within 5 degrees and 5 % of the distance between the cameras, or 10 mm) fixes which
    way each view goes; of equally good ones, the fewest turns.
    """
    rel = {
        v: [b2c_j[v] @ invert_transform(b2c_k[v]), b2c_j[v] @ F @ invert_transform(b2c_k[v])] for v in shared
    }

    def distance(A: np.ndarray, ref: np.ndarray) -> float:
        c = (np.trace(A[:3, :3] @ ref[:3, :3].T) - 1.0) / 2.0
        angle = float(np.arccos(np.clip(c, -1.0, 1.0)))
        tol = max(10.0, 0.05 * float(np.linalg.norm(ref[:3, 3])))
        return max(angle / np.radians(5.0), float(np.linalg.norm(A[:3, 3] - ref[:3, 3])) / tol)

    best: tuple[int, int, list[int]] | None = None
    for v0 in shared:
        for h in (0, 1):
            ref = rel[v0][h]
            d = {v: (distance(rel[v][0], ref), distance(rel[v][1], ref)) for v in shared}
            turn = [v for v in shared if d[v][1] < d[v][0]]
            key = (sum(min(d[v]) < 1.0 for v in shared), -len(turn))
            if best is None or key > best[:2]:
                best = (*key, turn)
    return best[2] if best is not None else []


def _unplaced_message(names: Sequence[str], used: list[set[int]], placed: list[int]) -> str:
    k = next(i for i in range(len(names)) if i not in placed)
    shared = [(len(used[k] & used[j]), names[j]) for j in placed]
    n, other = max(shared)
    return (
        f"camera {names[k]} shares {n} usable view(s) with camera {other} and fewer with the others "
        f"placed in the rig: at least {MIN_SHARED_VIEWS} views of the board seen at once by it and "
        "another camera are needed to place it (views are matched across cameras by the number "
        "in their file names)"
    )


def _rig_names(detections, camera_names, image_sizes, view_names, image_names):
    """The cameras', views' and images' names and the image sizes, checked against the
    detections' shape: (names, vnames, inames, sizes)."""
    n_cam = len(detections)
    names = [str(x) for x in camera_names]
    if n_cam == 0:
        raise ValueError("a rig needs at least one camera")
    if len(names) != n_cam or len(image_sizes) != n_cam:
        raise ValueError(
            f"{n_cam} cameras of detections, {len(names)} camera_names, {len(image_sizes)} image_sizes"
        )
    if len(set(names)) != n_cam or not all(n.strip() for n in names):
        raise ValueError(f"camera names must be different non-empty strings, got {names!r}")
    n_views = len(detections[0])
    if any(len(d) != n_views for d in detections):
        raise ValueError(f"every camera needs one entry per view: {[len(d) for d in detections]} entries")
    vnames = [f"view{v + 1}" for v in range(n_views)] if view_names is None else [str(x) for x in view_names]
    if len(vnames) != n_views:
        raise ValueError(f"view_names has {len(vnames)} entries for {n_views} views")
    if image_names is None:
        inames = [list(vnames) for _ in range(n_cam)]
    else:
        inames = [[vnames[v] if x is None else str(x) for v, x in enumerate(row)] for row in image_names]
        if len(inames) != n_cam or any(len(r) != n_views for r in inames):
            raise ValueError("image_names must hold one name per camera and view")
    sizes = [tuple(int(s) for s in sz) for sz in image_sizes]
    return names, vnames, inames, sizes


def _usable_per_camera(dets, missing, board, names, inames, min_views):
    """Each camera's reasons (per view) and usable views; a camera with too few raises."""
    reasons, usable = [], []
    for k in range(len(dets)):
        r, u = usable_views(dets[k], board)
        reasons.append(r)
        usable.append(u)
        if len(u) < min_views:
            detail = "; ".join(f"{inames[k][v]}: {r[v]}" for v in range(len(r)) if r[v] and not missing[k][v])
            raise InputError(
                f"camera {names[k]}: calibration needs at least {min_views} views with the board found, "
                f"got {len(u)}" + (f" ({detail})" if detail else "")
            )
    return reasons, usable


def _place_cameras(singles, dets, used, parent, order, board, grid):
    """cam2rig of every camera from the views' poses it shares with its parent in the placement
    order, and the views' board2cam (a symmetric board's views renumbered in ``dets`` to agree)."""
    n_cam, n_views = len(singles), len(dets[0])
    b2c = [[singles[k].views[v].board2cam for v in range(n_views)] for k in range(n_cam)]
    cam2rig = [np.eye(4) for _ in range(n_cam)]
    F = _half_turn(grid) if _symmetric(board) else None
    for k in order[1:]:
        j = parent[k]
        shared = sorted(used[k] & used[j])
        if F is not None:
            # A board that looks the same turned by 180 degrees may be numbered from the
            # other end in one camera: renumber camera k's views to agree with camera j's.
            for v in _views_to_turn(b2c[j], b2c[k], shared, F):
                dets[k][v] = _turned(dets[k][v], grid)
                b2c[k][v] = b2c[k][v] @ F
        rel = [b2c[j][v] @ invert_transform(b2c[k][v]) for v in shared]
        cam2rig[k] = cam2rig[j] @ _robust_mean(rel)
    return cam2rig, b2c


def _board_poses(cam2rig, b2c, used) -> dict[int, np.ndarray]:
    """board2rig of every view some camera uses: the robust mean over those cameras."""
    out = {}
    for v in sorted(set().union(*used)):
        out[v] = _robust_mean([cam2rig[k] @ b2c[k][v] for k in range(len(cam2rig)) if v in used[k]])
    return out


def _initial_problem(singles, cam2rig, b2c, used, usable, dets, obj_all, model: str) -> _Problem:
    """The bundle adjustment's start: the cameras alone, cam2rig and board2rig from the views'
    poses, every usable view's corners, each camera's free parameters."""
    n_cam = len(singles)
    fixed = fixed_params(model)
    points = {
        (k, v): (obj_all[dets[k][v].ids], np.asarray(dets[k][v].corners, dtype=np.float64))
        for k in range(n_cam)
        for v in usable[k]
    }
    free = [[i for i in range(4 + DIST_MODELS[model]) if i not in fixed] for _ in range(n_cam)]
    return _Problem([s.camera for s in singles], cam2rig, _board_poses(cam2rig, b2c, used), [], points, free)


def _view_rms(problem: _Problem) -> dict[tuple[int, int], float]:
    """The reprojection RMS (px) of every (camera, view) of the adjusted problem."""
    layout = _layout(problem)
    f, _ = _evaluate(problem, _x0(problem, layout), layout, jacobian=False)
    return {
        kv: float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) for kv, e in _split_residuals(problem, f).items()
    }


def _worst_outlier(rms, used, usable, max_out, outlier_factor, outlier_min_px, min_views):
    """(ratio, k, v, rms, median) of the view farthest above its camera's outlier limit whose
    removal leaves every camera placed, or None (cameras at their outlier or view limit skipped)."""
    n_cam = len(used)
    worst = None
    for k in range(n_cam):
        vals = [rms[(k, v)] for v in sorted(used[k])]
        med = float(np.median(vals))
        limit = max(outlier_factor * med, outlier_min_px)
        if len(usable[k]) - len(used[k]) >= max_out[k] or len(used[k]) <= min_views:
            continue
        for v in sorted(used[k]):
            ratio = rms[(k, v)] / limit
            if ratio > 1 and (worst is None or ratio > worst[0]):
                trial = [set(u) for u in used]
                trial[k].discard(v)
                if len(_placement(trial)[1]) == n_cam:
                    worst = (ratio, k, v, rms[(k, v)], med)
    return worst


def _adjust(problem, used, usable, reasons, outlier_factor, outlier_min_px, min_views):
    """Bundle adjustment, the worst outlier view left out (``used`` and ``reasons`` updated)
    and the adjustment again, until none is left (at most a third of a camera's views):
    the adjusted problem and the outliers (camera, view, reason)."""
    n_cam = len(used)
    max_out = [len(u) // 3 for u in usable]
    outliers: list[tuple[int, int, str]] = []
    while True:
        problem.obs = [(k, v) for k in range(n_cam) for v in sorted(used[k])]
        problem.board2rig = {v: problem.board2rig[v] for v in sorted(set().union(*used))}
        problem = _bundle_adjust(problem)
        rms = _view_rms(problem)
        worst = _worst_outlier(rms, used, usable, max_out, outlier_factor, outlier_min_px, min_views)
        if worst is None:
            return problem, outliers
        _, k, v, r, med = worst
        used[k].discard(v)
        reasons[k][v] = f"outlier: view RMS {r:.3f} px > {outlier_factor:g} x median {med:.3f} px"
        outliers.append((k, v, reasons[k][v]))


# ------------------------------------------------------------------------------- calibrate
def calibrate_rig(
    detections: Sequence[Sequence[BoardDetection | str | None]],
    board: Board,
    image_sizes: Sequence[tuple[int, int]],
    *,
    camera_names: Sequence[str],
    view_names: Sequence[str] | None = None,
    image_names: Sequence[Sequence[str | None]] | None = None,
    model: str = "k3",
    outlier_factor: float = 3.0,
    outlier_min_px: float = 0.3,
    min_views: int = 3,
    square_mm: float | None = None,
) -> RigCalibrationResult:
    """Calibrate a rig of cameras from views of a board seen by several cameras at once.

    Parameters
    ----------
    detections : sequence of sequence of BoardDetection, str or None
        ``detections[k][v]``: camera k's detection of view v (the views aligned across
        cameras: view v is one pose of the board), or the reason it has none (a string), or
        None when camera k has no image of view v.
    board : Chessboard or CharucoBoard
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (:func:`~stiffmap.targets.as_board`).
    image_sizes : sequence of (int, int)
        [w, h] of each camera's images, px.
    camera_names : sequence of str
        One per camera, different; the first camera's frame is the rig frame.
    view_names : sequence of str, optional
        One per view (default ``view1``, ``view2``...).
    image_names : sequence of sequence of str or None, optional
        ``image_names[k][v]``: the file of camera k's view v (default the view's name).
    model : str
        Distortion model of every camera (a key of :data:`~stiffmap.vision.calibrate.DIST_MODELS`).
    outlier_factor, outlier_min_px : float
        A view is an outlier in a camera when its RMS exceeds ``outlier_factor`` times that
        camera's median view RMS and ``outlier_min_px`` (px).
    min_views : int
        Fewest usable views per camera.

    Returns
    -------
    RigCalibrationResult

    Raises
    ------
    InputError
        A camera with fewer than ``min_views`` usable views (naming it and why its views
        failed), or one that shares fewer than :data:`MIN_SHARED_VIEWS` views with the
        cameras placed in the rig.
    ValueError
        Inconsistent arguments (lengths, names, model).
    """
    board = as_board(board, square_mm, "board")
    if model not in DIST_MODELS:
        raise ValueError(f"model must be one of {sorted(DIST_MODELS)}, got {model!r}")
    names, vnames, inames, sizes = _rig_names(detections, camera_names, image_sizes, view_names, image_names)
    options = dict(outlier_factor=outlier_factor, outlier_min_px=outlier_min_px, min_views=min_views)
    n_cam = len(detections)
    grid = grid_of(board)
    obj_all = grid.object_points()
    dets = [[NO_IMAGE if d is None else d for d in row] for row in detections]
    missing = [[d is None for d in row] for row in detections]
    reasons, usable = _usable_per_camera(dets, missing, board, names, inames, min_views)
    used = [set(u) for u in usable]
    parent, order = _placement(used)
    if len(order) < n_cam:
        raise InputError(_unplaced_message(names, used, order))

    # 1. Each camera alone, 2. cam2rig and board2rig from the views' poses.
    singles = [
        calibrate_camera(dets[k], board, sizes[k], names=inames[k], model=model, **options)
        for k in range(n_cam)
    ]
    cam2rig, b2c = _place_cameras(singles, dets, used, parent, order, board, grid)
    problem = _initial_problem(singles, cam2rig, b2c, used, usable, dets, obj_all, model)
    # 3. Bundle adjustment, 4. outliers left out one at a time.
    problem, outliers = _adjust(problem, used, usable, reasons, **options)
    res = _result(problem, dets, missing, reasons, used, names, vnames, inames, model, outliers, obj_all)
    return _with_dispersion(res, dets, used, board, vnames)  # 5. the views' excess dispersion


def _with_dispersion(res: RigCalibrationResult, dets, used, board, vnames) -> RigCalibrationResult:
    """The result with its rig's dispersion and, in its ``info``, how it was estimated."""
    D, summary = _dispersion(res.rig, dets, used, board, vnames)
    rig = replace(res.rig, dispersion=D, info={**res.rig.info, "relative_poses": summary})
    return replace(res, rig=rig)


def _relative_deviation(rig: Rig, j: int, k: int, Tj, Qj, Tk, Qk) -> tuple[np.ndarray, np.ndarray]:
    """One view's cam_k2rig (through camera j's pose of the board) as a (t, r) perturbation e of
    the calibrated ``cam2rig`` of camera k, and its covariance P = E^-1 (Q_j + Q_k) E^-T
    (``Q`` each pose's covariance in its camera frame, mapped to the rig frame)."""
    A, C = rig.cameras[j].cam2rig, rig.cameras[k].cam2rig
    X = A @ Tj @ invert_transform(Tk)
    e = np.r_[X[:3, 3] - C[:3, 3], rotvec_from_matrix(X[:3, :3] @ C[:3, :3].T)]
    Ra, Rc = np.kron(np.eye(2), A[:3, :3]), np.kron(np.eye(2), C[:3, :3])
    Einv = np.linalg.inv(extrinsic_jacobian(Tk, C))
    P = Einv @ (Ra @ Qj @ Ra.T + Rc @ Qk @ Rc.T) @ Einv.T
    return e, 0.5 * (P + P.T)


def _corner_pose(rig: Rig, k: int, det: BoardDetection, board) -> tuple[np.ndarray, np.ndarray]:
    """Camera k's corner pose of a view with its final intrinsics, and its covariance as the
    cameras' consistency test takes it (times the corner errors' correlation)."""
    p = estimate_pose(det, board, rig.cameras[k].camera, refine="corners")
    return p.board2cam, corner_noise_factor(p.residuals_px) * p.cov_noise


def _dispersion(rig: Rig, dets, used, board, vnames) -> tuple[np.ndarray | None, dict]:
    """The rig's dispersion over every ``cam2rig`` after the first (step 5 of the module
    docstring), from the views each camera shares with the camera it is placed from, and a
    summary per camera (views, variance ratio, p-value, views left out)."""
    if len(rig) == 1:
        return None, {}
    parent, _ = _placement(used)
    n = len(rig.param_names)
    D = np.zeros((n, n))
    summary = {}
    for k, j in sorted(parent.items()):
        shared = sorted(used[k] & used[j])
        dev = [
            _relative_deviation(
                rig, j, k, *_corner_pose(rig, j, dets[j][v], board), *_corner_pose(rig, k, dets[k][v], board)
            )
            for v in shared
        ]
        if len(dev) < 3:
            continue
        r = excess_dispersion([e for e, _ in dev], [P for _, P in dev])
        se = rig.extrinsic_slice(k)
        D[se, se] = r.cov
        summary[rig.names[k]] = {
            "relative_to": rig.names[j],
            "views": len(shared),
            "variance_ratio": round(r.ratio, 4),
            "p_value": float(f"{r.p_value:.4g}"),
            "left_out": [vnames[shared[i]] for i in r.left_out],
        }
    return D, summary


def _split_residuals(p: _Problem, f: np.ndarray) -> dict[tuple[int, int], np.ndarray]:
    """The stacked residuals ``f`` (projected minus observed) per (camera, view): (m, 2) px each."""
    out = {}
    i = 0
    for k, v in p.obs:
        m = len(p.points[(k, v)][0])
        out[(k, v)] = f[i : i + 2 * m].reshape(m, 2)
        i += 2 * m
    return out


def _result(p, dets, missing, reasons, used, names, vnames, inames, model, outliers, obj_all):
    n_cam, n_views = len(names), len(vnames)
    f, S, layout = _information(p)
    cam_off, ext_off, view_off, n_a, n_total = layout
    dof = f.size - n_a - 6 * len(view_off)
    s2 = float(f @ f) / dof if dof > 0 else float("nan")
    # The free camera parameters and the cam2rig perturbations in the rig's param_names (the
    # information's order; fixed parameters: zero rows).
    proto = Rig(tuple(RigCamera(names[k], p.cameras[k], p.cam2rig[k]) for k in range(n_cam)))
    index = []
    for k in range(n_cam):
        index += [proto.intrinsic_slice(k).start + i for i in p.free[k]]
        if k > 0:
            index += list(range(proto.extrinsic_slice(k).start, proto.extrinsic_slice(k).stop))
    n = len(proto.param_names)
    S_full = np.zeros((n, n))
    S_full[np.ix_(index, index)] = S
    C = covariance_from_information(S_full, s2, index)

    uv_res = {kv: -e for kv, e in _split_residuals(p, f).items()}  # observed minus projected
    views, residuals, cams = [], [], []
    for k in range(n_cam):
        cam = p.cameras[k]
        rig2cam = invert_transform(p.cam2rig[k])
        vk = []
        for v in range(n_views):
            d = dets[k][v]
            if not isinstance(d, BoardDetection):
                vk.append(ViewResult(inames[k][v], False, float("nan"), reasons[k][v]))
                continue
            if (k, v) in uv_res:
                e = uv_res[(k, v)]
                T = rig2cam @ p.board2rig[v]
            else:  # an outlier: its own pose with the final camera (as calibrate_camera gives it)
                q = obj_all[d.ids]
                T = solve_view_pose(cam, q, d.corners)
                if T is None:  # pragma: no cover - a detection always has a pose
                    vk.append(ViewResult(inames[k][v], False, float("nan"), reasons[k][v], d.n_corners))
                    continue
                e = d.corners - cam.project(q @ T[:3, :3].T + T[:3, 3])
            rms_v = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
            vk.append(ViewResult(inames[k][v], (k, v) in uv_res, rms_v, reasons[k][v], d.n_corners, T))
        R = np.concatenate([uv_res[(k, v)] for v in sorted(used[k])])
        block = C[proto.intrinsic_slice(k), proto.intrinsic_slice(k)]
        sd = np.sqrt(np.maximum(np.diag(block), 0.0))
        views_k = [vr.to_dict() for v, vr in enumerate(vk) if not missing[k][v]]
        cams.append(with_calibration_results(cam, sd, R, views_k, block))
        views.append(tuple(vk))
        residuals.append(R)
    info = {
        "model": model,
        "rms_px": {names[k]: cams[k].rms_px for k in range(n_cam)},
        "views": [
            {
                "view": vnames[v],
                "rms_px": {
                    names[k]: (views[k][v].rms_px if views[k][v].used else None) for k in range(n_cam)
                },
            }
            for v in range(n_views)
        ],
        "outliers": [{"view": vnames[v], "camera": names[k], "reason": why} for k, v, why in outliers],
    }
    rig = Rig(tuple(RigCamera(names[k], cams[k], p.cam2rig[k]) for k in range(n_cam)), cov=C, info=info)
    board2rig = tuple(p.board2rig.get(v) for v in range(n_views))
    return RigCalibrationResult(
        rig=rig,
        views=tuple(views),
        board2rig=board2rig,
        residuals_px=tuple(residuals),
        model=model,
        view_names=tuple(vnames),
        outliers=tuple((vnames[v], names[k], why) for k, v, why in outliers),
    )
