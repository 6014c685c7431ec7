"""The photometric refinement of a chessboard's pose: :func:`refine_pose_photometric`.

From the corner-based pose, two passes of the solver
(:mod:`~stiffmap.vision.photometric.solver`): the first on an eighth of the selected
pixels (:mod:`~stiffmap.vision.photometric.pixels`) with equal weights, which brings the
fit near its optimum and gives the residuals a noise model var = alpha + beta I is
fitted to; then, the pixels selected again when the fitted blur differs from the
starting one, every pixel with weights from the noise model. The fit is then accepted
or refused (:mod:`~stiffmap.vision.photometric.acceptance`) and returned as a
:class:`~stiffmap.posemath.BoardPose` with its quality (:class:`PhotometricFit`).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace

import numpy as np

from ...camera import CameraModel
from ...posemath import BoardPose, projection_jacobian
from ...targets import CharucoBoard, Chessboard
from ..images import check_image
from .acceptance import accept_fit, check_blur
from .model import model_and_jacobian
from .pixels import MIN_PIXELS, PhotometricError, PhotometricSetup, check_board2cam, prepare_pixels
from .solver import FitState, fit_noise_model, gauss_newton, linear_shading

__all__ = ["PhotometricFit", "PhotometricTrack", "REUSE_PX", "FOLLOW_PX", "refine_pose_photometric"]


#: Gauss-Newton stops after a step shorter than this many standard deviations (in the metric
#: of the normal matrix): the model is so nearly linear over the start's distance (a few
#: sigma) that the remaining error is below 0.01 sigma (checked against 0.01).
_TOL_SIGMA = 3.0


@dataclass(frozen=True)
class PhotometricFit:
    """Quality and nuisance parameters of a photometric pose fit.

    Attributes
    ----------
    rms_dn : float
        RMS of the residuals (image minus model) over the pixels used, digital numbers (DN).
    noise_rms_dn : float
        RMS of the modelled noise sigma over the pixels used, DN (rms_dn / noise_rms_dn near 1:
        the model explains the image down to its noise).
    scale : float
        s = sqrt(sum w r^2 / (N - p)), residuals in units of the modelled noise (1: as expected).
    n_pixels : int
        Pixels used.
    outlier_fraction : float
        Fraction of the pixels down-weighted by the Huber weights.
    blur_px : float
        Fitted effective Gaussian blur sigma (optics and pixel integration), px, mean over
        the edges' directions.
    blur_anisotropy_px : (float, float)
        Its variation with the direction theta of an edge's normal: sigma(theta) =
        blur_px + b1 cos 2 theta + b2 sin 2 theta.
    dilation_px : float
        Fitted growth of the black squares, px (ink spread, a non-linear camera response,
        sharpening: each black/white edge moved towards its white side).
    dilation_anisotropy_px : (float, float)
        Its variation with the edge's direction, as for the blur.
    noise_model : (float, float)
        (alpha DN^2, beta DN): noise variance alpha + beta * I.
    shading_a, shading_b : ndarray
        Coefficients of the black level and of the contrast polynomials (DN), in the
        monomials of (u - u0) / L, (v - v0) / L (see :class:`PhotometricSetup`).
    iterations : int
        Gauss-Newton iterations (all passes).
    converged : bool
    seconds : float
    warm_start : bool
        The fit started from the previous image's fit of the board (:class:`PhotometricTrack`).
    corner_cov : ndarray, shape (6, 6), or None
        The noise covariance of the corner pose the fit was checked against
        (:func:`~stiffmap.vision.pose.estimate_pose` sets it): what the corners alone can tell,
        used where the pixels' own covariance is too optimistic on real images (a rig's
        consistency test, :mod:`~stiffmap.vision.fuse`).
    inner_only : bool
        The fit used only the edges between the inner corners (the whole board's model did not
        fit: outer squares cut short, a margin that is not white).
    """

    rms_dn: float
    noise_rms_dn: float
    scale: float
    n_pixels: int
    outlier_fraction: float
    blur_px: float
    blur_anisotropy_px: tuple[float, float]
    dilation_px: float
    dilation_anisotropy_px: tuple[float, float]
    noise_model: tuple[float, float]
    shading_a: np.ndarray
    shading_b: np.ndarray
    iterations: int
    converged: bool
    seconds: float
    warm_start: bool = False
    corner_cov: np.ndarray | None = None
    inner_only: bool = False


#: The previous image's pixel set is reused while the start pose moves the board's outline by
#: less than this, px (the bands and corner zones then shift by at most this much).
REUSE_PX = 0.25
#: The previous image's linearisation (Jacobian, normal matrix, weights) starts the fit while the
#: start pose moves the board's outline by less than this from where it was taken, px (the
#: Jacobian then differs by ~LIN_PX / blur, a few %); its steps then follow
#: :data:`~stiffmap.vision.photometric.solver.CHORD_SIGMA`'s rule. The calibration sensitivity of
#: a pose is kept within the same distance.
LIN_PX = 0.1
#: Chord steps (no new Jacobian) allowed after each linearisation of a warm-started fit.
_WARM_CHORD_STEPS = 2
#: A fit started from the previous image's pose alone (``warm_only``, no corners measured in
#: this image) is kept only when the board's outline moved by less than this from that pose, px
#: (the pixel set, chosen there, then still holds every edge's band), ...
FOLLOW_PX = 0.5
#: ... and its residuals' variance s^2 (in units of the modelled noise) is at most this many
#: times the previous fit's: a board that moved by a square or more, a changed scene or a
#: partly covered board leave the model's edges where the image has none (s^2 grows many-fold).
S2_GROWTH = 1.5
#: Iterations allowed to such a fit (it takes 2-3 when the board barely moved; one that moved
#: far takes many and would fail the checks above anyway).
FOLLOW_MAX_ITER = 4


class PhotometricTrack:
    """What one board's photometric fit leaves for the next image of a sequence (a warm start).

    In a sequence of one robot position the board barely moves between images. The next fit of
    the board then starts from this one: the same pixel set (only the pixels' values are read
    from the new image) while the start pose moves the board's outline by less than
    :data:`REUSE_PX` px (and the left-out areas moved by less than 1 px, or miss the pixels it
    looked at), else a new one selected for the fitted blur; the blur, dilation and shading of
    the last fit as the start of those parameters, and its noise model for the weights (refitted
    to each fit's residuals). The pass on an eighth of the pixels and the set-up of the cold fit
    are skipped, and the fit runs in single precision with chord steps (the Jacobian of the
    start reused, :func:`~stiffmap.vision.photometric.solver.gauss_newton`). The pose comes from
    the same model and the same cost as the cold fit's; a warm fit that fails any check falls
    back to the cold fit, and a failed cold fit clears the track.

    Used by :class:`~stiffmap.vision.sequence.PoseTracker` (one per camera and board).
    """

    def __init__(self) -> None:
        self._last: dict | None = None
        self._sensitivity: tuple | None = None
        #: The board's fits keep to its inner squares (the whole board's model did not fit it:
        #: :func:`~stiffmap.vision.pose.estimate_pose`); kept across :meth:`clear`.
        self.inner_only = False

    def clear(self) -> None:
        """Forget the last fit (the next one is cold)."""
        self._last = None
        self._sensitivity = None

    @property
    def ready(self) -> bool:
        """True when a fit is recorded (the next may start from it)."""
        return self._last is not None

    def start(self, img, board, camera, T0, exclude, options) -> dict | None:
        """The recorded fit when it may start this one (same board, camera, image type and options)."""
        last = self._last
        if last is None:
            return None
        if (
            last["board"] != board
            or last["camera"] != camera.key
            or last["shape"] != img.shape
            or last["dtype"] != img.dtype
            or last["options"] != options
        ):
            return None
        moved = _outline_shift(camera, board, T0, last["select_pose"])
        if not moved < board.square_mm * camera.fx / max(T0[2, 3], 1.0):
            return None  # moved by a square or more: a new start
        polys = _polygons(exclude)
        region = last["setup"].region
        same_exclusion = (
            len(polys) == len(last["exclude"])
            and all(
                p.shape == q.shape and float(np.max(np.abs(p - q), initial=0.0)) < 1.0
                for p, q in zip(polys, last["exclude"], strict=True)
            )
        ) or not (_meets(polys, region) or _meets(last["exclude"], region))
        return dict(last, reuse=moved < REUSE_PX and same_exclusion)

    def sensitivity(self, camera: CameraModel, board: Chessboard, T: np.ndarray) -> np.ndarray | None:
        """The calibration sensitivity of the last pose it was computed at, when ``T`` moves the
        board's outline by less than :data:`LIN_PX` px from it (it changes by ~1e-4 there)."""
        kept = self._sensitivity
        if kept is None or kept[2] != (board, camera.key):
            return None
        return kept[1] if _outline_shift(camera, board, T, kept[0]) < LIN_PX else None

    def keep_sensitivity(self, T: np.ndarray, A: np.ndarray, camera: CameraModel, board: Chessboard) -> None:
        """Keep the calibration sensitivity A computed at pose T."""
        self._sensitivity = (np.array(T, dtype=np.float64), A, (board, camera.key))

    def record_cold(self, img, setup, select_pose, select_blur, exclude, options, st, sol, board, camera, s2):
        """Keep a cold fit (its pixel set in single precision) for the next image."""
        w = img.shape[1]
        flat = setup.v.astype(np.int64) * w + setup.u.astype(np.int64)
        self._last = {
            "board": board,
            "camera": camera.key,
            "shape": img.shape,
            "dtype": img.dtype,
            "options": options,
            "select_pose": np.array(select_pose, dtype=np.float64),
            "select_blur": float(select_blur),
            "exclude": _polygons(exclude),
            "setup": setup.astype(np.float32),
            "flat": flat,
            "state": st,
            "noise": fit_noise_model(*_sample(setup, sol)),
            "lin": None,
            "s2": s2,
        }

    def record_warm(self, img, warm, T0, exclude, st, sol, setup, full: bool, s2: float) -> None:
        """Keep the state and noise model of a warm fit, and its pixel set when it was new."""
        last = self._last
        if last is None:  # pragma: no cover - a warm fit needs a record
            return
        if not warm["reuse"]:
            last["setup"] = setup
            last["flat"] = setup.v.astype(np.int64) * img.shape[1] + setup.u.astype(np.int64)
            last["select_pose"] = np.array(T0, dtype=np.float64)
            last["exclude"] = _polygons(exclude)
        last["state"] = st
        last["noise"] = fit_noise_model(*_sample(setup, sol, 32))
        last["lin"] = sol.lin if full else None
        last["s2"] = s2


def _outline_shift(camera: CameraModel, board: Chessboard, Ta: np.ndarray, Tb: np.ndarray) -> float:
    """Largest motion of the checkered area's corners between two poses, px (pinhole: the lens
    distortion changes a motion of a few px by a few %). inf when a corner is behind the camera."""
    q = _outline(board.square_mm, board.cols, board.rows)
    Pa = q @ Ta[:3, :2].T + Ta[:3, 3]
    Pb = q @ Tb[:3, :2].T + Tb[:3, 3]
    if Pa[:, 2].min() <= 0 or Pb[:, 2].min() <= 0:
        return float("inf")
    d = np.abs(Pa[:, :2] / Pa[:, 2:] - Pb[:, :2] / Pb[:, 2:]).max(axis=0)
    return float(max(d[0] * camera.fx, d[1] * camera.fy))


@functools.lru_cache(maxsize=64)
def _outline(s: float, cols: int, rows: int) -> np.ndarray:
    """The corners of a board's checkered area, (4, 2) (board frame, mm)."""
    q = np.array([[-s, -s], [cols * s, -s], [-s, rows * s], [cols * s, rows * s]])
    q.setflags(write=False)
    return q


def _meets(
    polygons: list[np.ndarray], region: tuple[int, int, int, int] | None, margin_px: float = 2.0
) -> bool:
    """Whether any polygon's bounding box meets the pixel box ``region`` (c0, r0, c1, r1) grown
    by ``margin_px`` (if none does, a pixel set chosen in that box is the same with or without
    them); True for an unknown region (None) and any polygon."""
    if region is None:
        return bool(polygons)
    c0, r0, c1, r1 = region
    for p in polygons:
        if p.size == 0:
            continue
        lo, hi = p.min(axis=0), p.max(axis=0)
        if (
            hi[0] >= c0 - margin_px
            and lo[0] <= c1 + margin_px
            and hi[1] >= r0 - margin_px
            and lo[1] <= r1 + margin_px
        ):
            return True
    return False


def _polygons(exclude) -> list[np.ndarray]:
    return [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in exclude]


def _sample(setup: PhotometricSetup, sol, every: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Model values and residuals of every ``every``-th pixel (for the noise model)."""
    e = np.asarray(sol.e[::every], dtype=np.float64)
    return np.asarray(setup.values[::every], dtype=np.float64) - e, e


def _cold_fit(T0, blur_init, huber, max_iter, select, fail):
    """Today's fit from the corner pose: a pass on an eighth of the pixels, then every pixel."""
    setup = select(T0, blur_init)
    select_pose, select_blur = T0, blur_init
    # Pass 1, on an eighth of the pixels, equal weights: near the optimum, and residuals for
    # the noise model.
    n = setup.n_pixels
    sub = setup.subset(np.arange(0, n, 8)) if n >= 8 * MIN_PIXELS else setup
    sig0 = np.array([blur_init, 0.0, 0.0])
    st = FitState(T0, sig0, np.zeros(3), *linear_shading(sub, T0, sig0, np.zeros(3)))
    m0, _ = model_and_jacobian(sub, st.T, st.sig, st.dil, st.a, st.b, jacobian=False)
    e0 = sub.values - m0
    var0 = max(1.4826 * float(np.median(np.abs(e0 - np.median(e0)))), 0.3) ** 2
    sol = gauss_newton(sub, st, lambda m: np.full_like(m, var0), huber, max_iter, tol=1.0)
    iters = sol.iterations
    st = sol.state
    m1 = sub.values - sol.e
    alpha, beta = fit_noise_model(m1, sol.e)

    def noise_var(m):
        return alpha + beta * np.maximum(m, 0.0)

    try:
        check_blur(st.sig)
    except PhotometricError as e:
        raise fail(e.detail) from None
    # The blur is now known: select again when the bands and corner zones were set for another.
    sig_max = st.sig[0] + np.hypot(st.sig[1], st.sig[2])
    if sig_max > 1.15 * blur_init or sig_max < 0.7 * blur_init:
        setup = select(st.T, sig_max)
        select_pose, select_blur = st.T, sig_max
        st = FitState(st.T, st.sig, st.dil, *linear_shading(setup, st.T, st.sig, st.dil))
    # Pass 2, every pixel, weights from the noise model.
    sol = gauss_newton(setup, st, noise_var, huber, max_iter, tol=_TOL_SIGMA)
    iters += sol.iterations
    return setup, sol, (alpha, beta), iters, select_pose, select_blur


def _warm_fit(img, board, camera, warm, T0, huber, max_iter, select, follow=False):
    """The fit started from the previous image's (:class:`PhotometricTrack`), single precision.

    Returns the set-up, the solution, the noise model, the iterations and whether the set-up
    is the whole recorded (or new) pixel set (its linearisation may then serve the next image).
    """
    full = True
    if warm["reuse"]:
        vals = img.ravel().take(warm["flat"])
        setup = replace(warm["setup"], values=vals.astype(np.float32))
        sat = np.iinfo(img.dtype).max
        bad = (vals >= sat) | (vals == 0)
        if bad.any():
            setup = setup.subset(np.flatnonzero(~bad))
            full = False
    else:
        setup = select(T0, warm["select_blur"]).astype(np.float32)
    if setup.n_pixels < MIN_PIXELS:
        raise PhotometricError("too few pixels")
    prev = warm["state"]
    alpha, beta = warm["noise"]
    a32, b32 = np.float32(alpha), np.float32(beta)

    def noise_var(m):
        return a32 + b32 * np.maximum(m, np.float32(0.0))

    lin = warm["lin"] if warm["reuse"] and full else None
    if lin is not None and not _outline_shift(camera, board, T0, lin.state.T) < LIN_PX:
        lin = None
    st = FitState(T0, prev.sig.copy(), prev.dil.copy(), prev.a.copy(), prev.b.copy())

    def watch(s: FitState) -> None:
        # Following the board from the previous pose alone: stop as soon as it has moved too far.
        moved = _outline_shift(camera, board, s.T, T0)
        if not moved < FOLLOW_PX:
            raise PhotometricError(
                f"the board moved by {moved:.2f} px or more from the previous image (a fit from that "
                f"pose alone is kept below {FOLLOW_PX:g} px)"
            )

    sol = gauss_newton(
        setup,
        st,
        noise_var,
        huber,
        min(max_iter, 10),
        tol=_TOL_SIGMA,
        chord=_WARM_CHORD_STEPS,
        start=lin,
        watch=watch if follow else None,
    )
    sig = sol.state.sig
    sig_max = sig[0] + np.hypot(sig[1], sig[2])
    blur = warm["select_blur"]
    if sig_max > 1.15 * blur or sig_max < 0.7 * blur:
        raise PhotometricError("the blur changed: the pixel set is for another")
    return setup, sol, (alpha, beta), sol.iterations, full


def _check_followed(camera, board, T0, T, s2: float, s2_prev: float) -> None:
    """The checks of a fit from the previous image's pose alone (``warm_only``)."""
    moved = _outline_shift(camera, board, T, T0)
    if not moved < FOLLOW_PX:
        raise PhotometricError(
            f"the board moved by {moved:.2f} px from the previous image (a fit from that pose alone "
            f"is kept below {FOLLOW_PX:g} px)"
        )
    if not s2 <= S2_GROWTH * s2_prev:
        raise PhotometricError(
            f"the residuals grew {s2 / s2_prev:.1f}-fold over the previous image's (more than "
            f"{S2_GROWTH:g}): the board moved far, or the scene changed"
        )


def _check_refine_inputs(board, camera, blur_init_px) -> None:
    if isinstance(board, CharucoBoard):
        raise ValueError("the photometric model does not describe ChArUco boards (markers); use corners")
    if not isinstance(board, Chessboard):
        raise ValueError(f"board must be a Chessboard, got {type(board).__name__}")
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    if not (np.isfinite(blur_init_px) and blur_init_px > 0):
        raise ValueError(f"blur_init_px must be positive, got {blur_init_px}")


def _selector(img, board, camera, fail, *, band_px, shading_degree, outer_edges, exclude, phase, inner_only):
    """The pixel selection at a pose and a blur (:func:`prepare_pixels`), its failure worded by ``fail``."""

    def select(T, sig) -> PhotometricSetup:
        try:
            return prepare_pixels(
                img,
                board,
                camera,
                T,
                band_px=band_px,
                blur_px=sig,
                shading_degree=shading_degree,
                outer_edges=outer_edges,
                exclude=exclude,
                phase=phase,
                inner_only=inner_only,
            )
        except PhotometricError as e:
            raise fail(e.detail) from None

    return select


@dataclass
class _Outcome:
    """An accepted fit (warm or cold) and what the track keeps of it.

    ``warm`` is the warm start it came from (None: a cold fit); ``full`` whether a warm fit's
    set-up is the whole pixel set; ``select_pose`` and ``select_blur`` where a cold fit chose
    its pixels.
    """

    setup: PhotometricSetup
    sol: object
    noise: tuple[float, float]
    iters: int
    ok: object
    warm: dict | None = None
    full: bool = False
    select_pose: np.ndarray | None = None
    select_blur: float | None = None


def _warm_outcome(img, board, camera, warm, T0, settings, select, fail, warm_only) -> _Outcome | None:
    """The fit started from the previous image's, accepted; None when it fails and the cold
    fit follows (with ``warm_only`` its failure is raised instead)."""
    huber, max_iter, max_outlier_fraction = settings
    try:
        n_iter = min(max_iter, FOLLOW_MAX_ITER) if warm_only else max_iter
        setup, sol, (alpha, beta), iters, full = _warm_fit(
            img, board, camera, warm, T0, huber, n_iter, select, follow=warm_only
        )
        ok = accept_fit(sol, setup, n_iter, max_outlier_fraction)
        if warm_only:
            _check_followed(camera, board, T0, sol.state.T, ok.s2, warm["s2"])
    except PhotometricError as e:
        if warm_only:
            raise fail(e.detail) from None
        return None  # the image differs from the previous one: today's fit from the start
    return _Outcome(setup, sol, (alpha, beta), iters, ok, warm=warm, full=full)


def _cold_outcome(T0, blur_init, settings, select, fail, track) -> _Outcome:
    """Today's fit from the start pose, accepted (a refused fit clears the track)."""
    huber, max_iter, max_outlier_fraction = settings
    setup, sol, (alpha, beta), iters, select_pose, select_blur = _cold_fit(
        T0, blur_init, huber, max_iter, select, fail
    )
    try:
        ok = accept_fit(sol, setup, max_iter, max_outlier_fraction)
    except PhotometricError as e:
        if track is not None:
            track.clear()
        raise fail(e.detail) from None
    return _Outcome(setup, sol, (alpha, beta), iters, ok, select_pose=select_pose, select_blur=select_blur)


def _corner_residuals(detection, T, camera):
    """The detected corners' reprojection residuals at pose T: (residuals (m, 2) px, m,
    rms px, sigma px); none (NaN) without a detection."""
    if detection is not None and detection.n_corners > 0:
        obj = detection.object_points()
        uv, _ = projection_jacobian(T, obj, camera)
        res = np.asarray(detection.corners, dtype=np.float64) - uv
        mc = len(obj)
        rms_px = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
        sigma_px = float(np.sqrt(np.sum(res**2) / max(2 * mc - 6, 1)))
        return res, mc, rms_px, sigma_px
    return np.zeros((0, 2)), 0, float("nan"), float("nan")


def _fit_quality(out: _Outcome, t_start: float, inner_only: bool) -> PhotometricFit:
    st, sol, ok = out.sol.state, out.sol, out.ok
    e, var = sol.e, sol.var
    return PhotometricFit(
        rms_dn=float(np.sqrt(np.mean(e * e))),
        noise_rms_dn=float(np.sqrt(np.mean(var))),
        scale=float(np.sqrt(ok.s2)),
        n_pixels=int(e.size),
        outlier_fraction=ok.outlier_fraction,
        blur_px=float(st.sig[0]),
        blur_anisotropy_px=(float(st.sig[1]), float(st.sig[2])),
        dilation_px=float(st.dil[0]),
        dilation_anisotropy_px=(float(st.dil[1]), float(st.dil[2])),
        noise_model=out.noise,
        shading_a=st.a.copy(),
        shading_b=st.b.copy(),
        iterations=out.iters,
        converged=sol.converged,
        seconds=time.perf_counter() - t_start,
        warm_start=out.warm is not None,
        inner_only=bool(inner_only),
    )


def _record(track: PhotometricTrack, out: _Outcome, img, T0, exclude, options, board, camera) -> None:
    """Keep the fit in the track for the next image."""
    st, sol, s2 = out.sol.state, out.sol, out.ok.s2
    if out.warm is None:
        track.record_cold(
            img, out.setup, out.select_pose, out.select_blur, exclude, options, st, sol, board, camera, s2
        )
    else:
        track.record_warm(img, out.warm, T0, exclude, st, sol, out.setup, out.full, s2)


# Longer than ~80 lines for its interface alone: 17 keyword parameters (the public API, kept as
# callers use it) and their documentation take ~100 lines; the body (~50 lines) is the steps
# above (_selector, _warm_outcome or _cold_outcome, _corner_residuals, _fit_quality, _record).
def refine_pose_photometric(
    image,
    board: Chessboard,
    camera: CameraModel,
    board2cam_init,
    *,
    detection=None,
    blur_init_px: float = 1.0,
    band_px: float | None = None,
    shading_degree: int = 2,
    outer_edges: bool = True,
    exclude=(),
    huber: float = 3.0,
    max_iter: int = 30,
    max_outlier_fraction: float = 0.3,
    source: str | None = None,
    phase: int | None = None,
    track: PhotometricTrack | None = None,
    warm_only: bool = False,
    inner_only: bool = False,
):
    """Refine a chessboard's pose by fitting a model of the blurred board to its pixels.

    See the module docstring for the model and the fit.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8 or uint16 (or BGR uint8, converted to grey)
    board : Chessboard
    camera : CameraModel
    board2cam_init : array_like, shape (4, 4), mm
        Starting pose, within a small fraction of a square of the truth (e.g. the
        corner-based pose of :func:`~stiffmap.vision.pose.estimate_pose`).
    detection : BoardDetection, optional
        The board's detected corners: then ``rms_px``, ``residuals_px`` and
        ``sigma_px`` of the result are the corners' reprojection errors at the
        photometric pose; without it they are NaN / empty and ``n_corners`` is 0.
    blur_init_px : float
        Starting effective blur sigma, px.
    band_px : float, optional
        Half-width of the band of pixels used along every grid line, px (default
        :data:`~stiffmap.vision.photometric.pixels.BAND_SIGMAS` blur sigmas, at least
        :data:`~stiffmap.vision.photometric.pixels.BAND_MIN_PX`).
    shading_degree : int
        Degree (0, 1, 2) of the black-level and contrast polynomials over the image.
    outer_edges : bool
        Use the outer edges of the checkered area against the white margin.
    exclude : sequence of array_like, shape (k, 2)
        Polygons (px) left out (the other board, known obstructions).
    huber : float
        Huber threshold, in noise sigmas.
    max_iter : int
        Largest number of Gauss-Newton iterations per pass.
    max_outlier_fraction : float
        Refuse the fit when more than this fraction of the pixels are down-weighted as
        outliers (an obstructed board).
    source : str, optional
        Image name for error messages.
    phase : {0, 1}, optional
        Colour phase of the board (square (i, j) black when i + j + phase is even);
        default ``detection.phase``, else 0.
    track : PhotometricTrack, optional
        The board's fit in the previous image of a sequence (updated here): when the board
        has barely moved, the fit starts from it (:class:`PhotometricTrack`).
    warm_only : bool
        Only the warm start from ``track``, from a start pose that is the previous image's
        fitted pose (no corners measured in this image): raise :class:`PhotometricError`
        (``track`` unchanged) instead of fitting from the start when there is no warm start or
        it fails, when the fitted outline moved :data:`FOLLOW_PX` px or more from the start,
        or when s^2 grew more than :data:`S2_GROWTH` times over the previous fit's.
    inner_only : bool
        Fit only the edges between the inner corners (see
        :func:`~stiffmap.vision.photometric.pixels.prepare_pixels`).

    Returns
    -------
    BoardPose
        ``method == "photometric"``; ``cov`` (6, 6) over (t mm, r rad) as in
        ``docs/conventions.md``; ``photometric`` holds the fit's quality and
        nuisance parameters (:class:`PhotometricFit`, residual RMS in DN).

    Raises
    ------
    PhotometricError
        Too few usable pixels, a singular or diverging fit, an implausible blur or
        contrast, or too many pixels rejected as outliers.
    ValueError
        Inputs of the wrong type or shape.
    """
    t_start = time.perf_counter()
    _check_refine_inputs(board, camera, blur_init_px)
    T0 = check_board2cam(board2cam_init)
    img = check_image(image, uint16=True)
    colour_phase = int(phase if phase is not None else getattr(detection, "phase", 0))

    def fail(msg: str) -> PhotometricError:
        return PhotometricError(f"{board.size} chessboard: photometric fit: {msg}", source=source)

    options = (band_px, int(shading_degree), bool(outer_edges), colour_phase, bool(inner_only))
    select = _selector(
        img,
        board,
        camera,
        fail,
        band_px=band_px,
        shading_degree=shading_degree,
        outer_edges=outer_edges,
        exclude=exclude,
        phase=colour_phase,
        inner_only=inner_only,
    )
    settings = (huber, max_iter, max_outlier_fraction)
    warm = track.start(img, board, camera, T0, exclude, options) if track is not None else None
    if warm_only and warm is None:
        raise fail("no warm start from the previous image")
    out = None
    if warm is not None:
        out = _warm_outcome(img, board, camera, warm, T0, settings, select, fail, warm_only)
    if out is None:
        out = _cold_outcome(T0, float(blur_init_px), settings, select, fail, track)
    T = out.sol.state.T.copy()
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T[:3, :3] = U @ Vt
    res, mc, rms_px, sigma_px = _corner_residuals(detection, T, camera)
    fit = _fit_quality(out, t_start, inner_only)
    if track is not None:
        _record(track, out, img, T0, exclude, options, board, camera)
    return BoardPose(
        board2cam=T,
        cov=out.ok.cov,
        rms_px=rms_px,
        n_corners=mc,
        residuals_px=res,
        sigma_px=sigma_px,
        condition=out.ok.condition,
        iterations=out.iters,
        method="photometric",
        photometric=fit,
    )
