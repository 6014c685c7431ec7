"""OpenCV's fisheye lens model (equidistant projection, Kannala-Brandt polynomial), pure NumPy.

:class:`~stiffmap.camera.CameraModel` with ``model="fisheye"`` maps a ray through these
functions; the pinhole model with OpenCV's polynomial distortion (``model="opencv"``) stays in
:mod:`stiffmap.camera`. Both work in the same coordinates: a point (X, Y, Z) of the camera
frame (Z > 0) has ideal normalised coordinates (x, y) = (X/Z, Y/Z), the model maps them to
distorted normalised coordinates (x', y'), and the pixel is (fx x' + cx, fy y' + cy).

Model (OpenCV's ``cv::fisheye``, skew alpha = 0): with r = |(x, y)| and theta = atan(r) the
angle of the ray off the optical axis,

    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
    (x', y') = (theta_d / r) (x, y).

The distorted radius is a polynomial of the angle, not of tan(angle) as in the pinhole
model, so it stays finite up to 90 degrees off axis: the model describes lenses whose image
the pinhole polynomial can only follow near the centre. It is radial, so it is one to one
wherever theta_d grows with theta: its inverse is a one-dimensional root, found here by
Newton's method safeguarded by bisection on [0, theta_end] (:func:`fisheye_theta_end`: where
theta_d stops growing, or :data:`MAX_THETA`). Rays 90 degrees or more off axis (a lens with
more than 180 degrees of view) have no (X/Z, Y/Z): they are outside the model's field.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = [
    "FISHEYE_NAMES",
    "MAX_THETA",
    "fisheye_distort",
    "fisheye_coefficient_jacobian",
    "fisheye_undistort",
    "fisheye_theta_end",
    "fisheye_theta_d",
]

#: Names of the fisheye model's distortion coefficients (camera.json's ``dist``).
FISHEYE_NAMES = ("k1", "k2", "k3", "k4")
#: Largest angle off the optical axis a ray of the model may have, rad (89.5 degrees: x/z up
#: to 115; at 90 degrees the ray leaves the Z > 0 half-space that X/Z describes).
MAX_THETA = math.radians(89.5)
#: Below this radius the series of theta_d / r about r = 0 is used (exact to rounding).
_SMALL_R = 1e-7


def _coefficients(k) -> tuple[float, float, float, float]:
    k = np.asarray(k, dtype=np.float64).ravel()
    if k.size != 4:
        raise ValueError(f"the fisheye model has 4 coefficients (k1, k2, k3, k4), got {k.size}")
    return float(k[0]), float(k[1]), float(k[2]), float(k[3])


def fisheye_theta_d(theta, k) -> tuple[np.ndarray, np.ndarray]:
    """theta_d(theta) and its derivative d theta_d / d theta (rad, unitless).

    Parameters
    ----------
    theta : array_like
        Angles off the optical axis, rad.
    k : array_like, shape (4,)
        (k1, k2, k3, k4).
    """
    k1, k2, k3, k4 = _coefficients(k)
    t = np.asarray(theta, dtype=np.float64)
    t2 = t * t
    poly = 1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
    dpoly = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
    return t * poly, dpoly


def fisheye_distort(xy, k, *, jacobian: bool):
    """Distorted normalised coordinates of ideal ones, and optionally their Jacobian.

    Parameters
    ----------
    xy : ndarray, shape (..., 2)
        Ideal normalised coordinates (X/Z, Y/Z).
    k : array_like, shape (4,)
    jacobian : bool

    Returns
    -------
    xy_distorted : ndarray, shape (..., 2)
    J : ndarray, shape (..., 2, 2) or None
        d(x', y') / d(x, y).
    """
    k1 = _coefficients(k)[0]
    xy = np.asarray(xy, dtype=np.float64)
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    r = np.sqrt(r2)
    small = r < _SMALL_R
    rs = np.where(small, 1.0, r)
    theta = np.arctan(rs)
    td, dtd = fisheye_theta_d(theta, k)
    # s = theta_d / r: 1 + (k1 - 1/3) r^2 + O(r^4) about r = 0.
    s = np.where(small, 1.0 + (k1 - 1.0 / 3.0) * r2, td / rs)
    out = np.stack([s * x, s * y], axis=-1)
    if not jacobian:
        return out, None
    # d s / d r = (theta_d' / (1 + r^2) - s) / r; the Jacobian is s I + (ds/dr / r) (x, y)(x, y)^T.
    g = np.where(small, 2.0 * (k1 - 1.0 / 3.0), (dtd / (1.0 + rs * rs) - td / rs) / (rs * rs))
    J = np.empty((*x.shape, 2, 2))
    J[..., 0, 0] = s + g * x * x
    J[..., 0, 1] = g * x * y
    J[..., 1, 0] = g * x * y
    J[..., 1, 1] = s + g * y * y
    return out, J


def fisheye_coefficient_jacobian(xy, k) -> np.ndarray:
    """d(x', y') / d(k1, k2, k3, k4) at ideal normalised coordinates: shape (..., 2, 4)."""
    _coefficients(k)
    xy = np.asarray(xy, dtype=np.float64)
    x, y = xy[..., 0], xy[..., 1]
    r = np.hypot(x, y)
    small = r < _SMALL_R
    rs = np.where(small, 1.0, r)
    theta = np.arctan(rs)
    # d theta_d / d k_i = theta^(2i + 1); divided by r: theta^(2i + 1) / r (-> 0 as r -> 0, i >= 1).
    J = np.zeros((*x.shape, 2, 4))
    for i in range(4):
        q = np.where(small, 0.0, theta ** (2 * i + 3) / rs)
        J[..., 0, i] = q * x
        J[..., 1, i] = q * y
    return J


@lru_cache(maxsize=64)
def _theta_end_cached(k: tuple[float, float, float, float]) -> tuple[float, bool]:
    theta = np.linspace(0.0, MAX_THETA, 20001)
    _, dtd = fisheye_theta_d(theta, k)
    bad = ~(np.isfinite(dtd) & (dtd > 0))
    if not bad.any():
        return MAX_THETA, False
    i = int(np.argmax(bad))
    if i == 0:
        return 0.0, True
    # Refine the root of theta_d' between the last good and the first bad sample (bisection).
    lo, hi = float(theta[i - 1]), float(theta[i])
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if fisheye_theta_d(mid, k)[1] > 0:
            lo = mid
        else:
            hi = mid
    return lo, True


def fisheye_theta_end(k) -> tuple[float, bool]:
    """Where the fisheye model stops being one to one.

    Returns
    -------
    theta_end : float
        The first angle off axis (rad) where theta_d stops growing, or :data:`MAX_THETA`.
    folds : bool
        True when theta_d stops growing before :data:`MAX_THETA` (the polynomial folds over).
    """
    return _theta_end_cached(_coefficients(k))


@lru_cache(maxsize=64)
def _inverse_table(k: tuple[float, float, float, float], theta_end: float) -> tuple[np.ndarray, np.ndarray]:
    """theta_d and theta on 4097 angles of [0, theta_end]: the start of Newton's method by interpolation."""
    theta = np.linspace(0.0, theta_end, 4097)
    return fisheye_theta_d(theta, k)[0], theta


def fisheye_undistort(
    xy_distorted, k, *, theta_max: float | None = None, tol: float = 1e-15, max_iter: int = 20
) -> tuple[np.ndarray, np.ndarray]:
    """Ideal normalised coordinates of distorted ones (vectorised), and where there are none.

    Solves theta_d(theta) = |(x', y')| for theta in [0, theta_max], where theta_d grows: Newton's
    method from the linear interpolation of a table of theta_d (4097 angles; two or three
    steps reach the last digits), its steps kept inside [0, theta_max]; then
    (x, y) = tan(theta) (x', y') / |(x', y')|.

    Parameters
    ----------
    xy_distorted : array_like, shape (..., 2)
    k : array_like, shape (4,)
    theta_max : float, optional
        Largest angle off axis accepted, rad (default :func:`fisheye_theta_end`: where the
        model stops being one to one, or :data:`MAX_THETA`).
    tol : float
        Convergence tolerance on theta, rad.
    max_iter : int

    Returns
    -------
    xy : ndarray, shape (..., 2)
        NaN where there is no ray.
    bad : ndarray of bool, shape (...)
        True where the distorted radius lies beyond theta_d(theta_max), is not finite, or
        Newton's method did not converge.
    """
    kk = _coefficients(k)
    t_end = fisheye_theta_end(kk)[0] if theta_max is None else min(float(theta_max), MAX_THETA)
    target = np.asarray(xy_distorted, dtype=np.float64)
    rho = np.hypot(target[..., 0], target[..., 1])
    table_rho, table_theta = _inverse_table(kk, t_end)
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(rho) & (rho <= table_rho[-1]))
    rho_c = np.where(bad, 0.0, rho)
    theta = np.interp(rho_c, table_rho, table_theta)
    for _ in range(max_iter):
        f, df = fisheye_theta_d(theta, kk)
        step = (f - rho_c) / df
        theta = np.clip(theta - step, 0.0, t_end)
        if np.all(np.abs(step) <= tol * np.maximum(1.0, theta)):
            break
    f, _ = fisheye_theta_d(theta, kk)
    bad |= ~(np.abs(f - rho_c) <= 1e3 * tol * np.maximum(1.0, rho_c))
    small = rho_c < _SMALL_R
    scale = np.tan(theta) / np.where(small, 1.0, rho_c)
    scale = np.where(small, 1.0, scale)
    xy = target * scale[..., None]
    xy[bad] = np.nan
    return xy, bad
