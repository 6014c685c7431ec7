"""One pose of a board seen by several cameras of a rig: the per-camera poses fused.

Each camera k of a :class:`~stiffmap.rig.Rig` that saw the board gives its pose
``board2cam_k`` (:func:`~stiffmap.vision.pose.estimate_pose`: corners, then the photometric
refinement) with the fit's noise covariance N_k and its sensitivity A_k to camera k's own
parameters. :func:`fuse_poses` maps each into the rig frame and combines them into one
pose, ``board2rig``, with its covariance and its sensitivity to every parameter of the rig.

**The rig frame plays the camera frame.** The result is a :class:`FusedPose`, a
:class:`~stiffmap.posemath.PoseEstimate` whose pose is ``board2rig`` and whose covariance is
over the (t, r) left perturbation in the rig frame (``docs/conventions.md``, "Pose
uncertainty"); everything downstream (``mobile2base``, displacements, campaigns) takes it
through ``board2frame`` as it takes a camera's :class:`~stiffmap.posemath.BoardPose`
(``board2cam``), with ``cam2base`` reading ``rig2base``. A rig of one
camera is that camera: its fused pose is the camera's pose (to rounding).

To the rig frame (``cam2rig_k`` = C_k = (R_c, t_c); (t, r) left perturbations):

- board2rig_k = C_k . board2cam_k: t = R_c t_b + t_c, R = R_c R_b;
- a perturbation (dt, dr) of ``board2cam_k`` (camera frame) moves board2rig_k by
  (R_c dt, R_c dr): the noise covariance maps by J_k = blockdiag(R_c, R_c), N'_k = J_k N_k J_k^T,
  and the intrinsic sensitivity to J_k A_k;
- a perturbation (dt_c, dr_c) of ``cam2rig_k`` (the rig's ``NAME.tx..rz``) moves it by
  dt = dt_c - [R_c t_b]x dr_c, dr = dr_c: the extrinsic sensitivity
  E_k = [[I, -[R_c t_b]x], [0, I]] (from Exp(dr_c) R_c t_b = R_c t_b + dr_c x R_c t_b).

Fusion: the information-weighted mean in the tangent space around a reference pose T
(first the most informative view's, then the mean itself; two or three passes):
delta_k = (t_k - t, rotvec(R_k R^T)), W_k = N'_k^-1, delta = (sum W_k)^-1 sum W_k delta_k,
T <- (t + delta_t, Exp(delta_r) R). Then

- ``cov_noise`` = (sum W_k)^-1;
- ``calibration_jacobian`` A = (sum W_k)^-1 sum W_k [J_k A_k in camera k's intrinsic columns
  of ``rig.param_names``, E_k in its extrinsic columns] (the weights' own dependence on the
  parameters is second order);
- ``cov`` = ``cov_noise`` + A ``rig.calibration_cov`` A^T (``cov_calibration``; None when the
  rig's uncertainty is unknown, or a view has no sensitivity).

Why fuse the per-camera estimates rather than fit one pose to every camera's corners (or
pixels) at once: each per-camera fit minimises its own cost, which near its minimum is the
quadratic (x - x_k)^T W_k (x - x_k) in the pose x; the joint cost is their sum, whose minimum
is the information-weighted mean above. The two are the same estimate to first order (they
differ by the cost's curvature change over the cameras' disagreement, a few thousandths of a
sigma; ``tests/test_fuse.py`` checks it against a joint Gauss-Newton over two cameras'
corners), and the fusion keeps each camera's photometric refinement, its checks and its
fallback to the corner pose exactly as they are for one camera.

Consistency: the per-camera rig-frame poses should agree within their uncertainty. The
statistic chi2 = min_x sum (x_k - x)^T V^-1 (x_k - x) over the stacked views, with V their
joint covariance (each view's noise, and the rig's calibration error through the views'
sensitivities, correlated across cameras; and the rig's dispersion, ``Rig.dispersion``, through
each view's extrinsic Jacobian: how much the cameras' relative pose scattered between the
calibration's views beyond what their poses predict), follows a chi-square law with 6 (n - 1)
degrees of freedom when the rig file describes the cameras. The dispersion enters the test only:
the fused pose and its covariance are those of the views' own noise and the calibration (its
split between the cameras, hence its share in the fused pose, is not known from their
difference; see docs/vision.md, "Several cameras"). Above its :data:`CONSISTENCY_QUANTILE`
the pose carries a warning (``consistency_warning``) saying how far each camera's pose is
from the fused one: a rig file that is not this rig's, or a camera moved since the rig was
calibrated.

Symmetric boards: a chessboard whose colours do not fix its origin (``cols + rows`` even)
may be numbered from either end by each camera; each view is re-expressed through the
board's symmetry (half turn, and quarter turns for square boards) nearest to the reference
(``reference``: the board's previous fused pose, else the first view), so all views describe
the same board frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..geometry import displacement_from_poses, invert_transform, rotvec_from_matrix
from ..posemath import BoardPose, PoseEstimate, check_pose, perturb_pose, point_jacobian
from ..rig import Rig
from ..stats import chi2_ppf, chi2_sf
from ..targets import CharucoBoard, Chessboard
from .pose import corner_noise_factor

__all__ = [
    "FusedPose",
    "ViewPose",
    "fuse_poses",
    "board_symmetries",
    "to_rig_frame",
    "extrinsic_jacobian",
    "CONSISTENCY_QUANTILE",
    "FUSED_METHOD",
]

#: Quantile of the chi-square law above which the cameras' poses are said to disagree.
CONSISTENCY_QUANTILE = 0.9999
#: ``BoardPose.method`` of a pose fused from two or more cameras (a single view keeps its own).
FUSED_METHOD = "fused"
#: Largest number of re-linearisations of the weighted mean.
_MAX_PASSES = 3


@dataclass(frozen=True)
class ViewPose:
    """One camera's view of a board, as it entered the fusion.

    Attributes
    ----------
    camera : str
        The camera's name in the rig.
    index : int
        Its position in the rig.
    pose : BoardPose
        The pose as that camera measured it (``board2cam``, camera frame, the camera's own
        corner numbering).
    board2rig : ndarray, shape (4, 4), mm
        That pose in the rig frame, re-expressed in the fused board frame (``symmetry``).
    cov_noise : ndarray, shape (6, 6)
        Its noise covariance in the rig frame (t mm, r rad).
    offset : ndarray, shape (6,)
        (t, rotation vector) of this view's board2rig about the fused pose, mm and rad.
    symmetry : str
        ``"none"``, ``"half turn"``, ``"quarter turn"`` or ``"three-quarter turn"``: the board
        symmetry applied to bring the camera's numbering to the fused one.
    """

    camera: str
    index: int
    pose: BoardPose
    board2rig: np.ndarray
    cov_noise: np.ndarray
    offset: np.ndarray
    symmetry: str = "none"

    @property
    def rms_px(self) -> float:
        return self.pose.rms_px

    @property
    def method(self) -> str:
        return self.pose.method

    @property
    def fallback(self) -> str | None:
        return self.pose.fallback


@dataclass(frozen=True)
class FusedPose(PoseEstimate):
    """A board's pose in the rig frame from every camera that saw it (see the module docstring).

    A :class:`~stiffmap.posemath.PoseEstimate` whose pose is ``board2rig`` (the rig frame plays
    the camera frame: ``board2frame`` is ``board2rig``) and whose ``calibration_jacobian`` is
    over ``rig.param_names``.
    The corner statistics pool the views: ``rms_px`` over all their corners, ``n_corners``
    their sum, ``residuals_px`` stacked in the order of ``views``, ``sigma_px`` pooled.
    ``method`` is the view's own for one camera, ``"fused"`` for several; ``fallback`` names
    each camera whose photometric refinement fell back; ``iterations`` counts the passes of
    the weighted mean.

    Attributes
    ----------
    board2rig : ndarray, shape (4, 4), mm
        The board's pose in the rig frame (a keyword argument).
    views : tuple of ViewPose
        The cameras that saw the board, in the rig's order.
    chi2 : float
        The consistency statistic (0 for one camera).
    dof : int
        Its degrees of freedom, 6 (n - 1).
    consistency_warning : str or None
        Set when ``chi2`` exceeds the :data:`CONSISTENCY_QUANTILE` of its law.
    """

    board2rig: np.ndarray = field(kw_only=True)
    views: tuple[ViewPose, ...] = ()
    chi2: float = 0.0
    dof: int = 0
    consistency_warning: str | None = None

    @property
    def board2frame(self) -> np.ndarray:
        return self.board2rig

    @property
    def board2cam(self) -> np.ndarray:
        """One camera's view: that camera's own pose of the board (its frame; ``board2rig`` is
        the same when the camera frame is the rig's, as for a camera.json measured alone).

        Raises
        ------
        AttributeError
            Several cameras: there is no one camera frame (read ``board2rig``, or a view's).
        """
        if len(self.views) == 1:
            return self.views[0].pose.board2cam
        raise AttributeError(
            f"a pose fused from {len(self.views)} cameras has no one camera frame: read board2rig "
            "(the rig frame's) or views[i].pose.board2cam (camera i's)"
        )

    @property
    def cameras(self) -> tuple[str, ...]:
        """Names of the cameras that saw the board."""
        return tuple(v.camera for v in self.views)

    @property
    def p_value(self) -> float:
        """Probability of a chi2 at least this large when the cameras agree (1 for one camera)."""
        if self.dof == 0:
            return 1.0
        return chi2_sf(self.chi2, self.dof)


def to_rig_frame(board2cam: np.ndarray, cam2rig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``board2rig`` = cam2rig . board2cam and the map J = blockdiag(R_c, R_c) of its (t, r).

    Returns
    -------
    board2rig : ndarray, shape (4, 4), mm
    J : ndarray, shape (6, 6)
        d(t, r of board2rig) / d(t, r of board2cam), both left perturbations.
    """
    C = np.asarray(cam2rig, dtype=np.float64)
    T = C @ board2cam
    J = np.zeros((6, 6))
    J[:3, :3] = C[:3, :3]
    J[3:, 3:] = C[:3, :3]
    return T, J


def extrinsic_jacobian(board2cam: np.ndarray, cam2rig: np.ndarray) -> np.ndarray:
    """E = d(t, r of board2rig) / d(t, r of cam2rig), shape (6, 6): [[I, -[R_c t_b]x], [0, I]].

    ``board2cam``, ``cam2rig`` (4, 4) mm; both perturbations are (t (mm), r (rad)) left
    perturbations in the rig frame (:func:`~stiffmap.posemath.perturb_pose`): the board's
    origin is a point that cam2rig moves (:func:`~stiffmap.posemath.point_jacobian`).
    """
    return point_jacobian(cam2rig, np.asarray(board2cam, dtype=np.float64)[:3, 3])


def board_symmetries(board) -> list[tuple[str, np.ndarray]]:
    """The board-frame transforms S that map the board onto itself where detection cannot tell.

    ``board2cam @ S`` is then the same physical pose numbered from another corner. The identity
    always; the half turn about the board's centre when its colours do not fix the origin
    (``cols + rows`` even); quarter turns too for a square grid. ChArUco boards (the markers
    fix every corner's id) and ``None`` have the identity only.

    Returns
    -------
    list of (name, ndarray (4, 4))
    """
    out = [("none", np.eye(4))]
    if board is None or isinstance(board, CharucoBoard) or not isinstance(board, Chessboard):
        return out
    s = board.square_mm
    cx, cy = (board.cols - 1) * s / 2, (board.rows - 1) * s / 2

    def about_centre(angle_deg: int) -> np.ndarray:
        c, sn = {90: (0.0, 1.0), 180: (-1.0, 0.0), 270: (0.0, -1.0)}[angle_deg]
        S = np.eye(4)
        S[:2, :2] = [[c, -sn], [sn, c]]
        S[:2, 3] = np.array([cx, cy]) - S[:2, :2] @ [cx, cy]
        return S

    if not board.orientation_from_colours:
        out.append(("half turn", about_centre(180)))
    if board.cols == board.rows:
        out += [("quarter turn", about_centre(90)), ("three-quarter turn", about_centre(270))]
    return out


def _sym(C: np.ndarray) -> np.ndarray:
    return 0.5 * (C + C.T)


@dataclass
class _View:
    """One camera's view on its way to the fusion: its pose in the rig frame, noise covariance,
    sensitivity to the rig's parameters (None without), symmetry applied and consistency noise."""

    k: int
    T: np.ndarray
    N: np.ndarray
    B: np.ndarray | None
    symmetry: str
    Q: np.ndarray


def _views_by_index(rig: Rig, poses) -> dict[int, BoardPose]:
    """The poses by camera index, checked."""
    if not poses:
        raise ValueError("fuse_poses needs at least one camera's pose")
    views_in: dict[int, BoardPose] = {}
    for key, p in poses.items():
        k = rig.index(key) if isinstance(key, str) else int(key)
        if not 0 <= k < len(rig):
            raise ValueError(f"camera index {key!r} out of range ({len(rig)} cameras)")
        if k in views_in:
            raise ValueError(f"camera {rig.names[k]!r} given twice")
        check_pose(p.board2cam, f"{rig.names[k]} board2cam")
        views_in[k] = p
    return views_in


def _rig_sensitivity(rig: Rig, k: int, p: BoardPose, J: np.ndarray, C: np.ndarray) -> np.ndarray:
    """d(t, r of board2rig) / d(rig's parameters): J A_k in camera k's intrinsic columns, its
    extrinsic Jacobian in its extrinsic ones."""
    B = np.zeros((6, len(rig.param_names)))
    Ak = np.asarray(p.calibration_jacobian, dtype=np.float64)
    si = rig.intrinsic_slice(k)
    if Ak.shape != (6, si.stop - si.start):
        raise ValueError(
            f"camera {rig.names[k]!r}: calibration_jacobian must be (6, {si.stop - si.start}) "
            f"over its parameters, got {Ak.shape}"
        )
    B[:, si] = J @ Ak
    se = rig.extrinsic_slice(k)
    if se is not None:
        B[:, se] = extrinsic_jacobian(p.board2cam, C)
    return B


def _to_rig(rig: Rig, k: int, p: BoardPose, with_A: bool) -> _View:
    """One view in the rig frame: pose, noise covariance, sensitivity to the rig's parameters."""
    C = rig.cameras[k].cam2rig
    T, J = to_rig_frame(p.board2cam, C)
    N = _sym(J @ p.cov_noise @ J.T)
    B = _rig_sensitivity(rig, k, p, J, C) if with_A else None
    # The consistency test's noise: what the corners can tell (a photometric pose's own
    # covariance is too optimistic on real images), times their errors' correlation.
    corner = getattr(p.photometric, "corner_cov", None)
    Q = corner_noise_factor(p.residuals_px) * _sym(J @ (p.cov_noise if corner is None else corner) @ J.T)
    return _View(k, T, N, B, "none", Q)


def _align_numbering(mapped: list[_View], syms, ref: np.ndarray) -> None:
    """One board frame for all views: each re-expressed through the symmetry nearest to ``ref``."""
    if len(syms) <= 1:
        return
    for v in mapped:
        T = v.T
        angles = [np.linalg.norm(rotvec_from_matrix((T @ S)[:3, :3] @ ref[:3, :3].T)) for _, S in syms]
        j = int(np.argmin(angles))
        if j:
            name, S = syms[j]
            M = point_jacobian(T, S[:3, 3])  # d(t, r of T S) / d(t, r of T)
            v.T = T @ S
            v.N = _sym(M @ v.N @ M.T)
            v.Q = _sym(M @ v.Q @ M.T)
            v.B = None if v.B is None else M @ v.B
            v.symmetry = name


def _weighted_mean(Ts, Ws, cov_noise) -> tuple[np.ndarray, int]:
    """The information-weighted mean of poses Ts (two or more) and the passes it took: from
    the most informative view, re-linearised around the mean."""
    T_f = Ts[int(np.argmax([np.linalg.slogdet(W)[1] for W in Ws]))].copy()
    passes = 0
    for _ in range(_MAX_PASSES):
        passes += 1
        g = sum(W @ displacement_from_poses(T_f, T) for W, T in zip(Ws, Ts, strict=True))
        step = cov_noise @ g
        T_f = perturb_pose(T_f, step)
        if np.abs(step[:3]).max() < 1e-12 * max(1.0, np.abs(T_f[:3, 3]).max()) and (
            np.abs(step[3:]).max() < 1e-14
        ):
            break
    U, _, Vt = np.linalg.svd(T_f[:3, :3])
    T_f[:3, :3] = U @ Vt
    return T_f, passes


def _fused_sensitivity(mapped: list[_View], Ws, cov_noise, rig: Rig):
    """The fused pose's sensitivity A to the rig's parameters and the covariance it carries
    (None when the rig's uncertainty is unknown)."""
    if len(mapped) == 1:
        A = mapped[0].B
    else:
        A = cov_noise @ sum(W @ v.B for W, v in zip(Ws, mapped, strict=True))
    Sc = rig.calibration_cov
    cov_cal = _sym(A @ Sc @ A.T) if Sc is not None else None
    return A, cov_cal


def _pooled_stats(src: list[BoardPose], views, Wsum, passes: int) -> dict:
    """The fused pose's corner statistics, condition, method and fallback (one view: its own)."""
    if len(src) == 1:
        p0 = src[0]
        return dict(
            rms_px=p0.rms_px,
            n_corners=p0.n_corners,
            residuals_px=p0.residuals_px,
            sigma_px=p0.sigma_px,
            condition=p0.condition,
            iterations=p0.iterations,
            method=p0.method,
            photometric=p0.photometric,
            fallback=p0.fallback,
        )
    n_c = np.array([p.n_corners for p in src], dtype=float)
    dofs = np.maximum(2 * n_c - 6, 0)
    s2 = np.array([p.sigma_px**2 for p in src])
    fallbacks = [f"{v.camera}: {v.pose.fallback}" for v in views if v.pose.fallback]
    dist = float(np.mean([np.linalg.norm(p.board2cam[:3, 3]) for p in src]))
    D = np.diag([1.0, 1.0, 1.0] + [max(dist, 1.0)] * 3)
    Dinv = np.linalg.inv(D)
    return dict(
        rms_px=float(np.sqrt(np.sum(n_c * np.array([p.rms_px**2 for p in src])) / n_c.sum())),
        n_corners=int(n_c.sum()),
        residuals_px=np.concatenate([np.asarray(p.residuals_px).reshape(-1, 2) for p in src]),
        sigma_px=float(np.sqrt(np.sum(dofs * s2) / dofs.sum())) if dofs.sum() > 0 else float("nan"),
        condition=float(np.linalg.cond(Dinv @ Wsum @ Dinv)),
        iterations=passes,
        method=FUSED_METHOD,
        photometric=None,
        fallback="; ".join(fallbacks) or None,
    )


def fuse_poses(
    rig: Rig,
    poses: Mapping[int | str, BoardPose],
    *,
    board=None,
    reference: np.ndarray | None = None,
    label: str = "board",
) -> FusedPose:
    """One pose of a board in the rig frame from the poses the rig's cameras measured.

    Parameters
    ----------
    rig : Rig
    poses : mapping of int (or camera name) to BoardPose
        Camera index in ``rig`` (or its name) -> that camera's pose of the board (``board2cam``
        in its camera frame, ``cov_noise`` and ``calibration_jacobian`` over its own
        ``param_names``). At least one.
    board : Chessboard or CharucoBoard, optional
        The board, for its symmetries (:func:`board_symmetries`); without it the views are
        taken as numbered alike.
    reference : ndarray, shape (4, 4), optional
        A previous ``board2rig`` of the board (the previous image's fused pose): the views'
        numbering is brought to the one nearest to it (default: the first view's).
    label : str
        The board's name in the consistency warning (e.g. ``"mobile target (8x6 chessboard)"``).

    Returns
    -------
    FusedPose
        Its pose is ``board2rig``. One view: that camera's pose mapped to the rig frame
        (itself for the first camera).

    Raises
    ------
    ValueError
        No pose, an unknown camera, or a pose that is not a (4, 4) rigid transform.
    """
    views_in = _views_by_index(rig, poses)
    order = sorted(views_in)
    with_A = all(views_in[k].calibration_jacobian is not None for k in order)
    mapped = [_to_rig(rig, k, views_in[k], with_A) for k in order]
    ref = check_pose(reference, "reference") if reference is not None else mapped[0].T
    _align_numbering(mapped, board_symmetries(board), ref)
    Ts = [v.T for v in mapped]
    Ns = [v.N for v in mapped]
    Ws = [np.linalg.inv(N) for N in Ns] if len(mapped) > 1 else []
    Wsum = sum(Ws)
    if len(mapped) == 1:
        # One view: itself (no inversion round trip).
        cov_noise, T_f, passes = Ns[0], Ts[0].copy(), 0
    else:
        cov_noise = _sym(np.linalg.inv(Wsum))
        T_f, passes = _weighted_mean(Ts, Ws, cov_noise)
    offsets = [displacement_from_poses(T_f, T) for T in Ts]
    A, cov_cal = _fused_sensitivity(mapped, Ws, cov_noise, rig) if with_A else (None, None)
    cov = cov_noise if cov_cal is None else cov_noise + cov_cal
    views = tuple(
        ViewPose(rig.names[v.k], v.k, views_in[v.k], v.T, v.N, off, v.symmetry)
        for v, off in zip(mapped, offsets, strict=True)
    )
    chi2, dof = _consistency(
        [v.Q for v in mapped],
        [v.B for v in mapped],
        offsets,
        rig.calibration_cov if with_A else None,
        _dispersion_terms(rig, mapped),
    )
    return FusedPose(
        board2rig=T_f,
        cov=_sym(cov),
        calibration_jacobian=A,
        cov_calibration=cov_cal,
        views=views,
        chi2=chi2,
        dof=dof,
        consistency_warning=_consistency_warning(views, chi2, dof, label),
        **_pooled_stats([views_in[k] for k in order], views, Wsum, passes),
    )


def _dispersion_terms(rig: Rig, mapped: list[_View]) -> tuple[np.ndarray, np.ndarray] | None:
    """(G, D): the views' stacked sensitivities G to their cameras' ``cam2rig`` perturbations (the
    extrinsic Jacobian at each view's board origin, in the rig's parameter columns) and the rig's
    dispersion D over them; None when the rig has no dispersion."""
    D = rig.dispersion
    if D is None:
        return None
    G = np.zeros((6 * len(mapped), len(rig.param_names)))
    for i, v in enumerate(mapped):
        se = rig.extrinsic_slice(v.k)
        if se is not None:
            C = rig.cameras[v.k].cam2rig
            G[6 * i : 6 * i + 6, se] = extrinsic_jacobian(invert_transform(C) @ v.T, C)
    return G, D


def _consistency(Ns, Bs, offsets, Sc, dispersion=None) -> tuple[float, int]:
    """chi2 = min_x (r - H x)^T V^-1 (r - H x) over the stacked views' offsets r, and 6 (n - 1).

    V = blockdiag(N_k) + B Sc B^T (B the views' stacked sensitivities to the rig's
    parameters) when the rig's calibration covariance is known, else blockdiag(N_k); plus
    G D G^T with the rig's dispersion (``dispersion`` = (G, D), :func:`_dispersion_terms`).
    """
    n = len(Ns)
    if n < 2:
        return 0.0, 0
    V = np.zeros((6 * n, 6 * n))
    for i, N in enumerate(Ns):
        V[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = N
    if Sc is not None and all(B is not None for B in Bs):
        Bst = np.vstack(Bs)
        V += Bst @ Sc @ Bst.T
    if dispersion is not None:
        G, D = dispersion
        V += G @ D @ G.T
    # Scale translations and rotations alike before solving (mm against rad).
    scale = np.sqrt(np.diag(V))
    Vs = V / np.outer(scale, scale)
    r = np.concatenate(offsets) / scale
    H = np.vstack([np.eye(6)] * n) / scale[:, None]
    Vi_r = np.linalg.solve(Vs, r)
    Vi_H = np.linalg.solve(Vs, H)
    g = H.T @ Vi_r
    chi2 = float(r @ Vi_r - g @ np.linalg.solve(H.T @ Vi_H, g))
    return max(chi2, 0.0), 6 * (n - 1)


@lru_cache(maxsize=16)
def _chi2_limit(dof: int) -> float:
    return chi2_ppf(CONSISTENCY_QUANTILE, dof)


def _consistency_warning(views, chi2: float, dof: int, label: str) -> str | None:
    if dof == 0:
        return None
    limit = _chi2_limit(dof)
    if not chi2 > limit:
        return None
    parts = ", ".join(
        f"{v.camera} {1000 * np.linalg.norm(v.offset[:3]):.1f} um / "
        f"{1000 * np.linalg.norm(v.offset[3:]):.2f} mrad"
        for v in views
    )
    return (
        f"the cameras disagree on the pose of the {label}: chi2 = {chi2:.0f} for {dof} degrees of freedom, "
        f"above its {100 * CONSISTENCY_QUANTILE:g} % quantile {limit:.1f} (each camera's pose from the "
        f"fused one: {parts}); is the rig file this rig's, did a camera move since it was calibrated, or "
        "did the board move between the cameras' exposures?"
    )
