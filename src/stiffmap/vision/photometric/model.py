"""The edge model of the photometric fit: the blurred, shaded board at each selected pixel.

Each pixel centre p has a ray (x/z, y/z). With the board plane's homography
H = [r1, r2, t] (``board2cam`` = [R | t]), the ray meets the board at
w = H^-1 (x/z, y/z, 1), (X, Y) = (w0 / w2, w1 / w2) mm. The printed
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
exact where the blur along one axis has saturated: pixels within 3 sigma of both
an X and a Y line (the corners) are left out of the pixel set
(:mod:`~stiffmap.vision.photometric.pixels`).

The rays are the camera's (the lens distortion inverted, cached per camera: they do
not depend on the pose). The Jacobian is over the pose (the
perturbation t <- t + dt, R <- Exp(dr) R in the camera frame of
:func:`~stiffmap.posemath.perturb_pose`), the blur and dilation terms and the
shading coefficients.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from ...posemath import ray2board_homography
from .pixels import PhotometricSetup

__all__ = ["model_and_jacobian", "poly", "N_NONLINEAR", "GEMM_SINGLE_THREAD", "GEMV_SINGLE_THREAD"]

_SQRT_2PI = np.sqrt(2.0 * np.pi)

#: Parameters before the shading coefficients (the model is non-linear in them): pose (6),
#: blur (3), dilation (3).
N_NONLINEAR = 12

#: Products below these sizes keep OpenBLAS on one thread: its matrix products are
#: threaded above m n k = 262144 (GEMM) and m n = 9216 (GEMV), and its threads only contend
#: with the elementwise work (badly on a loaded machine).
GEMM_SINGLE_THREAD = 262144
GEMV_SINGLE_THREAD = 9216


def poly(coef: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """coef @ basis as a sum of scaled rows (a BLAS matrix-vector product would be threaded)."""
    out = coef[0] * basis[0]
    for k in range(1, basis.shape[0]):
        out += coef[k] * basis[k]
    return out


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
    S = setup
    dt = S.values.dtype
    X, Y, dX, dY, Hi, T = _board_points(S, board2cam)
    sig, zx, zy, ex, ey, Fx, Fy, Gx, Gy, c = _edges(S, dX, dY, blur_px, dilation_px)
    a, b = _shading(S, shading_a, shading_b)
    model = a + b * c
    if not jacobian:
        return model, None
    # d c / d z along each axis (phi the normal density).
    cz_x = (S.fx1 * Fy + S.gx1 * Gy) * (np.exp(dt.type(-0.5) * zx * zx) if ex is None else ex)
    cz_x *= dt.type(-0.5 / _SQRT_2PI)
    cz_y = (S.fy1 * Fx + S.gy1 * Gx) * (np.exp(dt.type(-0.5) * zy * zy) if ey is None else ey)
    cz_y *= dt.type(-0.5 / _SQRT_2PI)
    nb = S.basis.shape[0]
    J = np.empty((N_NONLINEAR + 2 * nb, X.size), dtype=dt) if out is None else out
    bs = b / sig
    _pose_rows(J, cz_x * S.isx * bs, cz_y * S.isy * bs, X, Y, Hi, T)
    J[6] = -(cz_x * zx + cz_y * zy) * bs
    J[7] = J[6] * S.c2
    J[8] = J[6] * S.s2
    J[9] = -(cz_x * S.bsx + cz_y * S.bsy) * bs
    J[10] = J[9] * S.c2
    J[11] = J[9] * S.s2
    J[N_NONLINEAR : N_NONLINEAR + nb] = S.basis
    J[N_NONLINEAR + nb :] = S.basis * c
    return model, J


def _board_points(S: PhotometricSetup, board2cam):
    """The board point (X, Y) of each pixel's ray and its distances (dX, dY) to its grid lines,
    mm, and the inverse homography and the pose, all in the set-up's precision."""
    dt = S.values.dtype
    T64 = np.asarray(board2cam, dtype=np.float64)
    # The board point of each ray, and its distance to the grid line, in double precision (the
    # rays and lines are kept so in a float32 set-up): the distance is a small difference of
    # coordinates of up to ~100 mm, and rounding X to single precision (~1e-5 mm, 5e-5 px)
    # would move the optimum by up to a quarter of a standard deviation.
    Hi64 = ray2board_homography(T64)
    rx, ry = S.rx, S.ry
    iw2 = 1.0 / (Hi64[2, 0] * rx + Hi64[2, 1] * ry + Hi64[2, 2])
    X = (Hi64[0, 0] * rx + Hi64[0, 1] * ry + Hi64[0, 2]) * iw2
    Y = (Hi64[1, 0] * rx + Hi64[1, 1] * ry + Hi64[1, 2]) * iw2
    # (Subtracted in double, then rounded: np.subtract(..., dtype=float32) would round X first.)
    dX = (X - S.line_x).astype(dt, copy=False)
    dY = (Y - S.line_y).astype(dt, copy=False)
    if dt != X.dtype:
        X, Y = X.astype(dt), Y.astype(dt)
    return X, Y, dX, dY, Hi64.astype(dt), T64.astype(dt)


def _edges(S: PhotometricSetup, dX, dY, blur_px, dilation_px):
    """The blurred pattern c at each pixel and what its derivatives need: the blur sigma, the
    normalised distances zx, zy to the edges, exp(-z^2 / 2) along each (None in double
    precision: computed there when needed), and the blurred factors Fx, Fy, Gx, Gy."""
    dt = S.values.dtype
    one = dt.type(1.0)
    bl = np.asarray(blur_px, dtype=np.float64).astype(dt)
    dl = np.asarray(dilation_px, dtype=np.float64).astype(dt)
    sig = bl[0] + bl[1] * S.c2 + bl[2] * S.s2
    dil = dl[0] + dl[1] * S.c2 + dl[2] * S.s2
    zx = dX * S.isx - dil * S.bsx
    zx /= sig
    zy = dY * S.isy - dil * S.bsy
    zy /= sig
    if dt == np.float32:
        (Px, ex), (Py, ey) = _ndtr_exp32(zx), _ndtr_exp32(zy)
    else:
        Px, Py = ndtr(zx), ndtr(zy)
        ex = ey = None
    Fx = S.fx0 + S.fx1 * Px
    Gx = S.gx0 + S.gx1 * Px
    Fy = S.fy0 + S.fy1 * Py
    Gy = S.gy0 + S.gy1 * Py
    c = one - dt.type(0.5) * (Fx * Fy + Gx * Gy)
    return sig, zx, zy, ex, ey, Fx, Fy, Gx, Gy, c


def _shading(S: PhotometricSetup, shading_a, shading_b):
    """The black level a and the contrast b at each pixel: in one small matrix product (2 x
    n_basis x N stays below OpenBLAS's threading size for chunks of up to 20000 pixels; poly
    otherwise)."""
    dt = S.values.dtype
    sa = np.asarray(shading_a, dtype=np.float64).astype(dt)
    sb = np.asarray(shading_b, dtype=np.float64).astype(dt)
    if S.basis.shape[1] * S.basis.shape[0] * 2 <= GEMM_SINGLE_THREAD:
        a, b = np.stack([sa, sb]) @ S.basis
        return a, b
    return poly(sa, S.basis), poly(sb, S.basis)


def _pose_rows(J, cX, cY, X, Y, Hi, T) -> None:
    """J's rows 0..5, d model / d(t, r), from cX, cY = d model / d X, d Y (1/mm).

    d X / d(t, r) = (-gX, gX x a), gX = Hi[0] - X Hi[2], a = R q (the board point, camera frame);
    v = dmodel/dX gX + dmodel/dY gY, so d model / d(t, r) = (-v, v x a).
    """
    cXY = cX * X + cY * Y
    vx = cX * Hi[0, 0] + cY * Hi[1, 0] - cXY * Hi[2, 0]
    vy = cX * Hi[0, 1] + cY * Hi[1, 1] - cXY * Hi[2, 1]
    vz = cX * Hi[0, 2] + cY * Hi[1, 2] - cXY * Hi[2, 2]
    ax = T[0, 0] * X + T[0, 1] * Y
    ay = T[1, 0] * X + T[1, 1] * Y
    az = T[2, 0] * X + T[2, 1] * Y
    np.negative(vx, out=J[0])
    np.negative(vy, out=J[1])
    np.negative(vz, out=J[2])
    J[3] = vy * az - vz * ay
    J[4] = vz * ax - vx * az
    J[5] = vx * ay - vy * ax


# Abramowitz & Stegun 7.1.26 for erfc(x) = t P(t) exp(-x^2), t = 1 / (1 + p x), x >= 0 (absolute
# error below 1.5e-7), written for Phi(z) = erfc(-z / sqrt 2) / 2 with x = |z| / sqrt 2.
_AS_P = np.float32(0.3275911 / np.sqrt(2.0))
_AS_A = tuple(
    np.float32(0.5 * a) for a in (1.061405429, -1.453152027, 1.421413741, -0.284496736, 0.254829592)
)


def _ndtr_exp32(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phi(z) and exp(-z^2 / 2) in float32 (one exponential for both; Phi within 1e-7).

    scipy's ``ndtr`` works in double precision and takes 15 ns a value; this takes about 3
    (with the exponential the Jacobian needs anyway).
    """
    e = np.exp(np.float32(-0.5) * z * z)
    t = np.abs(z)
    t *= _AS_P
    t += np.float32(1.0)
    np.reciprocal(t, out=t)
    q = _AS_A[0] * t
    for a in _AS_A[1:]:
        q += a
        q *= t
    q *= e  # erfc(|z| / sqrt 2) / 2
    np.subtract(np.float32(0.5), q, out=q)
    np.copysign(q, z, out=q)
    q += np.float32(0.5)
    return q, e
