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

import time
from dataclasses import dataclass

import numpy as np

from ...camera import CameraModel
from ...posemath import BoardPose, projection_jacobian
from ...targets import CharucoBoard, Chessboard
from ..images import check_image
from .acceptance import accept_fit, check_blur
from .model import model_and_jacobian
from .pixels import MIN_PIXELS, PhotometricError, PhotometricSetup, check_board2cam, prepare_pixels
from .solver import FitState, fit_noise_model, gauss_newton, linear_shading

__all__ = ["PhotometricFit", "refine_pose_photometric"]


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
        2.5 blur sigmas, at least 2 px).
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
    if isinstance(board, CharucoBoard):
        raise ValueError("the photometric model does not describe ChArUco boards (markers); use corners")
    if not isinstance(board, Chessboard):
        raise ValueError(f"board must be a Chessboard, got {type(board).__name__}")
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    if not (np.isfinite(blur_init_px) and blur_init_px > 0):
        raise ValueError(f"blur_init_px must be positive, got {blur_init_px}")
    T0 = check_board2cam(board2cam_init)
    img = check_image(image, uint16=True)
    colour_phase = int(phase if phase is not None else getattr(detection, "phase", 0))

    def fail(msg: str) -> PhotometricError:
        return PhotometricError(f"{board.size} chessboard: photometric fit: {msg}", source=source)

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
                phase=colour_phase,
            )
        except PhotometricError as e:
            raise fail(e.detail) from None

    setup = select(T0, float(blur_init_px))
    # Pass 1, on an eighth of the pixels, equal weights: near the optimum, and residuals for
    # the noise model.
    n = setup.n_pixels
    sub = setup.subset(np.arange(0, n, 8)) if n >= 8 * MIN_PIXELS else setup
    sig0 = np.array([float(blur_init_px), 0.0, 0.0])
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
    if sig_max > 1.15 * blur_init_px or sig_max < 0.7 * blur_init_px:
        setup = select(st.T, sig_max)
        st = FitState(st.T, st.sig, st.dil, *linear_shading(setup, st.T, st.sig, st.dil))
    # Pass 2, every pixel, weights from the noise model.
    sol = gauss_newton(setup, st, noise_var, huber, max_iter, tol=_TOL_SIGMA)
    iters += sol.iterations
    st = sol.state
    try:
        ok = accept_fit(sol, setup, max_iter, max_outlier_fraction)
    except PhotometricError as e:
        raise fail(e.detail) from None
    e, var = sol.e, sol.var
    T = st.T.copy()
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T[:3, :3] = U @ Vt
    if detection is not None and detection.n_corners > 0:
        obj = detection.object_points()
        uv, _ = projection_jacobian(T, obj, camera)
        res = np.asarray(detection.corners, dtype=np.float64) - uv
        mc = len(obj)
        rms_px = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
        sigma_px = float(np.sqrt(np.sum(res**2) / max(2 * mc - 6, 1)))
    else:
        res = np.zeros((0, 2))
        mc = 0
        rms_px = sigma_px = float("nan")
    fit = PhotometricFit(
        rms_dn=float(np.sqrt(np.mean(e * e))),
        noise_rms_dn=float(np.sqrt(np.mean(var))),
        scale=float(np.sqrt(ok.s2)),
        n_pixels=int(e.size),
        outlier_fraction=ok.outlier_fraction,
        blur_px=float(st.sig[0]),
        blur_anisotropy_px=(float(st.sig[1]), float(st.sig[2])),
        dilation_px=float(st.dil[0]),
        dilation_anisotropy_px=(float(st.dil[1]), float(st.dil[2])),
        noise_model=(alpha, beta),
        shading_a=st.a.copy(),
        shading_b=st.b.copy(),
        iterations=iters,
        converged=sol.converged,
        seconds=time.perf_counter() - t_start,
    )
    return BoardPose(
        board2cam=T,
        cov=ok.cov,
        rms_px=rms_px,
        n_corners=mc,
        residuals_px=res,
        sigma_px=sigma_px,
        condition=ok.condition,
        iterations=iters,
        method="photometric",
        photometric=fit,
    )
