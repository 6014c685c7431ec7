"""Compliant displacement of the mobile target between unloaded and loaded images.

:func:`compliant_displacement` turns the :class:`~stiffmap.vision.sequence.ImageMeasurement`
of unloaded and loaded images of one robot position into the displacement
(d, r) of the mobile target (or of a point of the platform): d the translation
in mm, r the rotation vector of R_loaded R_unloaded^T in rad
(``docs/conventions.md``).

Samples: when there are as many unloaded as loaded images (n > 1) they are
taken as repeats, paired in order (unloaded i with loaded i: a drift between
repeats cancels); otherwise every loaded image is compared with the mean pose
of the unloaded images. The result is the mean of the samples, their standard
deviation and n, and the covariance of the mean propagated from the pose
covariances.

Calibration: the camera's calibration error is common to every image, so it is not noise
that averages out or adds up from pose to pose. Each pose carries its sensitivity
A = d pose / d c to the camera's parameters c (``BoardPose.calibration_jacobian``); a
displacement's sensitivity is the difference G = P_loaded A_loaded - P_unloaded A_unloaded
(P moving the pose's perturbation to the point's), averaged over the samples, and its
calibration share is G cov_c G^T. A focal-length error is thus a scale error of the
displacement (as it is of the distance), the share does not shrink with the number of
repeats, and it is carried separately (``cov_calibration``, ``calibration_jacobian``) so
that displacements measured with one camera can be combined with their common error
(``cov`` is the total: the poses' own noise, ``cov_noise``, plus the calibration's share).

Frame: the displacement is computed in the camera frame from the mobile
target's poses only, and rotated into the robot base frame with ``cam2base``
averaged over every image where the fixed target was seen (reference paper,
eq. 1). Using each image's own ``cam2base`` instead would add the fixed
target's pose noise, magnified by the lever arm between the two targets, to
every displacement. The fixed target's apparent motion between the unloaded
and loaded images is reported (``fixed_shift``) and flagged when it exceeds
5 sigma: the camera or the base moved.

:func:`displacement_per_image` compares each image of a series with the same
reference images, one by one and together (``stiffmap displacement``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry import displacement_from_poses, mean_transform
from ..posemath import point_jacobian, skew
from .sequence import ImageMeasurement

__all__ = [
    "Displacement",
    "compliant_displacement",
    "pair_calibration_jacobian",
    "base_frame_calibration_jacobian",
    "mean_pose",
    "ImageDisplacements",
    "displacement_per_image",
]


@dataclass(frozen=True)
class Displacement:
    """Compliant displacement of the mobile target (or a point of the platform).

    Attributes
    ----------
    d : ndarray, shape (3,), mm
        Mean translation (loaded minus unloaded).
    r : ndarray, shape (3,), rad
        Mean rotation vector of R_loaded R_unloaded^T.
    cov : ndarray, shape (6, 6)
        Covariance of (d, r), propagated from the pose covariances.
    d_std, r_std : ndarray, shape (3,)
        Standard deviation of the samples (NaN when n = 1).
    n : int
        Number of samples.
    samples : ndarray, shape (n, 6)
        (d, r) of each sample.
    frame : str
        ``"base"`` or ``"cam"``.
    point : ndarray, shape (3,), mm
        The point of the mobile target (its frame) whose displacement this is.
    pairing : str
        ``"pairs"`` (repeat i: unloaded i, loaded i) or ``"mean-reference"``.
    n_unloaded, n_loaded : int
        Images used (failed ones left out).
    fixed_shift : ndarray, shape (6,) or None
        Apparent displacement of the fixed target between the mean unloaded and
        the mean loaded images, camera frame (should be zero).
    flags : tuple of str
        Warnings (fixed target moved, images left out).
    cov_calibration : ndarray, shape (6, 6) or None
        The calibration's share of ``cov``, G cov_c G^T (None: the camera's uncertainty is
        unknown, not included).
    calibration_jacobian : ndarray, shape (6, n) or None
        G = d(d, r) / d(camera parameters), ``CameraModel.param_names`` order: the
        displacement's part of the error common to every measurement with the camera.
    """

    d: np.ndarray
    r: np.ndarray
    cov: np.ndarray
    d_std: np.ndarray
    r_std: np.ndarray
    n: int
    samples: np.ndarray
    frame: str
    point: np.ndarray
    pairing: str
    n_unloaded: int
    n_loaded: int
    fixed_shift: np.ndarray | None = None
    flags: tuple[str, ...] = ()
    cov_calibration: np.ndarray | None = None
    calibration_jacobian: np.ndarray | None = None

    @property
    def cov_noise(self) -> np.ndarray:
        """The share of ``cov`` from the poses' own noise (independent between measurements)."""
        return self.cov if self.cov_calibration is None else self.cov - self.cov_calibration

    @property
    def d_sigma_calibration(self) -> np.ndarray:
        """1-sigma of d due to the calibration alone, shape (3,), mm (NaN: unknown)."""
        return self._sigma_cal()[:3]

    @property
    def r_sigma_calibration(self) -> np.ndarray:
        """1-sigma of r due to the calibration alone, shape (3,), rad (NaN: unknown)."""
        return self._sigma_cal()[3:]

    @property
    def calibration_share(self) -> np.ndarray:
        """Share of each component's variance from the calibration, shape (6,), 0..1 (NaN: unknown)."""
        if self.cov_calibration is None:
            return np.full(6, np.nan)
        tot = np.diag(self.cov)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(tot > 0, np.diag(self.cov_calibration) / tot, 0.0)

    def _sigma_cal(self) -> np.ndarray:
        if self.cov_calibration is None:
            return np.full(6, np.nan)
        return np.sqrt(np.maximum(np.diag(self.cov_calibration), 0.0))

    @property
    def vector(self) -> np.ndarray:
        """(dx, dy, dz, rx, ry, rz), mm and rad."""
        return np.concatenate([self.d, self.r])

    @property
    def d_sigma(self) -> np.ndarray:
        """Propagated 1-sigma of d, shape (3,), mm."""
        return np.sqrt(np.diag(self.cov)[:3])

    @property
    def r_sigma(self) -> np.ndarray:
        """Propagated 1-sigma of r, shape (3,), rad."""
        return np.sqrt(np.diag(self.cov)[3:])


def mean_pose(poses) -> np.ndarray:
    """Mean of rigid transforms (:func:`stiffmap.geometry.mean_transform`).

    Parameters
    ----------
    poses : array_like, shape (n, 4, 4)

    Returns
    -------
    ndarray, shape (4, 4)
    """
    return mean_transform(poses)


def _ref_rotation(T_ref: np.ndarray, T_moved: np.ndarray) -> np.ndarray:
    """diag(I, Q), Q = R_moved R_ref^T: r = rotvec(Exp(dr1) Q Exp(-dr0)) moves by dr1 - Q dr0.

    Matters for an error common to both poses (the calibration's): each pose's rotation error
    is large beside their difference, and Q = I would leave [r]x dr0 in it.
    """
    M = np.eye(6)
    M[3:, 3:] = T_moved[:3, :3] @ T_ref[:3, :3].T
    return M


def pair_calibration_jacobian(
    T_ref: np.ndarray, A_ref: np.ndarray, T_moved: np.ndarray, A_moved: np.ndarray, point: np.ndarray
) -> np.ndarray:
    """Sensitivity (6, n) of the displacement of ``point`` between two poses to the camera's parameters.

    G = P_moved A_moved - diag(I, Q) P_ref A_ref (camera frame), with A = d(t, r)/d(camera
    parameters) of each pose (``BoardPose.calibration_jacobian``; for a mean reference pose the
    mean of its images' A), P the point's Jacobian and Q = R_moved R_ref^T.
    """
    A0 = _ref_rotation(T_ref, T_moved) @ point_jacobian(T_ref, point)
    return point_jacobian(T_moved, point) @ A_moved - A0 @ A_ref


def base_frame_calibration_jacobian(
    G_cam: np.ndarray, d_base: np.ndarray, R_cam2base: np.ndarray, A_fixed_rotation: np.ndarray
) -> np.ndarray:
    """A displacement's calibration sensitivity (6, n) once rotated into the base frame.

    The displacement d_cam is turned into the base frame by R_G, the rotation of ``cam2base``
    found from the fixed target's (mean) pose, whose rotation moves with the calibration too
    (its sensitivity ``A_fixed_rotation``, rows 3: of the fixed target's A, averaged): d_base =
    R_G d_cam moves by R_G G_cam dc + [d_base]x R_G A_fixed_rotation dc (per translation and
    rotation block).
    """
    B = np.zeros((6, 6))
    B[:3, :3] = R_cam2base
    B[3:, 3:] = R_cam2base
    C = np.vstack([skew(d_base[:3]), skew(d_base[3:])])
    return B @ G_cam + C @ R_cam2base @ A_fixed_rotation


def _usable(ms: Sequence[ImageMeasurement], what: str) -> list[ImageMeasurement]:
    good = [m for m in ms if m.ok and m.mobile is not None]
    if not good:
        names = ", ".join(m.image for m in ms[:3]) + (" ..." if len(ms) > 3 else "")
        raise InputError(f"no usable {what} image (mobile target not measured in {names or 'any image'})")
    return good


def _check_point(point, pairing: str, frame: str) -> np.ndarray:
    """The platform point (3,) mm, with ``pairing`` and ``frame`` checked."""
    q = np.zeros(3) if point is None else np.asarray(point, dtype=np.float64).reshape(-1)
    if q.shape != (3,) or not np.all(np.isfinite(q)):
        raise ValueError(f"point must be 3 finite numbers (mm, target frame), got {point!r}")
    if pairing not in ("auto", "pairs", "mean-reference"):
        raise ValueError(f"pairing must be 'auto', 'pairs' or 'mean-reference', got {pairing!r}")
    if frame not in ("auto", "base", "cam"):
        raise ValueError(f"frame must be 'auto', 'base' or 'cam', got {frame!r}")
    return q


def _groups(unloaded, loaded, pairing: str):
    """The usable unloaded and loaded measurements, the pairing (``"auto"`` chosen) and the
    flags naming the images left out."""
    flags = []
    u_all, l_all = list(unloaded), list(loaded)
    u = _usable(u_all, "unloaded")
    lo = _usable(l_all, "loaded")
    for group, good, name in ((u_all, u, "unloaded"), (l_all, lo, "loaded")):
        if len(good) < len(group):
            bad = [m.image for m in group if m not in good]
            flags.append(f"{len(bad)} {name} image(s) left out: {', '.join(bad)}")
    if pairing == "auto":
        pairing = (
            "pairs" if len(u) == len(lo) == len(u_all) == len(l_all) and len(u) > 1 else "mean-reference"
        )
    if pairing == "pairs" and len(u) != len(lo):
        raise InputError(f"pairs need as many unloaded as loaded images, got {len(u)} and {len(lo)}")
    return u, lo, pairing, flags


def _paired(u, lo, q, with_A: bool):
    """Samples, noise covariance of their mean and calibration sensitivity (None without) of
    the displacements of loaded image i from unloaded image i."""
    samples = []
    cov_sum = np.zeros((6, 6))
    G_sum = 0.0
    for a, b in zip(u, lo, strict=True):
        samples.append(displacement_from_poses(a.mobile2cam, b.mobile2cam, q))
        A0 = _ref_rotation(a.mobile2cam, b.mobile2cam) @ point_jacobian(a.mobile2cam, q)
        A1 = point_jacobian(b.mobile2cam, q)
        cov_sum += A0 @ a.mobile.cov_noise @ A0.T + A1 @ b.mobile.cov_noise @ A1.T
        if with_A:
            Aa, Ab = a.mobile.calibration_jacobian, b.mobile.calibration_jacobian
            G_sum = G_sum + pair_calibration_jacobian(a.mobile2cam, Aa, b.mobile2cam, Ab, q)
    cov = cov_sum / len(u) ** 2
    return samples, cov, (G_sum / len(u) if with_A else None)


def _from_mean_reference(u, lo, q, with_A: bool):
    """Samples, noise covariance of their mean and calibration sensitivity (None without) of
    the displacements of every loaded image from the mean unloaded pose."""
    samples = []
    cov_sum = np.zeros((6, 6))
    ref = mean_pose([m.mobile2cam for m in u])
    cov_ref = np.zeros((6, 6))
    for a in u:
        A0a = point_jacobian(a.mobile2cam, q)
        cov_ref += A0a @ a.mobile.cov_noise @ A0a.T
    cov_ref /= len(u) ** 2
    A_ref = np.mean([a.mobile.calibration_jacobian for a in u], axis=0) if with_A else None
    G_sum = 0.0
    for b in lo:
        samples.append(displacement_from_poses(ref, b.mobile2cam, q))
        A1 = point_jacobian(b.mobile2cam, q)
        cov_sum += A1 @ b.mobile.cov_noise @ A1.T
        if with_A:
            Ab = b.mobile.calibration_jacobian
            G_sum = G_sum + pair_calibration_jacobian(ref, A_ref, b.mobile2cam, Ab, q)
    cov = cov_ref + cov_sum / len(lo) ** 2
    return samples, cov, (G_sum / len(lo) if with_A else None)


def _fixed_target_shift(u, lo, flags: list[str]) -> np.ndarray | None:
    """Apparent motion of the fixed target (camera frame) when it was seen in both groups; a
    flag when it moved beyond its noise."""
    fu = [m for m in u if m.fixed is not None]
    fl = [m for m in lo if m.fixed is not None]
    if not (fu and fl):
        return None
    F0 = mean_pose([m.fixed2cam for m in fu])
    F1 = mean_pose([m.fixed2cam for m in fl])
    fixed_shift = displacement_from_poses(F0, F1)
    # The fixed target's own noise only: the calibration's error moves it alike in both groups.
    cf = sum(m.fixed.cov_noise for m in fu) / len(fu) ** 2 + sum(m.fixed.cov_noise for m in fl) / len(fl) ** 2
    z = fixed_shift / np.sqrt(np.maximum(np.diag(cf), 1e-30))
    if np.max(np.abs(z)) > 5:
        flags.append(
            f"the fixed target moved by {np.linalg.norm(fixed_shift[:3]):.4f} mm / "
            f"{np.linalg.norm(fixed_shift[3:]):.2e} rad between the unloaded and loaded images "
            f"({np.max(np.abs(z)):.0f} sigma): did the camera or the robot base move?"
        )
    return fixed_shift


def _in_base_frame(S, cov, Gc, with_base):
    """The samples, their mean, covariance and calibration sensitivity rotated into the base
    frame (the mean cam2base of the images with one)."""
    G = mean_pose([m.cam2base for m in with_base])
    RG = G[:3, :3]
    Bm = np.zeros((6, 6))
    Bm[:3, :3] = RG
    Bm[3:, 3:] = RG
    S = S @ Bm.T
    mean = S.mean(axis=0)
    # Uncertainty of the mean cam2base rotation (d r_G = -R_G d r_fixed), averaged.
    Crf = sum(m.fixed.cov_noise[3:, 3:] for m in with_base) / len(with_base) ** 2
    CG = RG @ Crf @ RG.T
    C = np.vstack([-skew(mean[:3]), -skew(mean[3:])])
    cov = Bm @ cov @ Bm.T + C @ CG @ C.T
    if Gc is not None:
        if all(m.fixed.calibration_jacobian is not None for m in with_base):
            Af = np.mean([m.fixed.calibration_jacobian[3:] for m in with_base], axis=0)
            Gc = base_frame_calibration_jacobian(Gc, mean, RG, Af)
        else:
            Gc = None
    return S, mean, cov, Gc


def compliant_displacement(
    unloaded: Sequence[ImageMeasurement],
    loaded: Sequence[ImageMeasurement],
    point=None,
    *,
    pairing: str = "auto",
    frame: str = "auto",
) -> Displacement:
    """Displacement of the mobile target between unloaded and loaded images.

    Parameters
    ----------
    unloaded, loaded : sequence of ImageMeasurement
        Measurements of one robot position without and with the load (failed
        images are left out and flagged).
    point : array_like, shape (3,), optional
        A point of the platform in the mobile target's frame (mm), e.g. the
        tool point; default the target's origin.
    pairing : {"auto", "pairs", "mean-reference"}
        ``"auto"``: pairs when both lists have the same length n > 1 (and no image
        failed), else mean-reference.
    frame : {"auto", "base", "cam"}
        ``"auto"``: the base frame when ``mobile2base`` is known in some image,
        else the camera frame.

    Returns
    -------
    Displacement

    Raises
    ------
    InputError
        When no unloaded or no loaded image is usable, or the base frame is
        asked without a fixed target.
    """
    q = _check_point(point, pairing, frame)
    u, lo, pairing, flags = _groups(unloaded, loaded, pairing)
    # The poses' own noise is independent from image to image (cov_noise); the calibration's
    # error is common: its sensitivity Gc is the difference of the poses' sensitivities.
    with_A = all(m.mobile.calibration_jacobian is not None for m in u + lo)
    displacements = _paired if pairing == "pairs" else _from_mean_reference
    samples, cov, Gc = displacements(u, lo, q, with_A)
    S = np.array(samples)
    fixed_shift = _fixed_target_shift(u, lo, flags)
    with_base = [m for m in u + lo if m.mobile2base is not None and m.fixed is not None]
    if frame == "base" and not with_base:
        raise InputError("the base frame needs a fixed target and fixed2base in the measurements")
    if frame == "base" or (frame == "auto" and bool(with_base)):
        S, mean, cov, Gc = _in_base_frame(S, cov, Gc, with_base)
        frame_name = "base"
    else:
        mean = S.mean(axis=0)
        frame_name = "cam"
    std = S.std(axis=0, ddof=1) if len(S) > 1 else np.full(6, np.nan)
    Sc = _calibration_cov(u + lo) if Gc is not None else None
    cov_cal = None
    if Sc is not None:
        cov_cal = Gc @ Sc @ Gc.T
        cov_cal = 0.5 * (cov_cal + cov_cal.T)
        cov = cov + cov_cal
    return Displacement(
        d=mean[:3],
        r=mean[3:],
        cov=0.5 * (cov + cov.T),
        d_std=std[:3],
        r_std=std[3:],
        n=len(S),
        samples=S,
        frame=frame_name,
        point=q,
        pairing=pairing,
        n_unloaded=len(u),
        n_loaded=len(lo),
        fixed_shift=fixed_shift,
        flags=tuple(flags),
        cov_calibration=cov_cal,
        calibration_jacobian=Gc,
    )


def _calibration_cov(ms: Sequence[ImageMeasurement]) -> np.ndarray | None:
    """The camera's calibration covariance the measurements share (None: unknown in some)."""
    covs = [m.calibration_cov for m in ms]
    if not covs or any(c is None for c in covs):
        return None
    first = covs[0]
    if any(c.shape != first.shape or not np.array_equal(c, first) for c in covs[1:]):
        raise ValueError("the measurements were made with different cameras (calibration covariances differ)")
    return first


@dataclass(frozen=True)
class ImageDisplacements:
    """The displacement of the target in each image of a series, against the same reference.

    Attributes
    ----------
    references : tuple of ImageMeasurement
        The reference (unloaded) images, failed ones included.
    images : tuple of ImageMeasurement
        The images compared with them, in order, failed ones included.
    displacements : tuple of (Displacement or None)
        One per image: its displacement from the mean reference pose, None where the
        image failed.
    summary : Displacement or None
        Mean, standard deviation and n over the measured images (None when none was).
    """

    references: tuple[ImageMeasurement, ...]
    images: tuple[ImageMeasurement, ...]
    displacements: tuple[Displacement | None, ...]
    summary: Displacement | None

    @property
    def n_ok(self) -> int:
        """Images measured, references included."""
        return sum(m.ok for m in self.references) + sum(d is not None for d in self.displacements)

    @property
    def n_images(self) -> int:
        """All images, references included."""
        return len(self.references) + len(self.images)


def displacement_per_image(
    references: Sequence[ImageMeasurement], images: Sequence[ImageMeasurement], point=None
) -> ImageDisplacements:
    """Displacement of the target in each image relative to the mean pose of the references.

    Each measured image is compared alone with the references, then all of them
    together (the summary); both with :func:`compliant_displacement`
    (``pairing="mean-reference"``, the frame chosen as there).

    Parameters
    ----------
    references : sequence of ImageMeasurement
        Reference (unloaded) images, averaged; failed ones are left out.
    images : sequence of ImageMeasurement
        Images after the load (or any moved state); failed ones get no displacement.
    point : array_like, shape (3,), optional
        Point of the mobile target (its frame, mm) whose displacement this is.

    Returns
    -------
    ImageDisplacements

    Raises
    ------
    InputError
        When no reference image was measured.
    """
    refs = list(references)
    if not any(m.ok for m in refs):
        names = ", ".join(m.image for m in refs)
        raise InputError(
            f"no reference image could be measured ({names or 'none given'}); nothing to compare with"
        )
    per = [
        compliant_displacement(refs, [m], point, pairing="mean-reference") if m.ok else None for m in images
    ]
    measured = [m for m, d in zip(images, per, strict=True) if d is not None]
    summary = compliant_displacement(refs, measured, point, pairing="mean-reference") if measured else None
    return ImageDisplacements(tuple(refs), tuple(images), tuple(per), summary)
