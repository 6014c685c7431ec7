"""Validation against known stage displacements (the reference study's X-table test).

A target on a micrometer stage is photographed at its start position and after
known displacements (the reference study: 2, 5, 10 and 20 mm, ten repeats each,
its Table I). :func:`validate_stage` compares the measured displacement of each
image, relative to the mean start pose, with the nominal one: the norm of the
displacement vector (as the reference study reports it) and its component along
the stage axis fitted to all images (the principal direction of the measured
displacements). Per nominal step: mean, standard deviation, n and the error
mean - nominal.

:func:`validate_stage_series` takes the images of a stage manifest in its order
(:func:`stiffmap.vision.files.read_stage_manifest`: nominal 0 is the start position).

The result is data; :func:`stiffmap.report.validation.stage_plot_svg` draws it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry import displacement_from_poses
from .displacement import mean_pose
from .sequence import ImageMeasurement

__all__ = ["StageStep", "StageValidation", "validate_stage", "validate_stage_series", "REFERENCE_TABLE_I"]

#: The reference study's Table I: nominal (mm) -> (mean, std) of the estimated displacement, mm.
REFERENCE_TABLE_I = {2.0: (1.99, 0.28), 5.0: (4.97, 0.27), 10.0: (9.75, 0.24), 20.0: (20.01, 0.21)}


@dataclass(frozen=True)
class StageStep:
    """Measured displacements at one nominal stage displacement.

    Attributes
    ----------
    nominal_mm : float
    norm_mm : ndarray, shape (n,)
        Norm of each image's displacement vector, mm.
    along_mm : ndarray, shape (n,)
        Component along the fitted stage axis, mm.
    images : tuple of str
    """

    nominal_mm: float
    norm_mm: np.ndarray
    along_mm: np.ndarray
    images: tuple[str, ...]

    @property
    def n(self) -> int:
        return int(self.norm_mm.size)

    @property
    def mean_mm(self) -> float:
        """Mean of the norms, mm."""
        return float(self.norm_mm.mean())

    @property
    def std_mm(self) -> float:
        """Standard deviation of the norms (n - 1), mm; NaN for one image."""
        return float(self.norm_mm.std(ddof=1)) if self.n > 1 else float("nan")

    @property
    def error_mm(self) -> float:
        """mean - nominal, mm."""
        return self.mean_mm - self.nominal_mm

    @property
    def along_mean_mm(self) -> float:
        return float(self.along_mm.mean())

    @property
    def along_std_mm(self) -> float:
        return float(self.along_mm.std(ddof=1)) if self.n > 1 else float("nan")


@dataclass(frozen=True)
class StageValidation:
    """Result of :func:`validate_stage`.

    Attributes
    ----------
    steps : tuple of StageStep
        By increasing nominal displacement.
    axis : ndarray, shape (3,)
        Unit vector of the fitted stage axis, camera frame.
    n_reference : int
        Start-position images averaged into the reference pose.
    failed : tuple of (str, str)
        Images left out and why.
    """

    steps: tuple[StageStep, ...]
    axis: np.ndarray
    n_reference: int
    failed: tuple[tuple[str, str], ...] = ()

    @property
    def rms_error_mm(self) -> float:
        """RMS over all images of (norm - nominal), mm."""
        e = np.concatenate([s.norm_mm - s.nominal_mm for s in self.steps])
        return float(np.sqrt(np.mean(e**2)))

    @property
    def max_std_mm(self) -> float:
        """Largest per-step standard deviation, mm."""
        v = [s.std_mm for s in self.steps if s.n > 1]
        return float(max(v)) if v else float("nan")


def _named(failure: tuple[str, str]) -> str:
    """Why an image gave no pose, naming it once (an image's error names it already)."""
    image, why = failure
    return why if why.startswith(f"{image}:") else f"{image}: {why}"


def validate_stage(
    reference: Sequence[ImageMeasurement],
    moved: Sequence[tuple[float, ImageMeasurement]],
    point=None,
) -> StageValidation:
    """Compare measured target displacements with known stage displacements.

    Parameters
    ----------
    reference : sequence of ImageMeasurement
        Images at the stage's start position (averaged).
    moved : sequence of (nominal_mm, ImageMeasurement)
        Images after a known displacement, mm.
    point : array_like, shape (3,), optional
        Point of the target (its frame, mm) whose displacement is compared;
        default the target's origin (a pure translation stage moves every point alike).

    Returns
    -------
    StageValidation

    Raises
    ------
    InputError
        No usable reference image, or no usable moved image.
    """
    failed = [(m.image, m.error or "no pose") for m in reference if not m.ok or m.mobile is None]
    ref = [m for m in reference if m.ok and m.mobile is not None]
    if not ref:
        raise InputError("no usable reference image (nominal 0): " + "; ".join(map(_named, failed)))
    good = []
    for nom, m in moved:
        nom = float(nom)
        if not np.isfinite(nom) or nom < 0:
            raise ValueError(f"nominal displacements must be finite and >= 0 mm, got {nom}")
        if m.ok and m.mobile is not None:
            good.append((nom, m))
        else:
            failed.append((m.image, m.error or "no pose"))
    if not good:
        raise InputError("no usable image of a moved stage: " + "; ".join(map(_named, failed)))
    T0 = mean_pose([m.mobile2cam for m in ref])
    q = np.zeros(3) if point is None else np.asarray(point, dtype=np.float64).reshape(3)
    D = np.array([displacement_from_poses(T0, m.mobile2cam, q)[:3] for _, m in good])
    noms = np.array([n for n, _ in good])
    # Stage axis: principal direction of the displacements, signed along growing nominal.
    _, _, Vt = np.linalg.svd(D, full_matrices=False)
    axis = Vt[0]
    if np.sum((D @ axis) * noms) < 0:
        axis = -axis
    steps = []
    for nom in sorted(set(noms.tolist())):
        sel = noms == nom
        steps.append(
            StageStep(
                nominal_mm=nom,
                norm_mm=np.linalg.norm(D[sel], axis=1),
                along_mm=D[sel] @ axis,
                images=tuple(m.image for (n, m) in good if n == nom),
            )
        )
    return StageValidation(steps=tuple(steps), axis=axis, n_reference=len(ref), failed=tuple(failed))


def validate_stage_series(
    measurements: Sequence[ImageMeasurement], nominals_mm: Sequence[float], point=None
) -> StageValidation:
    """:func:`validate_stage` of a stage manifest's images: those at nominal 0 mm are the references.

    Parameters
    ----------
    measurements : sequence of ImageMeasurement
        One per image of the manifest, in its order.
    nominals_mm : sequence of float
        The stage displacement of each image, mm (0: the start position).
    point : array_like, shape (3,), optional
        As :func:`validate_stage`.

    Raises
    ------
    InputError
        As :func:`validate_stage`.
    """
    pairs = list(zip(measurements, nominals_mm, strict=True))
    reference = [m for m, n in pairs if n == 0]
    moved = [(n, m) for m, n in pairs if n != 0]
    return validate_stage(reference, moved, point)
