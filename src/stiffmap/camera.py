"""Pinhole camera with OpenCV's lens-distortion model, and the ``camera.json`` file.

Pure NumPy (no OpenCV): the vision path produces a :class:`CameraModel` by
calibration, the virtual test-bed renders through one, and both read and write
the same ``camera.json``.

Model (OpenCV's, pixels (x right, y down), pixel centres at integer
coordinates): a point (X, Y, Z) in the camera frame (mm, Z > 0 in front) has
normalised coordinates x = X/Z, y = Y/Z; with r^2 = x^2 + y^2,

    radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
    x' = x radial + 2 p1 x y + p2 (r^2 + 2 x^2) + s1 r^2 + s2 r^4
    y' = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y + s3 r^2 + s4 r^4
    u = fx x' + cx,  v = fy y' + cy.

``dist`` holds (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]), the
order OpenCV uses; missing terms are zero. The tilted-sensor terms (14
coefficients) are not supported.

A fisheye or strong wide-angle lens takes OpenCV's fisheye model instead (``model``
``"fisheye"``, :mod:`stiffmap.lens`): (x', y') = (theta_d / r) (x, y) with theta = atan(r)
and theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), ``dist`` =
(k1, k2, k3, k4). It is one to one wherever theta_d grows with theta (up to 89.5 degrees off
axis), so a calibrated fisheye model usually inverts over the whole image where the
polynomial above folds over before the image corners.

``camera.json``::

    {"image_size": [w, h], "fx": ..., "fy": ..., "cx": ..., "cy": ...,
     "model": "opencv",                        # or "fisheye"; absent: "opencv"
     "dist": [k1, k2, p1, p2, k3],             # fisheye: [k1, k2, k3, k4]
     "std": {"fx": ..., "fy": ..., "cx": ..., "cy": ..., "dist": [...]},   # 1 sigma
     "cov": {"params": ["fx", "fy", "cx", "cy", "k1", ...], "matrix": [[...], ...]},
     "rms_px": ..., "residual_std_px": [sx, sy],
     "views": [{"image": ..., "used": true, "rms_px": ..., "reason": ""}]}

Only ``image_size``, ``fx``, ``fy``, ``cx``, ``cy`` and ``dist`` are required (``model`` is
written only when it is not ``"opencv"``, so files of the pinhole model read and write as
they always did). ``cov`` is the
full covariance of the calibrated parameters (px and unitless, the order of ``params``, a
subset of :meth:`CameraModel.param_names`; parameters it does not name are taken as exact):
it must be square, symmetric and positive semi-definite. Without it, ``std`` gives a
diagonal covariance (correlations unknown); without either the calibration's uncertainty is
unknown (:attr:`CameraModel.calibration_cov` is None). Reading one
(:meth:`CameraModel.from_dict`, :func:`load_camera`) also checks that it describes a
physical camera (:func:`plausibility_problems`): an image of 1 to 100 000 px per side, focal
lengths of 0.1 to 100 times the image diagonal with fx / fy within 1/2.1 to 2.1, the principal
point inside the image, distortion coefficients of sane magnitude (radial k1..k6 within
+/-1000, tangential p1, p2 and thin-prism s1..s4 within +/-1) that are one to one near the
image centre, a reprojection RMS below 0.5 % of the image diagonal, and non-negative
uncertainties no larger than any calibration leaves (:func:`sigma_limits`: a 1-sigma of a
focal length or principal point above the largest plausible focal length, or of a coefficient
above its largest plausible value, says nothing; such numbers, 1e10 or 1e200, made the pose
covariances overflow or singular). Each problem is an :class:`~stiffmap.errors.InputError`
naming the file and
the key.

The distortion polynomial is invertible only near the image centre for a strong lens (it
folds over beyond the calibrated field): :meth:`CameraModel.undistort` raises
:class:`UndistortionError` (a ``ValueError``) naming where it is not, never a NaN or an
overflow.

The camera owns the cache of its pixels' rays (:func:`pixel_rays`): the undistorted
ray of every pixel does not depend on what the camera looks at, so the renderer
(:mod:`stiffmap.sim`) and the photometric pose refinement
(:mod:`stiffmap.vision.photometric`) build it once per camera and share it.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .io import dumps_json, read_json, replace_keeping_previous
from .lens import (
    FISHEYE_NAMES,
    fisheye_coefficient_jacobian,
    fisheye_distort,
    fisheye_theta_d,
    fisheye_theta_end,
    fisheye_undistort,
)

__all__ = [
    "CameraModel",
    "LENS_MODELS",
    "PixelRays",
    "UndistortionError",
    "RigFileAsCamera",
    "InvertibleField",
    "invertible_field",
    "pixel_rays",
    "plausibility_problems",
    "sigma_limits",
    "reference_camera",
    "load_camera",
    "save_camera",
    "check_cov_object",
]

_DIST_LENGTHS = (4, 5, 8, 12)
#: Lens models of a camera (camera.json's ``model``): the pinhole model with OpenCV's
#: polynomial distortion, and OpenCV's fisheye model (:mod:`stiffmap.lens`).
LENS_MODELS = ("opencv", "fisheye")
#: How many distortion coefficients each lens model takes.
DIST_LENGTHS = {"opencv": _DIST_LENGTHS, "fisheye": (4,)}
#: Names of the distortion coefficients, in OpenCV's order.
DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4")
#: Plausible ranges (camera.json's physical checks): focal length in image diagonals, the
#: principal point's margin outside the image in image sizes (0: inside the image, as on
#: every camera whose image was not cropped off-centre), the largest ratio fx / fy (or fy /
#: fx: square pixels give 1, digitised video 1.1, a 2:1 anamorphic lens or binning 2), the
#: largest radial (k) and tangential / thin-prism (p, s) coefficients, the largest
#: reprojection RMS as a share of the image diagonal (a calibration whose corners miss its
#: model by 0.5 % of the image did not describe the camera: 3.2 px at 640x480, where real
#: calibrations give 0.1-1 px), the largest image side in px.
FOCAL_DIAGONALS = (0.1, 100.0)
PRINCIPAL_MARGIN = 0.0
MAX_ASPECT = 2.1
MAX_RADIAL = 1e3
MAX_TANGENTIAL = 1.0
MAX_RMS_DIAGONAL = 0.005
MAX_IMAGE_PX = 100_000


class UndistortionError(ValueError):
    """The lens-distortion model cannot be inverted at some points.

    Beyond the calibrated field a strong distortion polynomial folds over: a distorted
    position there has no undistorted ray (or several). ``where`` says which points.
    """


def _lengths_text(model: str) -> str:
    """How many coefficients ``dist`` holds for a lens model, in words ("4, 5, 8 or 12")."""
    n = [str(v) for v in DIST_LENGTHS[model]]
    return n[0] if len(n) == 1 else ", ".join(n[:-1]) + " or " + n[-1]


def _dist12(dist: np.ndarray) -> np.ndarray:
    d = np.zeros(12)
    d[: dist.size] = dist
    return d


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics and distortion of a camera (see the module docstring).

    Attributes
    ----------
    image_size : (int, int)
        (width, height) in px.
    fx, fy, cx, cy : float
        Focal lengths and principal point, px.
    dist : tuple of float
        (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]); with the fisheye model
        (k1, k2, k3, k4).
    std : dict or None
        1-sigma uncertainties, same keys (``fx``, ``fy``, ``cx``, ``cy``, ``dist``).
    rms_px : float or None
        Calibration reprojection RMS, px.
    residual_std_px : (float, float) or None
        Standard deviation of the calibration residuals per axis, px.
    views : tuple of dict
        Per calibration image: ``image``, ``used``, ``rms_px``, ``reason``.
    cov : ndarray, shape (n, n) or None
        Full covariance of the calibrated parameters, in the order of :attr:`param_names`
        (px and unitless); see :attr:`calibration_cov`.
    model : str
        The lens model, one of :data:`LENS_MODELS`: ``"opencv"`` (pinhole with OpenCV's
        polynomial distortion, the default) or ``"fisheye"`` (:mod:`stiffmap.lens`).
    """

    image_size: tuple[int, int]
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    std: dict[str, Any] | None = None
    rms_px: float | None = None
    residual_std_px: tuple[float, float] | None = None
    views: tuple[dict[str, Any], ...] = field(default_factory=tuple)
    cov: np.ndarray | None = field(default=None, compare=False)
    model: str = "opencv"

    def __post_init__(self) -> None:
        if self.model not in LENS_MODELS:
            raise ValueError(f"model must be one of {list(LENS_MODELS)}, got {self.model!r}")
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ValueError(f"image_size must be positive [w, h], got {self.image_size}")
        object.__setattr__(self, "image_size", (w, h))
        for k in ("fx", "fy", "cx", "cy"):
            v = float(getattr(self, k))
            if not math.isfinite(v):
                raise ValueError(f"{k} must be finite, got {v}")
            object.__setattr__(self, k, v)
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        d = np.asarray(self.dist, dtype=np.float64).ravel()
        if d.size not in DIST_LENGTHS[self.model] or not np.all(np.isfinite(d)):
            raise ValueError(
                f"dist must hold {_lengths_text(self.model)} finite coefficients (model {self.model}), "
                f"got {list(self.dist)}"
            )
        object.__setattr__(self, "dist", tuple(float(x) for x in d))
        object.__setattr__(self, "views", tuple(self.views))
        if self.cov is not None:
            C = np.array(self.cov, dtype=np.float64)
            n = 4 + d.size
            if C.shape != (n, n) or not np.all(np.isfinite(C)):
                raise ValueError(
                    f"cov must be a finite ({n}, {n}) matrix over {self.param_names}, got {C.shape}"
                )
            C = 0.5 * C + 0.5 * C.T  # (C + C.T) / 2 would overflow near 1e308
            C.setflags(write=False)
            object.__setattr__(self, "cov", C)

    # ------------------------------------------------------------ parameters
    @property
    def dist_names(self) -> tuple[str, ...]:
        """Names of the distortion coefficients: OpenCV's order, or (k1..k4) of the fisheye model."""
        return FISHEYE_NAMES if self.model == "fisheye" else DIST_NAMES[: len(self.dist)]

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the calibrated parameters: ("fx", "fy", "cx", "cy", "k1", "k2", ...)."""
        return ("fx", "fy", "cx", "cy", *self.dist_names)

    @property
    def params(self) -> np.ndarray:
        """The parameters of :attr:`param_names` as a vector (px and unitless)."""
        return np.array([self.fx, self.fy, self.cx, self.cy, *self.dist])

    def with_params(self, params) -> CameraModel:
        """The same camera with other parameters (:attr:`param_names` order), without uncertainties."""
        p = np.asarray(params, dtype=np.float64).ravel()
        if p.size != 4 + len(self.dist):
            raise ValueError(f"params must hold {4 + len(self.dist)} values {self.param_names}, got {p.size}")
        return CameraModel(self.image_size, p[0], p[1], p[2], p[3], tuple(p[4:]), model=self.model)

    @property
    def calibration_cov(self) -> np.ndarray | None:
        """Covariance of the calibrated parameters (:attr:`param_names` order), or None when unknown.

        ``cov`` when the camera has it; else the squares of ``std`` on the diagonal (the
        correlations unknown: a null std counts as 0); else None.
        """
        if self.cov is not None:
            return self.cov
        if self.std is None:
            return None
        s = [self.std.get(k) for k in ("fx", "fy", "cx", "cy")]
        sd = self.std.get("dist") or [None] * len(self.dist)
        v = np.array([0.0 if x is None else float(x) for x in [*s, *sd]]) ** 2
        return np.diag(v)

    @property
    def calibration_cov_source(self) -> str:
        """Where :attr:`calibration_cov` comes from: ``"cov"``, ``"std"`` (diagonal) or ``"none"``."""
        return "cov" if self.cov is not None else "std" if self.std is not None else "none"

    def projection_param_jacobian(self, xy) -> np.ndarray:
        """Derivative of the pixel of ideal normalised coordinates with respect to the parameters.

        Parameters
        ----------
        xy : array_like, shape (..., 2)
            Ideal normalised coordinates (X/Z, Y/Z) of points (held fixed).

        Returns
        -------
        ndarray, shape (..., 2, n)
            d(u, v) / d(fx, fy, cx, cy, k1, k2, p1, p2[, k3...]), :attr:`param_names` order.
        """
        xy = np.asarray(xy, dtype=np.float64)
        xd = self.distort(xy)
        if self.model == "fisheye":
            Jd = fisheye_coefficient_jacobian(xy, self.dist_array)
        else:
            Jd = _distort_coefficient_jacobian(xy, _dist12(self.dist_array))[..., : len(self.dist)]
        J = np.zeros((*xy.shape[:-1], 2, 4 + len(self.dist)))
        J[..., 0, 0] = xd[..., 0]
        J[..., 1, 1] = xd[..., 1]
        J[..., 0, 2] = 1.0
        J[..., 1, 3] = 1.0
        J[..., 0, 4:] = self.fx * Jd[..., 0, :]
        J[..., 1, 4:] = self.fy * Jd[..., 1, :]
        return J

    # ------------------------------------------------------------------ arrays
    @property
    def key(self) -> tuple:
        """What the pixel geometry depends on, hashable: (image_size, fx, fy, cx, cy, dist, model).

        Caches of per-pixel maps (:func:`pixel_rays`, the renderer's vignetting) are keyed
        by it: the uncertainties and the calibration's views do not matter there.
        """
        return (self.image_size, self.fx, self.fy, self.cx, self.cy, self.dist, self.model)

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        """Distortion coefficients as a float64 array (OpenCV order)."""
        return np.asarray(self.dist, dtype=np.float64)

    # ------------------------------------------------------------- projection
    def distort(self, xy) -> np.ndarray:
        """Apply the lens distortion to normalised coordinates.

        Parameters
        ----------
        xy : array_like, shape (..., 2)
            Ideal normalised coordinates (X/Z, Y/Z).

        Returns
        -------
        ndarray, shape (..., 2)
            Distorted normalised coordinates (x', y').
        """
        xy = np.asarray(xy, dtype=np.float64)
        return self._lens(xy, jacobian=False)[0]

    def distort_with_jacobian(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`distort` and its Jacobian.

        Parameters
        ----------
        xy : array_like, shape (..., 2)
            Ideal normalised coordinates (X/Z, Y/Z).

        Returns
        -------
        xy_distorted : ndarray, shape (..., 2)
        J : ndarray, shape (..., 2, 2)
            d(x', y') / d(x, y).
        """
        xy = np.asarray(xy, dtype=np.float64)
        return self._lens(xy, jacobian=True)

    def _lens(self, xy: np.ndarray, *, jacobian: bool):
        """The lens model's map of ideal to distorted normalised coordinates (and its Jacobian)."""
        if self.model == "fisheye":
            return fisheye_distort(xy, self.dist_array, jacobian=jacobian)
        return _distort(xy, _dist12(self.dist_array), jacobian=jacobian)

    def undistort(self, xy_distorted, *, tol: float = 1e-14, max_iter: int = 50) -> np.ndarray:
        """Invert :meth:`distort` by Newton's method (vectorised).

        Parameters
        ----------
        xy_distorted : array_like, shape (..., 2)
            Distorted normalised coordinates.
        tol : float
            Convergence tolerance on the normalised coordinates (1e-14 is about
            1e-11 px at f = 4000 px).

        Returns
        -------
        ndarray, shape (..., 2)

        Raises
        ------
        UndistortionError
            If Newton's method does not converge at some point (far outside the image,
            where the distortion polynomial folds over), or a point is not finite.
        """
        target = np.asarray(xy_distorted, dtype=np.float64)
        x, bad = self._newton_undistort(target, tol, max_iter)
        if np.any(bad):
            raise UndistortionError(_undistortion_message(target, bad))
        return x

    def _newton_undistort(
        self, target: np.ndarray, tol: float, max_iter: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Newton's method point by point (vectorised): the result and where it did not converge.

        The fisheye model is radial: its inverse is a one-dimensional root (:mod:`stiffmap.lens`),
        undefined beyond the model's field (there ``bad``).
        """
        if self.model == "fisheye":
            return fisheye_undistort(target, self.dist_array)
        d = _dist12(self.dist_array)
        x = target.copy()
        # Newton's steps may overflow where the model folds over: judged by the residual below.
        with np.errstate(all="ignore"):
            for _ in range(max_iter):
                f, J = _distort(x, d, jacobian=True)
                r = f - target
                if np.all(np.abs(r) < tol):
                    return x, np.zeros(target.shape[:-1], dtype=bool)
                # Solve J dx = r per point (2x2).
                a, b, c, e = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
                det = a * e - b * c
                dx0 = (e * r[..., 0] - b * r[..., 1]) / det
                dx1 = (-c * r[..., 0] + a * r[..., 1]) / det
                x = x - np.stack([dx0, dx1], axis=-1)
            f, _ = _distort(x, d, jacobian=False)
            bad = ~np.all((np.abs(f - target) < 1e3 * tol) & np.isfinite(x), axis=-1)
        return x, bad

    def project(self, points_cam) -> np.ndarray:
        """Pixel coordinates of 3D points given in the camera frame.

        Parameters
        ----------
        points_cam : array_like, shape (..., 3)
            Points in the camera frame, mm, Z > 0.

        Returns
        -------
        ndarray, shape (..., 2)
            (u, v) in px.
        """
        P = np.asarray(points_cam, dtype=np.float64)
        if P.shape[-1] != 3:
            raise ValueError(f"points_cam must have shape (..., 3), got {P.shape}")
        if np.any(P[..., 2] <= 0):
            raise ValueError("points behind the camera (Z <= 0) cannot be projected")
        xy = P[..., :2] / P[..., 2:3]
        return self.pixels_from_normalized(self.distort(xy))

    def project_rectangle(self, plane2cam, extent, samples: int = 33) -> np.ndarray:
        """Pixel outline of a rectangle drawn on a plane (a target's board frame).

        The sides are sampled, not only the corners, because lens distortion
        bends straight edges: the bounding box of the outline is then the
        bounding box of the whole rectangle's image.

        Parameters
        ----------
        plane2cam : array_like, shape (4, 4)
            Pose of the plane's frame in the camera frame (mm); the rectangle
            lies in its z = 0 plane.
        extent : (x0, y0, x1, y1)
            The rectangle, mm, in the plane's frame.
        samples : int
            Points per side.

        Returns
        -------
        ndarray, shape (4 * samples, 2)
            (u, v) in px, side after side.

        Raises
        ------
        ValueError
            Part of the rectangle lies behind the camera (Z <= 0).
        """
        T = np.asarray(plane2cam, dtype=np.float64)
        x0, y0, x1, y1 = (float(v) for v in extent)
        k = np.linspace(0.0, 1.0, int(samples))
        outline = np.concatenate(
            [
                np.c_[x0 + (x1 - x0) * k, np.full_like(k, y0)],
                np.c_[np.full_like(k, x1), y0 + (y1 - y0) * k],
                np.c_[x0 + (x1 - x0) * k, np.full_like(k, y1)],
                np.c_[np.full_like(k, x0), y0 + (y1 - y0) * k],
            ]
        )
        P = outline @ T[:3, :2].T + T[:3, 3]
        if np.any(P[:, 2] <= 1e-6):
            raise ValueError("the rectangle reaches behind the camera (Z <= 0)")
        return self.project(P)

    def pixels_from_normalized(self, xy_distorted) -> np.ndarray:
        """(u, v) = (fx x' + cx, fy y' + cy) from distorted normalised coordinates."""
        xy = np.asarray(xy_distorted, dtype=np.float64)
        return np.stack([self.fx * xy[..., 0] + self.cx, self.fy * xy[..., 1] + self.cy], axis=-1)

    def normalized_from_pixels(self, uv) -> np.ndarray:
        """Distorted normalised coordinates of pixel positions (no undistortion)."""
        uv = np.asarray(uv, dtype=np.float64)
        return np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], axis=-1)

    def rays_from_pixels(self, uv) -> np.ndarray:
        """Ideal normalised coordinates (X/Z, Y/Z) of the rays through pixel positions.

        Raises
        ------
        UndistortionError
            Naming the pixel (of those given) farthest from the principal point where the
            distortion model cannot be inverted.
        """
        uv = np.asarray(uv, dtype=np.float64)
        rays, bad = self._newton_undistort(self.normalized_from_pixels(uv), 1e-14, 50)
        if not np.any(bad):
            return rays
        with np.errstate(all="ignore"):
            r = np.hypot(uv[..., 0] - self.cx, uv[..., 1] - self.cy)
        k = np.unravel_index(int(np.argmin(np.where(bad, r, np.inf))), r.shape)
        u, v = uv[k]
        n_bad = int(bad.sum())
        raise UndistortionError(
            "the lens distortion model cannot be inverted "
            + (f"at {n_bad} of the {bad.size} pixel positions asked, the nearest " if bad.size > 1 else "")
            + f"at ({u:.0f}, {v:.0f}) px, {float(r[k]):.0f} px from the principal point ("
            + (
                "beyond the fisheye model's field: its polynomial folds over, or the ray is 90 "
                "degrees or more off axis)"
                if self.model == "fisheye"
                else "beyond the calibrated field the distortion polynomial folds over)"
            )
        )

    # -------------------------------------------------------------------- json
    def to_dict(self) -> dict[str, Any]:
        """The ``camera.json`` object."""
        d: dict[str, Any] = {
            "image_size": list(self.image_size),
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }
        if self.model != "opencv":  # a pinhole camera's file stays as it always was
            d["model"] = self.model
        d["dist"] = list(self.dist)
        if self.std is not None:
            d["std"] = self.std
        if self.rms_px is not None:
            d["rms_px"] = self.rms_px
        if self.residual_std_px is not None:
            d["residual_std_px"] = list(self.residual_std_px)
        if self.cov is not None:
            d["cov"] = {"params": list(self.param_names), "matrix": self.cov.tolist()}
        if self.views:
            d["views"] = list(self.views)
        return d

    @classmethod
    def from_dict(cls, data: Any, source: str = "camera.json") -> CameraModel:
        """Validate a ``camera.json`` object (types, then physical plausibility).

        Raises
        ------
        InputError
            Naming ``source`` and the key that is missing, of the wrong type, or not
            physically plausible (:func:`plausibility_problems`).
        """
        _check_camera_keys(data, source)
        keys = _Keys(source)
        size = _image_size(data["image_size"], keys)
        vals = {k: keys.number(k, data[k], positive=k in ("fx", "fy")) for k in ("fx", "fy", "cx", "cy")}
        model = data.get("model", "opencv")
        if model not in LENS_MODELS:
            models = ", ".join(repr(m) for m in LENS_MODELS)
            raise keys.bad("model", f"must be one of {models}, got {_short(model)}")
        dist = _distortion(data["dist"], model, keys)
        std = data.get("std")
        if std is not None:
            std = _check_std(std, len(dist), keys.bad)
        cov = data.get("cov")
        if cov is not None:
            cov = _check_cov(cov, len(dist), keys.bad, model)
        rms, rsd, views = _fit_record(data, keys)
        camera = cls(
            image_size=(size[0], size[1]),
            dist=tuple(dist),
            std=std,
            rms_px=rms,
            residual_std_px=rsd,
            views=tuple(views),
            cov=cov,
            model=model,
            **vals,
        )
        problems = plausibility_problems(camera)
        if problems:
            key, what = problems[0]
            raise keys.bad(key, what)
        return camera


def _check_camera_keys(data: Any, source: str) -> None:
    """A ``camera.json`` object with every key a camera needs (a rig file said as such)."""
    if not isinstance(data, dict):
        raise InputError(
            f"expected a JSON object with keys image_size, fx, fy, cx, cy, dist; got {type(data).__name__}",
            source=source,
        )
    missing = [k for k in ("image_size", "fx", "fy", "cx", "cy", "dist") if k not in data]
    if missing and "cameras" in data:
        raise RigFileAsCamera(_rig_names(data["cameras"]), source=source)
    if missing:
        raise InputError(
            f"missing key{'s' if len(missing) > 1 else ''} {', '.join(repr(k) for k in missing)}",
            source=source,
        )


class _Keys:
    """The errors naming a ``camera.json`` key, and its numbers checked."""

    def __init__(self, source: str) -> None:
        self.source = source

    def bad(self, key: str, what: str) -> InputError:
        return InputError(f"key {key!r}: {what}", source=self.source)

    def number(self, key: str, v: Any, positive: bool = False, nonnegative: bool = False) -> float:
        x = _finite_float(v)
        if x is None:
            raise self.bad(key, f"must be a finite number, got {_short(v)}")
        if positive and x <= 0:
            raise self.bad(key, f"must be positive, got {_short(v)}")
        if nonnegative and x < 0:
            raise self.bad(key, f"must be zero or positive, got {_short(v)}")
        return x


def _image_size(size: Any, keys: _Keys) -> list[int]:
    """``image_size``: [width, height], positive integers no larger than a camera's."""
    if (
        not isinstance(size, list)
        or len(size) != 2
        or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)
    ):
        raise keys.bad("image_size", f"must be [width, height] in px (positive integers), got {_short(size)}")
    if max(size) > MAX_IMAGE_PX:
        raise keys.bad(
            "image_size",
            f"{size[0]}x{size[1]} px is not a camera image (at most {MAX_IMAGE_PX} px per side)",
        )
    return size


def _distortion(dist: Any, model: str, keys: _Keys) -> list[float]:
    """``dist``: as many finite numbers as the lens model takes."""
    if not isinstance(dist, list) or len(dist) not in DIST_LENGTHS[model]:
        expected = (
            "4 numbers [k1, k2, k3, k4] (the fisheye model)"
            if model == "fisheye"
            else "4, 5, 8 or 12 numbers [k1, k2, p1, p2, k3, ...]"
        )
        raise keys.bad("dist", f"must be a list of {expected}, got {_short(dist)}")
    return [keys.number(f"dist[{i}]", v) for i, v in enumerate(dist)]


def _fit_record(data: dict, keys: _Keys):
    """The calibration's record, each optional: ``rms_px``, ``residual_std_px`` and ``views``."""
    rms = data.get("rms_px")
    rms = keys.number("rms_px", rms, nonnegative=True) if rms is not None else None
    rsd = data.get("residual_std_px")
    if rsd is not None:
        if not isinstance(rsd, list) or len(rsd) != 2:
            raise keys.bad("residual_std_px", f"must be [sx, sy], got {_short(rsd)}")
        rsd = tuple(keys.number(f"residual_std_px[{i}]", rsd[i], nonnegative=True) for i in range(2))
    views = data.get("views", [])
    if not isinstance(views, list):
        raise keys.bad("views", f"must be a list, got {_short(views)}")
    for i, v in enumerate(views):
        if not isinstance(v, dict):
            raise keys.bad(f"views[{i}]", f"must be an object (image, used, rms_px, reason), got {_short(v)}")
    return rms, rsd, views


def _finite_float(v: Any) -> float | None:
    """``v`` as a float when it is a finite JSON number (not a bool), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        x = float(v)
    except OverflowError:  # an integer of hundreds of digits
        return None
    return x if math.isfinite(x) else None


def _short(v: Any, n: int = 60) -> str:
    """``repr(v)`` cut to ``n`` characters (a value of thousands of digits stays one line)."""
    try:
        text = repr(v)
    except ValueError:  # an integer too long for repr
        return "an integer of thousands of digits"
    return text if len(text) <= n else text[: n - 3] + "..."


def _check_std(std: Any, n_dist: int, bad) -> dict[str, Any]:
    """Validate the ``std`` object (1 sigma, non-negative or null when unknown)."""
    if not isinstance(std, dict):
        raise bad("std", f"must be an object with keys fx, fy, cx, cy, dist; got {_short(std)}")

    def sigma(key: str, v: Any) -> float | None:
        if v is None:
            return None
        x = _finite_float(v)
        if x is None or x < 0:
            raise bad(key, f"must be a standard deviation (a finite number >= 0, or null), got {_short(v)}")
        return x

    out: dict[str, Any] = {}
    for k, v in std.items():
        if k in ("fx", "fy", "cx", "cy"):
            out[k] = sigma(f"std.{k}", v)
        elif k == "dist":
            if not isinstance(v, list) or len(v) != n_dist:
                raise bad(
                    "std.dist", f"must be a list of {n_dist} standard deviations (as 'dist'), got {_short(v)}"
                )
            out[k] = [sigma(f"std.dist[{i}]", x) for i, x in enumerate(v)]
        else:
            out[k] = v
    return out


#: Tolerances of the ``cov`` checks, relative to the standard deviations: asymmetry, and the
#: most negative eigenvalue of the correlation matrix (rounding in a hand-written file).
COV_SYMMETRY_TOL = 1e-6
COV_PSD_TOL = 1e-8


def _check_cov(cov: Any, n_dist: int, bad, model: str = "opencv") -> np.ndarray:
    """Validate the ``cov`` object; the full covariance over the camera's parameters."""
    names = FISHEYE_NAMES if model == "fisheye" else DIST_NAMES[:n_dist]
    return check_cov_object(
        cov, ("fx", "fy", "cx", "cy", *names), bad, hint=f"'dist' has {n_dist} coefficients"
    )


def check_cov_object(
    cov: Any, names: tuple[str, ...], bad, *, hint: str = "", of: str = "this camera"
) -> np.ndarray:
    """Validate a ``{"params": [...], "matrix": [[...]]}`` covariance over parameters ``names``.

    Parameters
    ----------
    cov : object
        The JSON value (``params`` optional: default ``names``; a subset names only those).
    names : tuple of str
        Every parameter the covariance may name, in the order of the returned matrix.
    bad : callable (key, what) -> Exception
        Builds the error naming the file and key.
    hint : str
        Said with an unknown parameter name.
    of : str
        What the parameters belong to, for the messages.

    Returns
    -------
    ndarray, shape (len(names), len(names))
        Symmetric, positive semi-definite; zero rows and columns for parameters not named.
    """
    params = _cov_params(cov, names, bad, hint, of)
    C = _cov_matrix(cov["matrix"], params, bad)
    full = np.zeros((len(names), len(names)))
    idx = [names.index(p) for p in params]
    full[np.ix_(idx, idx)] = C
    return full


def _cov_params(cov: Any, names: tuple[str, ...], bad, hint: str, of: str) -> list[str]:
    """The parameters a ``cov`` object names: distinct, each one of ``names`` (default all)."""
    if not isinstance(cov, dict) or set(cov) - {"params", "matrix"} or "matrix" not in cov:
        raise bad("cov", f"must be an object {{'params': [...], 'matrix': [[...]]}}; got {_short(cov)}")
    params = cov.get("params", list(names))
    if (
        not isinstance(params, list)
        or not params
        or not all(isinstance(p, str) for p in params)
        or len(set(params)) != len(params)
    ):
        raise bad(
            "cov.params",
            f"must be a list of distinct parameter names from {list(names)}, got {_short(params)}",
        )
    unknown = [p for p in params if p not in names]
    if unknown:
        raise bad(
            "cov.params",
            f"{', '.join(repr(p) for p in unknown)} is not a parameter of {of} (expected names from "
            f"{list(names)}" + (f": {hint})" if hint else ")"),
        )
    return params


def _cov_matrix(M: Any, params: list[str], bad) -> np.ndarray:
    """``cov.matrix`` over ``params``: square, finite, symmetric (to rounding; made exactly so),
    positive semi-definite, a zero variance with zero covariances."""
    m = len(params)
    if not isinstance(M, list) or len(M) != m or not all(isinstance(r, list) and len(r) == m for r in M):
        raise bad(
            "cov.matrix",
            f"must be a square {m}x{m} list of lists (one row per entry of 'params'), got {_short(M)}",
        )
    C = np.empty((m, m))
    for i, row in enumerate(M):
        for j, v in enumerate(row):
            x = _finite_float(v)
            if x is None:
                raise bad(f"cov.matrix[{i}][{j}]", f"must be a finite number, got {_short(v)}")
            C[i, j] = x
    d = np.diag(C)
    if np.any(d < 0):
        i = int(np.argmin(d))
        raise bad(
            f"cov.matrix[{i}][{i}]", f"the variance of {params[i]} must be zero or positive, got {d[i]:.6g}"
        )
    s = np.sqrt(d)
    scale = np.outer(s, s)
    asym = np.abs(C - C.T)
    tol = COV_SYMMETRY_TOL * scale + 1e-300
    if np.any(asym > tol):
        i, j = np.unravel_index(int(np.argmax(asym / tol)), C.shape)
        raise bad(
            "cov.matrix",
            f"is not symmetric: [{i}][{j}] = {C[i, j]:.6g} but [{j}][{i}] = {C[j, i]:.6g} "
            f"({params[i]}, {params[j]})",
        )
    C = 0.5 * C + 0.5 * C.T  # (C + C.T) / 2 would overflow near 1e308
    nz = s > 0
    off = float(np.abs(C[~nz]).max()) if np.any(~nz) else 0.0
    if off > 0:
        i = int(np.flatnonzero(~nz)[0])
        raise bad(
            "cov.matrix",
            f"{params[i]} has a zero variance but a non-zero covariance with another parameter "
            "(not a covariance matrix)",
        )
    R = C[np.ix_(nz, nz)] / scale[np.ix_(nz, nz)]
    lo = float(np.linalg.eigvalsh(R).min()) if R.size else 0.0
    if lo < -COV_PSD_TOL:
        raise bad(
            "cov.matrix",
            f"is not positive semi-definite (its correlation matrix has the eigenvalue {lo:.3g}; "
            "correlations beyond +/-1, or rounded too coarsely?)",
        )
    return C


#: The central disc where any lens's distortion is one to one: this fraction of the smaller
#: image side around the principal point.
CENTRAL_FRACTION = 0.25


def _fold_near_centre(camera: CameraModel) -> str | None:
    """Why the distortion model is not one to one near the image centre (None when it is).

    Checked on 16 rays x 64 radii out to :data:`CENTRAL_FRACTION` of the smaller image side:
    the Jacobian of the distortion stays finite with a positive determinant there for any
    lens (a fold or a pole of the rational model this near the centre is not a lens).
    """
    w, h = camera.image_size
    r_max = CENTRAL_FRACTION * min(w, h) / max(camera.fx, camera.fy)
    ang = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    rad = np.linspace(0.0, r_max, 65)[1:]
    xy = np.stack(np.broadcast_arrays(rad[:, None] * np.cos(ang), rad[:, None] * np.sin(ang)), axis=-1)
    with np.errstate(all="ignore"):
        out, J = camera.distort_with_jacobian(xy)
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        bad = ~(np.isfinite(det) & (det > 0) & np.all(np.isfinite(out), axis=-1))
    if not np.any(bad):
        return None
    i = int(np.argmax(np.any(bad, axis=1)))  # the smallest radius where it folds
    px = rad[i] * max(camera.fx, camera.fy)
    return (
        f"the distortion model {list(camera.dist)} folds over (or has a pole) {px:.0f} px from the "
        f"principal point, within the central {CENTRAL_FRACTION * min(w, h):.0f} px where any lens is "
        "one to one: not a lens's distortion (a calibration that did not converge?)"
    )


def plausibility_problems(camera: CameraModel) -> list[tuple[str, str]]:
    """What makes a camera physically implausible: (key, message) pairs, empty when none.

    The checks of a ``camera.json`` (see the module docstring): focal lengths of 0.1 to 100
    image diagonals and fx / fy within 1/2.1 to 2.1 (:data:`MAX_ASPECT`), the principal point
    inside the image, radial coefficients within +/-1000, tangential and thin-prism ones within
    +/-1, a reprojection RMS (when given) below 0.5 % of the image diagonal, and a distortion
    one to one near the image centre.
    """
    w, h = camera.image_size
    diag = math.hypot(w, h)
    lo, hi = FOCAL_DIAGONALS[0] * diag, FOCAL_DIAGONALS[1] * diag
    out = []
    for k in ("fx", "fy"):
        f = getattr(camera, k)
        if not lo <= f <= hi:
            out.append(
                (
                    k,
                    f"{f:.6g} px is not a plausible focal length for a {w}x{h} px image (expected "
                    f"{lo:.4g} to {hi:.4g} px: {FOCAL_DIAGONALS[0]:g} to {FOCAL_DIAGONALS[1]:g} times "
                    "the image diagonal; a focal length in mm instead of px?)",
                )
            )
    if not out and not 1 / MAX_ASPECT <= camera.fx / camera.fy <= MAX_ASPECT:
        out.append(
            (
                "fy",
                f"fx / fy = {camera.fx:.6g} / {camera.fy:.6g} = {camera.fx / camera.fy:.3g} is not a "
                f"camera's pixel aspect (expected {1 / MAX_ASPECT:.2g} to {MAX_ASPECT:g}: 1 for square "
                "pixels; a calibration from views that do not constrain it, e.g. a wrong --board?)",
            )
        )
    for k, n in (("cx", w), ("cy", h)):
        c = getattr(camera, k)
        m = PRINCIPAL_MARGIN * n
        if not -0.5 - m <= c <= n - 0.5 + m:
            out.append(
                (
                    k,
                    f"principal point {c:.6g} px is outside the {w}x{h} px image (expected "
                    f"{-0.5 - m:.4g} to {n - 0.5 + m:.4g} px: the optical axis meets the image "
                    "inside it on any camera)",
                )
            )
    rms_limit = MAX_RMS_DIAGONAL * diag
    if camera.rms_px is not None and camera.rms_px > rms_limit:
        out.append(
            (
                "rms_px",
                f"reprojection RMS {camera.rms_px:.3g} px is far above what a calibration leaves (at "
                f"most {rms_limit:.2g} px, {100 * MAX_RMS_DIAGONAL:g} % of the image diagonal): the "
                "model does not describe the views (a wrong board size, or mis-detected corners?)",
            )
        )
    for i, c in enumerate(camera.dist):
        name = camera.dist_names[i]
        limit = MAX_RADIAL if name.startswith("k") else MAX_TANGENTIAL
        if abs(c) > limit:
            kind = (
                "radial" if name.startswith("k") else "tangential" if name.startswith("p") else "thin-prism"
            )
            out.append(
                (
                    f"dist[{i}]",
                    f"{name} = {c:.6g} is not a plausible {kind} distortion coefficient "
                    f"(expected within +/-{limit:g}; a calibration that did not converge?)",
                )
            )
    if not out:
        fold = _fold_near_centre(camera)
        if fold is not None:
            out.append(("dist", fold))
    return out + _uncertainty_problems(camera)


def sigma_limits(camera: CameraModel) -> np.ndarray:
    """The largest plausible 1-sigma of each calibrated parameter, :attr:`CameraModel.param_names` order.

    The width of the range the parameter itself may take (:func:`plausibility_problems`): a
    focal length's or the principal point's, the largest plausible focal length (100 image
    diagonals, px); a distortion coefficient's, twice its largest magnitude (radial
    :data:`MAX_RADIAL`, others :data:`MAX_TANGENTIAL`). An uncertainty beyond says nothing a
    calibration could have measured (a variance where a standard deviation belongs, a unit
    slip), and it made the pose covariances that carry it overflow or turn singular.
    """
    px = FOCAL_DIAGONALS[1] * math.hypot(*camera.image_size)
    return np.array(
        [
            px if n in ("fx", "fy", "cx", "cy") else 2 * (MAX_RADIAL if n.startswith("k") else MAX_TANGENTIAL)
            for n in camera.param_names
        ]
    )


def _uncertainty_problems(camera: CameraModel) -> list[tuple[str, str]]:
    """The first uncertainty (``std`` or ``cov``) beyond :func:`sigma_limits`, as (key, message)."""
    if camera.cov is not None:
        s = np.sqrt(np.abs(np.diag(camera.cov)))
    elif camera.std is not None:  # the std themselves: their squares could overflow
        sd = camera.std.get("dist") or [None] * len(camera.dist)
        s = np.array(
            [0.0 if x is None else float(x) for x in [*map(camera.std.get, ("fx", "fy", "cx", "cy")), *sd]]
        )
    else:
        return []
    limits = sigma_limits(camera)
    over = np.flatnonzero(~(s <= limits))
    if not over.size:
        return []
    k = int(over[0])
    name = camera.param_names[k]
    if camera.calibration_cov_source == "cov":
        key = "cov.matrix"
    else:
        key = f"std.{name}" if k < 4 else f"std.dist[{k - 4}]"
    unit = " px" if k < 4 else ""
    return [
        (
            key,
            f"a 1-sigma of {s[k]:.3g}{unit} for {name} is not a calibration's uncertainty (at most "
            f"{limits[k]:.3g}{unit}, the width of the range {name} itself may take; a variance where a "
            "standard deviation belongs, or another unit? null says 'unknown')",
        )
    ]


def _distort(xy: np.ndarray, d: np.ndarray, *, jacobian: bool):
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
    x = xy[..., 0]
    y = xy[..., 1]
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = num / den
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + r2 * (s3 + s4 * r2)
    out = np.stack([xd, yd], axis=-1)
    if not jacobian:
        return out, None
    dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    drad = (dnum * den - num * dden) / (den * den)  # d rad / d r2
    sx = s1 + 2 * s2 * r2  # d(s1 r2 + s2 r4)/d r2
    sy = s3 + 2 * s4 * r2
    J = np.empty((*x.shape, 2, 2))
    J[..., 0, 0] = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x + 2 * x * sx
    J[..., 0, 1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * y * sx
    J[..., 1, 0] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * x * sy
    J[..., 1, 1] = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x + 2 * y * sy
    return out, J


def _distort_coefficient_jacobian(xy: np.ndarray, d: np.ndarray) -> np.ndarray:
    """d(x', y') / d(k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4) at ideal points: (..., 2, 12)."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
    x = xy[..., 0]
    y = xy[..., 1]
    r2 = x * x + y * y
    r4 = r2 * r2
    r6 = r4 * r2
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    J = np.zeros((*x.shape, 2, 12))
    # Radial: rad = num / den; d rad / d k(1,2,3) = r^(2,4,6) / den, d rad / d k(4,5,6) = -num r^.. / den^2.
    for col, rk in ((0, r2), (1, r4), (4, r6)):
        J[..., 0, col] = x * rk / den
        J[..., 1, col] = y * rk / den
    for col, rk in ((5, r2), (6, r4), (7, r6)):
        g = -num * rk / (den * den)
        J[..., 0, col] = x * g
        J[..., 1, col] = y * g
    J[..., 0, 2] = 2 * x * y
    J[..., 1, 2] = r2 + 2 * y * y
    J[..., 0, 3] = r2 + 2 * x * x
    J[..., 1, 3] = 2 * x * y
    J[..., 0, 8] = r2
    J[..., 0, 9] = r4
    J[..., 1, 10] = r2
    J[..., 1, 11] = r4
    return J


def _undistortion_message(target: np.ndarray, bad: np.ndarray) -> str:
    """What :class:`UndistortionError` says: how many points, and the normalised radius."""
    with np.errstate(all="ignore"):
        r = np.hypot(target[..., 0], target[..., 1])
    n_bad = int(np.sum(bad))
    r_bad = r[bad]
    r_ok = r[~bad]
    where = (
        f"distorted radius up to {float(np.nanmax(r_bad)):.3g}"
        if np.any(np.isfinite(r_bad))
        else "not finite"
    )
    inside = f"; it converged up to {float(r_ok.max()):.3g}" if r_ok.size else ""
    return (
        f"the lens distortion model cannot be inverted at {n_bad} of {bad.size} points "
        f"(normalised {where}{inside}): undistortion did not converge (points far outside the "
        "calibrated field?)"
    )


def reference_camera() -> CameraModel:
    """The reference vision study's camera (its Table IV): 2592x1944 px, DFK 72UC02.

    fx = 3733.27, fy = 3722.85, cx = 1466.77, cy = 904.81 px, k1 = -0.09, k2 = 0.11.
    """
    return CameraModel(
        image_size=(2592, 1944),
        fx=3733.27,
        fy=3722.85,
        cx=1466.77,
        cy=904.81,
        dist=(-0.09, 0.11, 0.0, 0.0, 0.0),
    )


class RigFileAsCamera(InputError):
    """A ``rig.json`` (several cameras) given where one camera's ``camera.json`` is read.

    Its message says what the file is; the command line adds which option takes it.
    """

    def __init__(self, cameras: str, *, source: str | None = None) -> None:
        super().__init__(
            f"this is a rig file ({cameras}), not one camera's camera.json: measure with it as a rig",
            source=source,
        )
        self.cameras = cameras


def _rig_names(items: Any) -> str:
    """``cameras 'left', 'right'``: the cameras a rig file's ``cameras`` list names, as far as it does."""
    names = [c.get("name") for c in items if isinstance(c, dict)] if isinstance(items, list) else []
    names = [repr(n) for n in names if isinstance(n, str)]
    return f"cameras {', '.join(names)}" if names else "key 'cameras'"


def load_camera(path: str | Path) -> CameraModel:
    """Read and validate a ``camera.json`` file (InputError naming the file and key)."""
    return CameraModel.from_dict(read_json(path, "camera file"), source=str(path))


def save_camera(camera: CameraModel, path: str | Path) -> Path | None:
    """Write ``camera.json`` atomically; a different earlier file is kept as ``camera.json.bak``.

    Returns the backup written, or None.
    """
    return replace_keeping_previous(path, dumps_json(camera.to_dict(), inline_numbers=True) + "\n")


# ------------------------------------------------------------------ invertible field

#: Share of the radius where the distortion folds over that is used (rays closer to the fold
#: are ill-conditioned: a pixel of noise there is many pixels of ray).
FIELD_SAFETY = 0.97
#: Directions and largest normalised radius (tan of the angle off axis) searched for a fold.
_FIELD_ANGLES = 720
_FIELD_R_MAX = 6.0
_FIELD_STEPS = 1200
_FIELD_CACHE: OrderedDict = OrderedDict()


@dataclass(frozen=True)
class InvertibleField:
    """Where a camera's lens-distortion model is one to one (get one with :func:`invertible_field`).

    A strong lens's calibrated polynomial (k1 -0.3, k2 0.15, k3 -0.08, say) stops growing
    with the radius somewhere beyond the calibrated field and folds back: there a distorted
    position has two undistorted rays, or none. Along each direction from the principal
    point, the field ends at :data:`FIELD_SAFETY` times the first radius where the
    distortion's Jacobian determinant is no longer positive; ``rho`` is that end in the
    distorted normalised plane, at the angles ``phi`` (sorted, radians).

    Attributes
    ----------
    phi, rho : ndarray, shape (n,)
    folds : bool
        False when the model is one to one out to 80 degrees off axis in every direction
        (89.5 degrees with the fisheye model, whose field is a disc: there ``rho`` is the
        same at every angle, ``theta_d`` at :data:`FIELD_SAFETY` times the angle off axis where
        theta_d stops growing, or at :data:`stiffmap.lens.MAX_THETA`).
    """

    camera: CameraModel
    phi: np.ndarray
    rho: np.ndarray
    folds: bool

    def contains_normalized(self, xy_distorted) -> np.ndarray:
        """True where distorted normalised points (..., 2) are inside the field."""
        xy = np.asarray(xy_distorted, dtype=np.float64)
        with np.errstate(all="ignore"):
            ang = np.arctan2(xy[..., 1], xy[..., 0])
            rho = np.hypot(xy[..., 0], xy[..., 1])
            lim = np.interp(ang, self.phi, self.rho, period=2 * np.pi)
            return np.isfinite(rho) & (rho < lim)

    def contains_pixels(self, uv) -> np.ndarray:
        """True where pixel positions (..., 2) are inside the field."""
        return self.contains_normalized(self.camera.normalized_from_pixels(uv))

    def radius_px(self) -> tuple[float, float]:
        """Shortest and longest distance from the principal point to the field's end, px."""
        c = self.camera
        d = self.rho * np.hypot(c.fx * np.cos(self.phi), c.fy * np.sin(self.phi))
        return float(d.min()), float(d.max())

    def image_share(self) -> float:
        """Share of the image's pixels inside the field (on a 64 x 64 sample grid)."""
        w, h = self.camera.image_size
        uv = np.stack(np.meshgrid(np.linspace(0, w - 1, 64), np.linspace(0, h - 1, 64)), axis=-1)
        return float(np.mean(self.contains_pixels(uv)))

    def describe(self) -> str:
        """One sentence: how far the field reaches and how much of the image it covers."""
        if not self.folds:
            share = self.image_share() if self.camera.model == "fisheye" else 1.0
            if share < 1.0:
                return (
                    f"the fisheye model reaches 89.5 degrees off axis, {100 * share:.1f} % of the image "
                    "(the other pixels see rays 90 degrees or more off axis, which have no X/Z)"
                )
            return "the lens model is one to one over the whole field of view"
        lo, hi = self.radius_px()
        share = self.image_share()
        where = "the whole image" if share >= 1.0 else f"{100 * share:.1f} % of the image"
        return (
            f"the lens model is invertible out to {lo:.0f}-{hi:.0f} px from the principal point "
            f"({where}; beyond, its polynomial folds over)"
        )


def invertible_field(camera: CameraModel) -> InvertibleField:
    """The field where ``camera``'s distortion model is one to one, computed once per camera."""
    key = camera.key
    hit = _FIELD_CACHE.get(key)
    if hit is not None:
        return hit
    field_ = _fisheye_field(camera) if camera.model == "fisheye" else _polynomial_field(camera)
    _FIELD_CACHE[key] = field_
    while len(_FIELD_CACHE) > _RAY_CACHE_SIZE:
        _FIELD_CACHE.popitem(last=False)
    return field_


def _fisheye_field(camera: CameraModel) -> InvertibleField:
    """The fisheye model's field: a disc, out to where theta_d stops growing (or 89.5 degrees)."""
    theta_end, folds = fisheye_theta_end(camera.dist_array)
    if folds:
        theta_end *= FIELD_SAFETY
    rho = float(fisheye_theta_d(theta_end, camera.dist_array)[0])
    phi = np.linspace(-np.pi, np.pi, _FIELD_ANGLES, endpoint=False)
    return InvertibleField(camera, phi, np.full(phi.shape, rho), folds)


def _polynomial_field(camera: CameraModel) -> InvertibleField:
    """The pinhole polynomial's field: along each direction, up to where its Jacobian folds."""
    theta = np.linspace(0.0, 2 * np.pi, _FIELD_ANGLES, endpoint=False)
    r = np.linspace(0.0, _FIELD_R_MAX, _FIELD_STEPS + 1)[1:]
    u = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    d = _dist12(camera.dist_array)
    with np.errstate(all="ignore"):
        _, J = _distort(r[:, None, None] * u[None], d, jacobian=True)
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        bad = ~(np.isfinite(det) & (det > 0))
    folds = bool(bad.any())
    first = np.where(bad.any(axis=0), np.argmax(bad, axis=0), r.size - 1)
    r_end = FIELD_SAFETY * r[first]
    with np.errstate(all="ignore"):
        edge, _ = _distort(r_end[:, None] * u, d, jacobian=False)
    phi = np.arctan2(edge[:, 1], edge[:, 0])
    rho = np.hypot(edge[:, 0], edge[:, 1])
    ok = np.isfinite(phi) & np.isfinite(rho)
    order = np.argsort(phi[ok])
    return InvertibleField(camera, phi[ok][order], rho[ok][order], folds)


# ------------------------------------------------------------------ ray cache

#: Step of the grid of exact rays the ray map interpolates, px.
_RAY_STEP_PX = 16
#: How far the grid reaches beyond the image on every side, px (the renderer asks for a
#: one-pixel halo, of a camera supersampled up to a few times).
_RAY_PAD_PX = 64
#: Cameras whose ray maps are kept (least recently used dropped first).
_RAY_CACHE_SIZE = 4
_RAY_CACHE: OrderedDict = OrderedDict()


class PixelRays:
    """Undistorted rays (x/z, y/z) of the pixels of a camera (get one with :func:`pixel_rays`).

    A ray is the pinhole ray ((u - cx) / fx, (v - cy) / fy) plus a correction, the
    inverted lens distortion (a few percent of the ray). The correction is a bicubic
    spline of the exact rays (:meth:`CameraModel.rays_from_pixels`) on a 16-px grid
    reaching 64 px beyond the image: interpolation error about 1e-8 px for the
    reference camera.

    Only pixels inside the lens model's :class:`InvertibleField` have rays. When the field
    ends within the image or its margin (a strong wide-angle lens), the correction bends
    too sharply near the fold for a spline: :attr:`correction_maps` are then the exact
    rays of every pixel inside the field (Newton's method, computed once), zero beyond it,
    and :attr:`valid_map` says which pixels have rays; :attr:`covers_image` says whether
    users need to look. (:meth:`block`, for the renderer, needs a camera that covers
    its image.)

    The fisheye model's correction is no small one (tens of percent of the ray near a wide
    lens's edge, a bicubic spline of it off by 1e-3 px), but its inverse is a one-dimensional
    root that costs little (:func:`stiffmap.lens.fisheye_undistort`, 0.2 s a megapixel): for
    it, :meth:`block` and :attr:`correction_maps` are exact rays, NaN beyond the field.

    Attributes
    ----------
    px : ndarray, shape (w,)
        Pinhole x/z of the pixel columns, (u - cx) / fx.
    py : ndarray, shape (h,)
        Pinhole y/z of the pixel rows.
    px32, py32 : ndarray of float32
        The same in float32.
    """

    def __init__(self, camera: CameraModel) -> None:
        # Lazy: scipy.interpolate costs ~0.2 s to import, and reading camera.json must stay light.
        from scipy.interpolate import RectBivariateSpline
        from scipy.ndimage import distance_transform_edt

        self.camera = camera
        w, h = camera.image_size
        self.px = (np.arange(w, dtype=np.float64) - camera.cx) / camera.fx
        self.py = (np.arange(h, dtype=np.float64) - camera.cy) / camera.fy
        self.px32 = self.px.astype(np.float32)
        self.py32 = self.py.astype(np.float32)
        self.field = invertible_field(camera)
        self._valid: np.ndarray | None = None
        self._maps: tuple[np.ndarray, np.ndarray] | None = None
        # The fisheye model: exact rays everywhere (its inverse is cheap), no spline.
        self._direct = camera.model == "fisheye"
        self._exact = self._direct
        if self._direct:
            return
        us = np.arange(-_RAY_PAD_PX, w + _RAY_PAD_PX + _RAY_STEP_PX, _RAY_STEP_PX, dtype=np.float64)
        vs = np.arange(-_RAY_PAD_PX, h + _RAY_PAD_PX + _RAY_STEP_PX, _RAY_STEP_PX, dtype=np.float64)
        U, V = np.meshgrid(us, vs)
        uv = np.stack([U, V], axis=-1)
        ok = self.field.contains_pixels(uv)
        rays = np.zeros(uv.shape)
        x, bad = camera._newton_undistort(camera.normalized_from_pixels(uv[ok]), 1e-14, 50)
        rays[ok] = x
        ok[ok] = ~bad
        if not ok.any():  # pragma: no cover - the centre is always inside (plausibility checks)
            raise UndistortionError(f"no pixel of the image can be undistorted: {self.field.describe()}")
        corr_x = rays[..., 0] - (U - camera.cx) / camera.fx
        corr_y = rays[..., 1] - (V - camera.cy) / camera.fy
        if not ok.all():
            # Beyond the field: the nearest valid node's correction (keeps the spline tame).
            idx = distance_transform_edt(~ok, return_distances=False, return_indices=True)
            corr_x, corr_y = corr_x[idx[0], idx[1]], corr_y[idx[0], idx[1]]
        self._sx = RectBivariateSpline(vs, us, corr_x, kx=3, ky=3, s=0)
        self._sy = RectBivariateSpline(vs, us, corr_y, kx=3, ky=3, s=0)
        # Where the field ends inside the grid the correction bends sharply near the fold, beyond
        # a spline's reach: the maps are then the exact rays of every pixel (Newton, once).
        self._exact = not ok.all()

    def block(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays on the grid rows x cols (pixel positions, may reach outside the image).

        Returns
        -------
        rx, ry : ndarray, shape (len(rows), len(cols))
            x/z and y/z, float64.
        """
        c = self.camera
        if self._direct:
            uv = np.stack(np.meshgrid(cols, rows), axis=-1)
            xy, _ = c._newton_undistort(c.normalized_from_pixels(uv), 1e-15, 20)
            return xy[..., 0], xy[..., 1]
        rx = ((cols - c.cx) / c.fx)[None, :] + self._sx(rows, cols)
        ry = ((rows - c.cy) / c.fy)[:, None] + self._sy(rows, cols)
        return rx, ry

    @property
    def valid_map(self) -> np.ndarray:
        """(h, w) bool: True where a pixel's ray is right (inside the invertible field)."""
        if self._valid is None:
            w, h = self.camera.image_size
            if self._exact:
                self.correction_maps  # noqa: B018 - computes the exact maps and their validity
            else:
                self._valid = np.ones((h, w), dtype=bool)
        return self._valid

    @property
    def covers_image(self) -> bool:
        """True when every pixel of the image has a right ray."""
        return bool(self.valid_map.all())

    @property
    def correction_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """The corrections at every pixel centre, float32 (h, w) each (to ~1e-9), built once.

        The ray of pixel [row, col] is (px[col] + cx[row, col], py[row] + cy[row, col]).
        """
        if self._maps is None:
            w, h = self.camera.image_size
            cols = np.arange(w, dtype=np.float64)
            cx = np.zeros((h, w), dtype=np.float32)
            cy = np.zeros((h, w), dtype=np.float32)
            valid = np.ones((h, w), dtype=bool)
            cam = self.camera
            for r in range(0, h, 256):
                rows = np.arange(r, min(r + 256, h), dtype=np.float64)
                if not self._exact:
                    cx[r : r + rows.size] = self._sx(rows, cols)
                    cy[r : r + rows.size] = self._sy(rows, cols)
                    continue
                uv = np.stack(np.meshgrid(cols, rows), axis=-1)
                ok = self.field.contains_pixels(uv)
                x, bad = cam._newton_undistort(cam.normalized_from_pixels(uv[ok]), 1e-14, 50)
                ok[ok] = ~bad
                x = x[~bad]
                cx[r : r + rows.size][ok] = x[:, 0] - (uv[ok][:, 0] - cam.cx) / cam.fx
                cy[r : r + rows.size][ok] = x[:, 1] - (uv[ok][:, 1] - cam.cy) / cam.fy
                valid[r : r + rows.size] = ok
            self._maps = (cx, cy)
            self._valid = valid
        return self._maps


def pixel_rays(camera: CameraModel) -> PixelRays:
    """The camera's ray map, built on first use and cached (per :attr:`CameraModel.key`)."""
    key = camera.key
    rays = _RAY_CACHE.get(key)
    if rays is None:
        rays = PixelRays(camera)
        _RAY_CACHE[key] = rays
        while len(_RAY_CACHE) > _RAY_CACHE_SIZE:
            _RAY_CACHE.popitem(last=False)
    else:
        _RAY_CACHE.move_to_end(key)
    return rays
