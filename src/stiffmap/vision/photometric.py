"""Direct (photometric) refinement of a chessboard's pose: a model of the blurred board fitted to its pixels.

Corner-based poses use small windows around the corners; the depth of a
planar board then comes from its apparent scale, measured by a few hundred
corners of ~0.02 px noise. This module fits a model of the whole blurred
chessboard to every pixel near the board's edges (``docs/vision.md``,
"Photometric pose refinement"): 3.4-5.9 times more precise along the line of
sight on the virtual test-bed's realistic renders.

Model. Each pixel centre p has a ray (x/z, y/z) (the lens distortion inverted,
from the camera's ray cache: it does not depend on the pose). With the board plane's
homography H = [r1, r2, t] (``board2cam`` = [R | t]), the ray meets the board
at w = H^-1 (x/z, y/z, 1), (X, Y) = (w0 / w2, w1 / w2) mm. The printed
pattern is, with the square waves Sx = (-1)^floor(X / s) and Sy likewise and
the indicators Ix, Iy of the checkered area [-s, cols s] x [-s, rows s]
(square (i, j) black when i + j is even, ``docs/conventions.md``; white
margin around),

    white(X, Y) = 1 - (Ix Iy + (Ix Sx)(Iy Sy)) / 2.

The image sees it blurred by the optics and integrated over the pixel, taken as
a Gaussian of ``sigma`` px across each edge (the effective blur, pixel box
included: sigma^2 = sigma_psf^2 + 1/12). Near a grid line X = k s, at the
signed distance dX = (X - k s) / |grad_p X| px from it (the local mm -> px
scale of the map), the blurred Ix and Ix Sx are A + (B - A) Phi((dX -/+ delta)
/ sigma), with A and B their values on either side, Phi the normal
distribution function and delta the growth of the black squares (ink spread, a
non-linear response: each edge moves towards its white side); likewise along
Y. sigma and delta may vary with the direction theta of the edge's normal in
the image (b0 + b1 cos 2 theta + b2 sin 2 theta: an elongated blur). The model
is the separable product

    c = 1 - (Fx Fy + Gx Gy) / 2,     I_model = a(p) + b(p) c,

with a (black level) and b (contrast) polynomials of degree ``shading_degree``
(default 2: the cos^4 vignetting) in the pixel coordinates. The product is
exact where the blur along one axis has saturated; pixels within 3 sigma of
both an X and a Y line (the corners, where the blur is not separable in board
coordinates when the board is seen obliquely) are left out. So are pixels
farther than ``band_px`` from every line (no information on the pose), outside
the checkered area grown by the band (the margin beyond and the background are
not modelled), saturated pixels, and pixels inside ``exclude`` polygons
(another board).

Fit. Gauss-Newton (Levenberg-Marquardt damped) with the analytic Jacobian of
:func:`model_and_jacobian` over the pose (perturbation t <- t + dt,
R <- Exp(dr) R in the camera frame, ``docs/conventions.md``), the blur and
dilation terms and the shading coefficients, started from the corner-based
pose: a first pass on an eighth of the pixels with equal weights, a noise model
var = alpha + beta I (read noise + photon shot noise) fitted to its residuals,
then all pixels with weights 1 / var and Huber weights (``huber`` noise sigmas)
against a partly bad region.

Covariance: cov = s^2 (J^T W J)^-1, pose block (t, r), s^2 = sum w r^2 / (N - p)
with r the residuals in units of the modelled noise sigma. Pixels' noise is
taken as independent (true of sensor noise, not of JPEG artefacts or of a model
error correlated along an edge, which make the covariance optimistic).

ChArUco boards (markers in the white squares) are not modelled.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import ndtr

from ..camera import CameraModel, pixel_rays
from ..errors import InputError
from ..targets import CharucoBoard, Chessboard
from .images import check_image

__all__ = [
    "PhotometricFit",
    "PhotometricError",
    "PhotometricSetup",
    "prepare_pixels",
    "model_and_jacobian",
    "refine_pose_photometric",
]

_SQRT_2PI = np.sqrt(2.0 * np.pi)
#: Corner zones: pixels within this many blur sigmas of both an X and a Y line are left out.
CORNER_SIGMAS = 3.0
#: Fewest pixels for a fit.
MIN_PIXELS = 200
#: Least contrast (1st percentile over the pixels) relative to its median: below, part of the
#: board is hidden (the contrast polynomial fades out there) or lit far too unevenly.
MIN_CONTRAST_RATIO = 0.3
#: Gauss-Newton stops after a step shorter than this many standard deviations (in the metric
#: of the normal matrix): the model is so nearly linear over the start's distance (a few
#: sigma) that the remaining error is below 0.01 sigma (checked against 0.01).
_TOL_SIGMA = 3.0
#: Parameters before the shading coefficients: pose (6), blur (3), dilation (3).
_NP = 12


class PhotometricError(InputError):
    """The photometric fit could not be done or did not converge (the corner pose stays usable)."""


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


# ------------------------------------------------------------------ pixel set


@dataclass(frozen=True)
class PhotometricSetup:
    """The pixels of one board used by the fit and what does not change during it.

    Per-pixel arrays all have shape (N,) (contiguous, for speed).

    Attributes
    ----------
    board : Chessboard
    rx, ry : ndarray
        Undistorted rays (x/z, y/z) of the pixel centres.
    u, v : ndarray
        Pixel centres, px.
    values : ndarray
        Image values, DN.
    line_x, line_y : ndarray
        Position k s (mm) of the nearest X and Y grid line, k in -1..cols (rows).
    isx, isy : ndarray
        1 / |grad_p X| and 1 / |grad_p Y| at the starting pose, px/mm (the local
        mm -> px scale, fixed during the fit: it sets the blur's width, not the
        edges' positions).
    bsx, bsy : ndarray
        For a pixel near an X line (Y line): +1 when the black square is on its low side,
        -1 when it is on its high side, 0 when there is no edge (white on both sides) or the
        pixel belongs to the other axis. The black squares grow by ``dilation_px``: the
        edge moves towards the white side.
    c2, s2 : ndarray
        cos 2 theta and sin 2 theta of the direction theta of the edge's normal in the
        image (for the blur and the dilation that depend on it).
    fx0, fx1, gx0, gx1, fy0, fy1, gy0, gy1 : ndarray
        Across the nearest line of each axis: the value A on the low side and the jump
        B - A of the indicator I (f) and of I S (g), so that the blurred factors are
        A + (B - A) Phi(d / sigma).
    basis : ndarray, shape (n_basis, N)
        Shading monomials of (u - u0) / L, (v - v0) / L.
    centre : (float, float)
    length : float
    """

    board: Chessboard
    rx: np.ndarray
    ry: np.ndarray
    u: np.ndarray
    v: np.ndarray
    values: np.ndarray
    line_x: np.ndarray
    line_y: np.ndarray
    isx: np.ndarray
    isy: np.ndarray
    bsx: np.ndarray
    bsy: np.ndarray
    c2: np.ndarray
    s2: np.ndarray
    fx0: np.ndarray
    fx1: np.ndarray
    gx0: np.ndarray
    gx1: np.ndarray
    fy0: np.ndarray
    fy1: np.ndarray
    gy0: np.ndarray
    gy1: np.ndarray
    basis: np.ndarray
    centre: tuple[float, float]
    length: float

    @property
    def n_pixels(self) -> int:
        return int(self.values.size)

    def slice(self, start: int, stop: int) -> PhotometricSetup:
        """Pixels start..stop-1 (views, no copy)."""
        kw = {}
        for f in self.__dataclass_fields__:
            val = getattr(self, f)
            if f == "basis":
                kw[f] = val[:, start:stop]
            elif isinstance(val, np.ndarray):
                kw[f] = val[start:stop]
            else:
                kw[f] = val
        return PhotometricSetup(**kw)

    def subset(self, idx: np.ndarray) -> PhotometricSetup:
        """The same set-up restricted to pixels ``idx``."""
        kw = {}
        for f in self.__dataclass_fields__:
            val = getattr(self, f)
            if f == "basis":
                kw[f] = np.ascontiguousarray(val[:, idx])
            elif isinstance(val, np.ndarray):
                kw[f] = np.ascontiguousarray(val[idx])
            else:
                kw[f] = val
        return PhotometricSetup(**kw)


def _monomials(un: np.ndarray, vn: np.ndarray, degree: int) -> np.ndarray:
    rows = [np.ones_like(un)]
    for d in range(1, degree + 1):
        for i in range(d + 1):
            rows.append(un ** (d - i) * vn**i)
    return np.ascontiguousarray(np.stack(rows, axis=0))


def _jumps(k: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    """(A_F, B_F - A_F, A_G, B_G - A_G) across line k of the indicator F = I and of G = I S.

    Lines k = -1..n at k s; square i spans [i s, (i + 1) s] for i = -1..n-1 with S = (-1)^i
    (square (i, j) black when i + j is even: black = (1 + Sx Sy) / 2 on the checkered area).
    """
    sgn_right = np.where(k % 2 == 0, 1.0, -1.0)  # (-1)^k, the square right of line k
    AF = np.where(k == -1, 0.0, 1.0)
    BF = np.where(k == n, 0.0, 1.0)
    AG = np.where(k == -1, 0.0, -sgn_right)
    BG = np.where(k == n, 0.0, sgn_right)
    return AF, BF - AF, AG, BG - AG


def _black_side(k: np.ndarray, j: np.ndarray, n: int, m: int) -> np.ndarray:
    """+1 when square (k - 1, j) is black, -1 when square (k, j) is, 0 when neither.

    Squares (i, j) with i in -1..n-1 and j in -1..m-1 are printed, black when i + j is
    even; anything else is the white margin.
    """
    inside_j = (j >= -1) & (j <= m - 1)
    left = inside_j & (k - 1 >= -1) & (k - 1 <= n - 1) & ((k - 1 + j) % 2 == 0)
    right = inside_j & (k >= -1) & (k <= n - 1) & ((k + j) % 2 == 0)
    return left.astype(np.float64) - right.astype(np.float64)


def _check_pose(board2cam) -> np.ndarray:
    T = np.array(board2cam, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"board2cam must be a finite (4, 4) transform, got shape {T.shape}")
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6:
        raise ValueError("board2cam's rotation part is not orthonormal")
    if float(R[:, 2] @ T[:3, 3]) <= 0:
        raise ValueError("board2cam: the board is seen from behind (its z axis points towards the camera)")
    return T


def _homography_inverse(T: np.ndarray) -> np.ndarray:
    """H^-1 for H = [r1, r2, t]: (X, Y, 1) ~ H^-1 (x/z, y/z, 1) on the board plane."""
    return np.linalg.inv(np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]]))


def prepare_pixels(
    image,
    board: Chessboard,
    camera: CameraModel,
    board2cam,
    *,
    band_px: float | None = None,
    blur_px: float = 1.0,
    shading_degree: int = 2,
    outer_edges: bool = True,
    exclude=(),
    saturation: int | None = None,
) -> PhotometricSetup:
    """Select the pixels of a board for the photometric fit at a starting pose.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8 or uint16
    board : Chessboard
    camera : CameraModel
    board2cam : array_like, shape (4, 4), mm
        Starting pose (e.g. the corner-based one).
    band_px : float, optional
        Pixels farther than this from every grid line are left out, px (default
        2.5 ``blur_px``, at least 2 px: beyond it an edge's gradient is below 5 % of its
        peak and the pixels hold under 0.5 % of the information on its position).
    blur_px : float
        Expected effective blur sigma, px (sets the default band and the corner
        zones left out: 3 sigma around every corner).
    shading_degree : int
        Degree (0, 1 or 2) of the black-level and contrast polynomials.
    outer_edges : bool
        Also use the outer edges of the checkered area against the white margin (the
        margin must then be white over at least ``band_px``).
    exclude : sequence of array_like, shape (k, 2)
        Polygons (px) whose pixels are not used (another board, a known obstruction).
    saturation : int, optional
        Pixels at or above this value are left out (default the dtype's maximum), and so
        are pixels at 0.

    Returns
    -------
    PhotometricSetup

    Raises
    ------
    PhotometricError
        The board is (mostly) outside the image or too few pixels are usable.
    """
    img = check_image(image, uint16=True)
    T = _check_pose(board2cam)
    if not isinstance(board, Chessboard):
        raise ValueError(f"the photometric model is for chessboards, got {type(board).__name__}")
    if int(shading_degree) not in (0, 1, 2):
        raise ValueError(f"shading_degree must be 0, 1 or 2, got {shading_degree}")
    if not (np.isfinite(blur_px) and blur_px > 0):
        raise ValueError(f"blur_px must be positive, got {blur_px}")
    band = max(2.5 * blur_px, 2.0) if band_px is None else float(band_px)
    if not (np.isfinite(band) and band > 0):
        raise ValueError(f"band_px must be positive, got {band_px}")
    h, w = img.shape
    if camera.image_size != (w, h):
        raise ValueError(
            f"image is {w}x{h} px but the camera is {camera.image_size[0]}x{camera.image_size[1]} px"
        )
    s = board.square_mm
    cols, rows = board.cols, board.rows
    # Bounding box of the checkered area grown by 0.6 square.
    grow = 0.6 * s
    extent = (-s - grow, -s - grow, cols * s + grow, rows * s + grow)
    try:
        uv = camera.project_rectangle(T, extent, samples=33)
    except ValueError:
        raise PhotometricError("the board reaches behind the camera") from None
    # Pixels c0..c1-1, r0..r1-1: their neighbours (for the local scale) are in the image.
    c0 = max(int(np.floor(uv[:, 0].min())), 1)
    c1 = min(int(np.ceil(uv[:, 0].max())) + 1, w - 1)
    r0 = max(int(np.floor(uv[:, 1].min())), 1)
    r1 = min(int(np.ceil(uv[:, 1].max())) + 1, h - 1)
    if c1 - c0 < 8 or r1 - r0 < 8:
        raise PhotometricError("the board is outside the image")
    rm = pixel_rays(camera)
    corr_x, corr_y = rm.correction_maps
    Hi = _homography_inverse(T)
    h32 = Hi.astype(np.float32)

    cxf, cyf = corr_x.ravel(), corr_y.ravel()

    def plane(u_i, v_i):
        """Board (X, Y) in float32 (1e-4 px is plenty to choose pixels) and w2 of pixels (u, v)."""
        flat = v_i * w + u_i
        rx = rm.px32[u_i] + cxf.take(flat)
        ry = rm.py32[v_i] + cyf.take(flat)
        w2 = h32[2, 0] * rx + h32[2, 1] * ry + h32[2, 2]
        iw = np.float32(1.0) / w2
        return (
            (h32[0, 0] * rx + h32[0, 1] * ry + h32[0, 2]) * iw,
            (h32[1, 0] * rx + h32[1, 1] * ry + h32[1, 2]) * iw,
            w2,
        )

    sf = np.float32(s)
    # Corner zones at least as wide as the band: every pixel kept is near one line only.
    cz = max(CORNER_SIGMAS * blur_px, band)

    def outside(Z, n, isz):
        """Distance (px) outside the checkered area along one axis (negative inside)."""
        return np.maximum(-sf - Z, Z - n * sf) * isz

    # Coarse pass on 4 x 4 tiles, sampled at one pixel of each (every pixel of a tile lies
    # within 2.9 px of it): keep the tiles that may hold pixels near a line.
    tu = np.arange(c0, c1, 4)
    tv = np.arange(r0, r1, 4)
    su = np.minimum(tu + 2, c1 - 1)
    sv = np.minimum(tv + 2, r1 - 1)
    Xc, Yc, w2c = plane(su[None, :], sv[:, None])
    gx = np.gradient(Xc) if min(Xc.shape) > 1 else None
    gy = np.gradient(Yc) if min(Yc.shape) > 1 else None
    if gx is None or gy is None:
        raise PhotometricError("the board is too small in the image")
    with np.errstate(divide="ignore", invalid="ignore"):
        isXc = np.float32(4.0) / np.sqrt(gx[0] ** 2 + gx[1] ** 2)
        isYc = np.float32(4.0) / np.sqrt(gy[0] ** 2 + gy[1] ** 2)
        reach = band + 3.0
        dXc = np.abs(Xc - np.clip(np.rint(Xc / sf), -1, cols) * sf) * isXc
        dYc = np.abs(Yc - np.clip(np.rint(Yc / sf), -1, rows) * sf) * isYc
        tiles = (
            ((dXc < reach) & (outside(Yc, rows, isYc) <= reach))
            | ((dYc < reach) & (outside(Xc, cols, isXc) <= reach))
        ) & (w2c > 0)
    ti, tj = np.nonzero(tiles)  # tile row, tile column
    off_v, off_u = (a.ravel() for a in np.meshgrid(np.arange(4), np.arange(4), indexing="ij"))
    v_i = (tv[ti][:, None] + off_v[None, :]).ravel()
    u_i = (tu[tj][:, None] + off_u[None, :]).ravel()
    tile = np.repeat(np.arange(ti.size), 16)
    inb = (v_i < r1) & (u_i < c1)
    v_i, u_i, tile = v_i[inb], u_i[inb], tile[inb]
    isX = isXc[ti, tj][tile]
    isY = isYc[ti, tj][tile]
    # Fine selection of the candidate pixels.
    X, Y, w2 = plane(u_i, v_i)
    with np.errstate(divide="ignore", invalid="ignore"):
        kx = np.clip(np.rint(X / sf), -1, cols)
        ky = np.clip(np.rint(Y / sf), -1, rows)
        dX = np.abs(X - kx * sf) * isX
        dY = np.abs(Y - ky * sf) * isY
        near_x = (dX < band) & (outside(Y, rows, isY) <= band)
        near_y = (dY < band) & (outside(X, cols, isX) <= band)
        if not outer_edges:
            near_x &= (kx > -1) & (kx < cols) & (outside(Y, rows, isY) < -band)
            near_y &= (ky > -1) & (ky < rows) & (outside(X, cols, isX) < -band)
        sel = (near_x | near_y) & ~((dX < cz) & (dY < cz)) & (w2 > 0)
    vals = img.ravel().take(v_i * w + u_i)
    sat = np.iinfo(img.dtype).max if saturation is None else int(saturation)
    sel &= (vals < sat) & (vals > 0)
    polys = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in exclude]
    if polys:
        m = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
        for p in polys:
            if p.shape[0] >= 3 and np.all(np.isfinite(p)):
                q = np.rint((p - [c0, r0]) * 16).astype(np.int32)
                cv2.fillPoly(m, [q], 1, lineType=cv2.LINE_8, shift=4)
        sel &= m[v_i - r0, u_i - c0] == 0
    idx = np.flatnonzero(sel)
    n = idx.size
    if n < MIN_PIXELS:
        raise PhotometricError(f"only {n} usable pixels near the board's edges (at least {MIN_PIXELS})")
    ui, vi = u_i[idx], v_i[idx]
    X, Y, dX, dY, kx, ky = X[idx], Y[idx], dX[idx], dY[idx], kx[idx], ky[idx]
    u = ui.astype(np.float64)
    v = vi.astype(np.float64)
    # Local scale |grad_p X|, |grad_p Y| (mm/px) and edge directions: those of the pixel's tile
    # (they vary by ~0.1 % over 4 px; they set the blur's width, not the edges' positions).
    tk = (ti[tile[idx]], tj[tile[idx]])
    gXu, gXv = gx[1][tk].astype(np.float64), gx[0][tk].astype(np.float64)
    gYu, gYv = gy[1][tk].astype(np.float64), gy[0][tk].astype(np.float64)
    sXk = 1.0 / isXc[tk].astype(np.float64)
    sYk = 1.0 / isYc[tk].astype(np.float64)
    kxs = kx.astype(np.int64)
    kys = ky.astype(np.int64)
    fx0, fx1, gx0, gx1 = _jumps(kxs, cols)
    fy0, fy1, gy0, gy1 = _jumps(kys, rows)
    # Which side of its line is black (the squares either side: (k - 1, j) and (k, j)).
    on_x = dX <= dY
    jx = np.floor(Y / sf).astype(np.int64)  # square row of an X-edge pixel
    iy = np.floor(X / sf).astype(np.int64)  # square column of a Y-edge pixel
    bsx = np.where(on_x, _black_side(kxs, jx, cols, rows), 0.0)
    bsy = np.where(on_x, 0.0, _black_side(kys, iy, rows, cols))
    # Direction of the edge's normal in the image (the gradient of X or Y).
    nu = np.where(on_x, gXu, gYu)
    nv = np.where(on_x, gXv, gYv)
    n2 = nu * nu + nv * nv
    c2 = (nu * nu - nv * nv) / n2
    s2 = 2.0 * nu * nv / n2
    u0, v0 = 0.5 * (c0 + c1 - 1), 0.5 * (r0 + r1 - 1)
    L = 0.5 * max(c1 - c0, r1 - r0, 2)
    return PhotometricSetup(
        board=board,
        rx=rm.px[ui] + corr_x[vi, ui],
        ry=rm.py[vi] + corr_y[vi, ui],
        u=u,
        v=v,
        values=vals[idx].astype(np.float64),
        line_x=kxs * s,
        line_y=kys * s,
        isx=1.0 / sXk,
        isy=1.0 / sYk,
        bsx=bsx,
        bsy=bsy,
        c2=c2,
        s2=s2,
        fx0=fx0,
        fx1=fx1,
        gx0=gx0,
        gx1=gx1,
        fy0=fy0,
        fy1=fy1,
        gy0=gy0,
        gy1=gy1,
        basis=_monomials((u - u0) / L, (v - v0) / L, int(shading_degree)),
        centre=(u0, v0),
        length=L,
    )


# ---------------------------------------------------------------------- model


def _poly(coef: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """coef @ basis as a sum of scaled rows (a BLAS matrix-vector product would be threaded)."""
    out = coef[0] * basis[0]
    for k in range(1, basis.shape[0]):
        out += coef[k] * basis[k]
    return out


def _wsum(w: np.ndarray, e: np.ndarray) -> float:
    """sum w e^2 (elementwise: BLAS's dot product is threaded on long vectors)."""
    return float(np.sum(w * e * e))


def model_and_jacobian(
    setup: PhotometricSetup,
    board2cam: np.ndarray,
    blur_px,
    dilation_px,
    shading_a: np.ndarray,
    shading_b: np.ndarray,
    *,
    jacobian: bool = True,
    out: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Model image values of the selected pixels and their Jacobian.

    Parameters
    ----------
    setup : PhotometricSetup
    board2cam : ndarray, shape (4, 4), mm
    blur_px : array_like, shape (3,), px
        Effective Gaussian blur sigma across an edge whose normal makes the angle theta
        with the image's x axis: sigma = b0 + b1 cos 2 theta + b2 sin 2 theta (an
        elongated blur: astigmatism, a camera's horizontal processing).
    dilation_px : array_like, shape (3,), px
        Growth of the black squares, d0 + d1 cos 2 theta + d2 sin 2 theta (each
        black/white edge moved towards its white side: ink spread, a non-linear
        response, sharpening).
    shading_a, shading_b : ndarray, shape (n_basis,)
        Black-level and contrast coefficients, DN.
    jacobian : bool
    out : ndarray, shape (12 + 2 n_basis, N), optional
        Where to write the Jacobian (returned).

    Returns
    -------
    model : ndarray, shape (N,), DN
    J : ndarray, shape (12 + 2 n_basis, N) or None
        Rows: d model / d (t (3, mm), r (3, rad)) for t <- t + dt, R <- Exp(dr) R (camera
        frame), then d / d blur_px (3), d / d dilation_px (3), d / d shading_a,
        d / d shading_b.
    """
    T = np.asarray(board2cam, dtype=np.float64)
    Hi = _homography_inverse(T)
    S = setup
    rx, ry = S.rx, S.ry
    iw2 = 1.0 / (Hi[2, 0] * rx + Hi[2, 1] * ry + Hi[2, 2])
    X = (Hi[0, 0] * rx + Hi[0, 1] * ry + Hi[0, 2]) * iw2
    Y = (Hi[1, 0] * rx + Hi[1, 1] * ry + Hi[1, 2]) * iw2
    bl = np.asarray(blur_px, dtype=np.float64)
    dl = np.asarray(dilation_px, dtype=np.float64)
    sig = bl[0] + bl[1] * S.c2 + bl[2] * S.s2
    dil = dl[0] + dl[1] * S.c2 + dl[2] * S.s2
    zx = (X - S.line_x) * S.isx - dil * S.bsx
    zx /= sig
    zy = (Y - S.line_y) * S.isy - dil * S.bsy
    zy /= sig
    Px, Py = ndtr(zx), ndtr(zy)
    Fx = S.fx0 + S.fx1 * Px
    Gx = S.gx0 + S.gx1 * Px
    Fy = S.fy0 + S.fy1 * Py
    Gy = S.gy0 + S.gy1 * Py
    c = 1.0 - 0.5 * (Fx * Fy + Gx * Gy)
    # a and b in one small matrix product (2 x n_basis x N stays below OpenBLAS's threading size
    # for chunks of up to 20000 pixels; _poly otherwise).
    if S.basis.shape[1] * S.basis.shape[0] * 2 <= _GEMM_SINGLE_THREAD:
        a, b = np.stack([np.asarray(shading_a, float), np.asarray(shading_b, float)]) @ S.basis
    else:
        a = _poly(shading_a, S.basis)
        b = _poly(shading_b, S.basis)
    model = a + b * c
    if not jacobian:
        return model, None
    # d c / d z along each axis (phi the normal density).
    cz_x = (S.fx1 * Fy + S.gx1 * Gy) * np.exp(-0.5 * zx * zx)
    cz_x *= -0.5 / _SQRT_2PI
    cz_y = (S.fy1 * Fx + S.gy1 * Gx) * np.exp(-0.5 * zy * zy)
    cz_y *= -0.5 / _SQRT_2PI
    cX = cz_x * S.isx  # d c / d X * sigma, 1/mm
    cY = cz_y * S.isy
    nb = S.basis.shape[0]
    J = np.empty((_NP + 2 * nb, X.size)) if out is None else out
    # d X / d(t, r) = (-gX, gX x a), gX = Hi[0] - X Hi[2], a = R q (the board point, camera frame);
    # v = (dc/dX gX + dc/dY gY) b, so d model / d(t, r) = (-v, v x a).
    bs = b / sig
    cX *= bs
    cY *= bs
    vx = cX * Hi[0, 0] + cY * Hi[1, 0] - (cX * X + cY * Y) * Hi[2, 0]
    vy = cX * Hi[0, 1] + cY * Hi[1, 1] - (cX * X + cY * Y) * Hi[2, 1]
    vz = cX * Hi[0, 2] + cY * Hi[1, 2] - (cX * X + cY * Y) * Hi[2, 2]
    ax = T[0, 0] * X + T[0, 1] * Y
    ay = T[1, 0] * X + T[1, 1] * Y
    az = T[2, 0] * X + T[2, 1] * Y
    np.negative(vx, out=J[0])
    np.negative(vy, out=J[1])
    np.negative(vz, out=J[2])
    J[3] = vy * az - vz * ay
    J[4] = vz * ax - vx * az
    J[5] = vx * ay - vy * ax
    J[6] = -(cz_x * zx + cz_y * zy) * bs
    J[7] = J[6] * S.c2
    J[8] = J[6] * S.s2
    J[9] = -(cz_x * S.bsx + cz_y * S.bsy) * bs
    J[10] = J[9] * S.c2
    J[11] = J[9] * S.s2
    J[_NP : _NP + nb] = S.basis
    J[_NP + nb :] = S.basis * c
    return model, J


# ------------------------------------------------------------------------ fit


def _apply(T: np.ndarray, delta: np.ndarray) -> np.ndarray:
    Tn = T.copy()
    Tn[:3, 3] = T[:3, 3] + delta[:3]
    R, _ = cv2.Rodrigues(np.asarray(delta[3:6], dtype=np.float64).reshape(3, 1))
    Tn[:3, :3] = R @ T[:3, :3]
    return Tn


#: Products below these sizes keep OpenBLAS on one thread: its matrix products are
#: threaded above m n k = 262144 (GEMM) and m n = 9216 (GEMV), and its threads only contend
#: with the elementwise work (badly on a loaded machine).
_GEMM_SINGLE_THREAD = 262144
_GEMV_SINGLE_THREAD = 9216
#: Pixels per chunk of the fused model / Jacobian / normal-matrix evaluation (kept in cache).
_CHUNK = 8192


def _weighted_gram(M: np.ndarray, w: np.ndarray, e: np.ndarray | None = None):
    """M diag(w) M^T for M of shape (p, N), summed over blocks of columns; with e, also M diag(w) e."""
    G = np.zeros((M.shape[0], M.shape[0]))
    g = np.zeros(M.shape[0])
    nk = max(64, min(_GEMM_SINGLE_THREAD // M.shape[0] ** 2, _GEMV_SINGLE_THREAD // M.shape[0]))
    for k in range(0, M.shape[1], nk):
        Mk = M[:, k : k + nk]
        Mw = Mk * w[k : k + nk]
        G += Mw @ Mk.T
        if e is not None:
            g += Mw @ e[k : k + nk]
    return G if e is None else (G, g)


def _linear_shading(setup: PhotometricSetup, T, sig, dil) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares black level and contrast at a fixed pose, blur and dilation (linear in them)."""
    nb = setup.basis.shape[0]
    ones = np.zeros(nb)
    ones[0] = 1.0
    _, J = model_and_jacobian(setup, T, sig, dil, np.zeros(nb), ones)
    G, g = _weighted_gram(J[_NP:], np.ones(setup.n_pixels), setup.values)
    try:
        coef = np.linalg.solve(G, g)
    except np.linalg.LinAlgError:
        raise PhotometricError("the black level and contrast are undetermined") from None
    return coef[:nb], coef[nb:]


def _huber(r: np.ndarray, k: float) -> np.ndarray:
    a = np.abs(r)
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))


@dataclass
class _State:
    T: np.ndarray
    sig: np.ndarray  # blur (3,), px
    dil: np.ndarray  # dilation (3,), px
    a: np.ndarray
    b: np.ndarray


@dataclass
class _Solution:
    state: _State
    iterations: int
    converged: bool
    e: np.ndarray  # residuals at the solution, DN
    var: np.ndarray  # modelled noise variance, DN^2
    hw: np.ndarray  # Huber weights
    A: np.ndarray  # J^T W J at the last linearisation (p, p)


class _Evaluator:
    """Residuals, noise, Huber weights and the normal equations of a state, chunk by chunk.

    The Jacobian of a chunk is written into one reused buffer, with the residuals as its
    last row, and its weighted Gram matrix [J; e] W [J; e]^T is accumulated at once:
    the full (p, N) Jacobian is never held in memory.
    """

    def __init__(self, setup: PhotometricSetup, noise_var, huber: float) -> None:
        self.setup = setup
        self.noise_var = noise_var
        self.huber = huber
        n = setup.n_pixels
        self.chunks = [setup.slice(k, min(k + _CHUNK, n)) for k in range(0, n, _CHUNK)]
        self.p = _NP + 2 * setup.basis.shape[0]
        self.buf = np.empty((self.p + 1, min(_CHUNK, n)))
        self.nk = max(64, _GEMM_SINGLE_THREAD // (self.p + 1) ** 2)

    def __call__(self, st: _State, jacobian: bool = True):
        p = self.p
        es, vs, hs = [], [], []
        G = np.zeros((p + 1, p + 1)) if jacobian else None
        for ch in self.chunks:
            n = ch.n_pixels
            M = self.buf[:, :n]
            m, _ = model_and_jacobian(ch, st.T, st.sig, st.dil, st.a, st.b, jacobian=jacobian, out=M[:p])
            e = ch.values - m
            var = self.noise_var(m)
            hw = _huber(e / np.sqrt(var), self.huber)
            if jacobian:
                M[p] = e
                w = hw / var
                for k in range(0, n, self.nk):
                    Mk = M[:, k : k + self.nk]
                    G += (Mk * w[k : k + self.nk]) @ Mk.T
            es.append(e)
            vs.append(var)
            hs.append(hw)
        e, var, hw = (np.concatenate(x) for x in (es, vs, hs))
        if not jacobian:
            return e, var, hw, None, None
        return e, var, hw, G[:p, :p], G[:p, p]


def _gauss_newton(
    setup: PhotometricSetup, st: _State, noise_var, huber: float, max_iter: int, tol: float = 0.1
) -> _Solution:
    """Damped Gauss-Newton (IRLS) from ``st``; ``noise_var(model)`` -> variance per pixel (DN^2).

    Converged when a step is below ``tol`` standard deviations of the parameters (its
    length in the metric of the normal matrix, sqrt(d^T A d)): the step is taken and the
    next one would be smaller still by the (linear) rate of convergence. The normal
    matrix returned is that of the last linearisation (less than ``tol`` sigma away).
    """
    nb = setup.basis.shape[0]
    evaluate = _Evaluator(setup, noise_var, huber)
    e, var, hw, A, g = evaluate(st)
    lam = 1e-6
    it = 0
    converged = False
    while it < max_iter:
        it += 1
        w = hw / var
        cost = _wsum(w, e)
        d = np.sqrt(np.diag(A))
        d[d == 0] = 1.0
        An = A / np.outer(d, d)
        gn = g / d
        accepted = last = False
        for _ in range(10):
            try:
                step = np.linalg.solve(An + lam * np.eye(An.shape[0]), gn) / d
            except np.linalg.LinAlgError:
                lam = max(lam * 10, 1e-6)
                continue
            sig_new = st.sig + step[6:9]
            if not np.isfinite(step).all() or sig_new[0] - np.hypot(sig_new[1], sig_new[2]) <= 0.05:
                lam = max(lam * 10, 1e-6)
                continue
            last = float(step @ A @ step) < tol * tol
            new = _State(
                _apply(st.T, step),
                sig_new,
                st.dil + step[9:12],
                st.a + step[_NP : _NP + nb],
                st.b + step[_NP + nb :],
            )
            e2, var2, hw2, A2, g2 = evaluate(new, jacobian=not last)
            # Cost at the same weights (IRLS): accept when it does not increase.
            if _wsum(w, e2) <= cost * (1 + 1e-12):
                accepted = True
                break
            lam = max(lam * 10, 1e-6)
        if not accepted:
            converged = True  # no step lowers the cost: at the minimum to rounding
            break
        st, e, var, hw = new, e2, var2, hw2
        lam = max(lam / 10, 1e-9)
        if last:
            converged = True
            break
        A, g = A2, g2
    return _Solution(st, it, converged, e, var, hw, A)


def _fit_noise_model(m: np.ndarray, e: np.ndarray) -> tuple[float, float]:
    """var = alpha + beta m from squared residuals (outliers beyond 4 robust sigma left out)."""
    mad = 1.4826 * np.median(np.abs(e - np.median(e)))
    keep = np.abs(e) < 4.0 * max(mad, 1e-6)
    mk, e2 = m[keep], e[keep] ** 2
    # Straight-line fit of e^2 against m (normal equations, elementwise sums).
    mm, ee = float(mk.mean()), float(e2.mean())
    sxx = float(np.sum((mk - mm) ** 2))
    beta = float(np.sum((mk - mm) * (e2 - ee))) / sxx if sxx > 0 else 0.0
    alpha = ee - beta * mm
    floor = max(0.05 * float(np.mean(e[keep] ** 2)), 1.0 / 12.0)
    beta = max(beta, 0.0)
    if alpha < floor:
        alpha = floor
    return alpha, beta


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
    from .pose import BoardPose, projection_jacobian

    t_start = time.perf_counter()
    if isinstance(board, CharucoBoard):
        raise ValueError("the photometric model does not describe ChArUco boards (markers); use corners")
    if not isinstance(board, Chessboard):
        raise ValueError(f"board must be a Chessboard, got {type(board).__name__}")
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    if not (np.isfinite(blur_init_px) and blur_init_px > 0):
        raise ValueError(f"blur_init_px must be positive, got {blur_init_px}")
    T0 = _check_pose(board2cam_init)
    img = check_image(image, uint16=True)

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
            )
        except PhotometricError as e:
            raise fail(e.detail) from None

    setup = select(T0, float(blur_init_px))
    # Pass 1, on an eighth of the pixels, equal weights: near the optimum, and residuals for
    # the noise model.
    n = setup.n_pixels
    sub = setup.subset(np.arange(0, n, 8)) if n >= 8 * MIN_PIXELS else setup
    sig0 = np.array([float(blur_init_px), 0.0, 0.0])
    st = _State(T0, sig0, np.zeros(3), *_linear_shading(sub, T0, sig0, np.zeros(3)))
    m0, _ = model_and_jacobian(sub, st.T, st.sig, st.dil, st.a, st.b, jacobian=False)
    e0 = sub.values - m0
    var0 = max(1.4826 * float(np.median(np.abs(e0 - np.median(e0)))), 0.3) ** 2
    sol = _gauss_newton(sub, st, lambda m: np.full_like(m, var0), huber, max_iter, tol=1.0)
    iters = sol.iterations
    st = sol.state
    m1 = sub.values - sol.e
    alpha, beta = _fit_noise_model(m1, sol.e)

    def noise_var(m):
        return alpha + beta * np.maximum(m, 0.0)

    if not 0.2 <= st.sig[0] <= 10.0:
        raise fail(f"implausible blur sigma {st.sig[0]:.2f} px (expected 0.2-10 px)")
    # The blur is now known: select again when the bands and corner zones were set for another.
    sig_max = st.sig[0] + np.hypot(st.sig[1], st.sig[2])
    if sig_max > 1.15 * blur_init_px or sig_max < 0.7 * blur_init_px:
        setup = select(st.T, sig_max)
        st = _State(st.T, st.sig, st.dil, *_linear_shading(setup, st.T, st.sig, st.dil))
    # Pass 2, every pixel, weights from the noise model.
    sol = _gauss_newton(setup, st, noise_var, huber, max_iter, tol=_TOL_SIGMA)
    iters += sol.iterations
    st = sol.state
    if not sol.converged:
        raise fail(f"did not converge in {max_iter} iterations")
    e, var, hw, A = sol.e, sol.var, sol.hw, sol.A
    w = hw / var
    outliers = float(np.mean(hw < 1.0))
    p, N = A.shape[0], e.size
    s2 = _wsum(w, e) / max(N - p, 1)
    try:
        cov_all = s2 * np.linalg.inv(A)
    except np.linalg.LinAlgError:
        raise fail("the pose is undetermined (singular normal matrix)") from None
    cov = 0.5 * (cov_all[:6, :6] + cov_all[:6, :6].T)
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        raise fail("the pose is undetermined (singular normal matrix)")
    if not 0.2 <= st.sig[0] <= 10.0:
        raise fail(f"implausible blur sigma {st.sig[0]:.2f} px (expected 0.2-10 px)")
    if outliers > max_outlier_fraction:
        raise fail(
            f"{100 * outliers:.0f} % of the pixels do not fit the model (more than "
            f"{100 * max_outlier_fraction:.0f} %: obstructed board or another pattern)"
        )
    bvals = _poly(st.b, setup.basis)
    contrast = float(np.median(bvals))
    if contrast <= 0:
        raise fail(f"the fitted contrast is not positive ({contrast:.1f} DN): inverted or wrong board")
    low = float(np.percentile(bvals, 1))
    if low < MIN_CONTRAST_RATIO * contrast:
        raise fail(
            f"the fitted contrast falls to {100 * low / contrast:.0f} % of its median over part of the "
            "board (obstructed or very unevenly lit board?)"
        )
    # Condition with rotations expressed as lateral motions at the board's distance (as pose.py).
    info = np.linalg.inv(cov_all[:6, :6] / s2)
    Ds = np.diag([1.0, 1.0, 1.0] + [1.0 / max(abs(st.T[2, 3]), 1.0)] * 3)
    condition = float(np.linalg.cond(Ds @ info @ Ds))
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
        scale=float(np.sqrt(s2)),
        n_pixels=int(N),
        outlier_fraction=outliers,
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
        cov=cov,
        rms_px=rms_px,
        n_corners=mc,
        residuals_px=res,
        sigma_px=sigma_px,
        condition=condition,
        iterations=iters,
        method="photometric",
        photometric=fit,
    )
