"""Validation against known stage displacements (the reference study's X-table test).

A target on a micrometer stage is photographed at its start position and after
known displacements (the reference study: 2, 5, 10 and 20 mm, ten repeats each,
its Table I). :func:`validate_stage` compares the measured displacement of each
image, relative to the mean start pose, with the nominal one: the norm of the
displacement vector (as the reference study reports it) and its component along
the stage axis fitted to all images (the principal direction of the measured
displacements). Per nominal step: mean, standard deviation, n and the error
mean - nominal.

:func:`stage_plot_svg` draws measured against nominal and the error per step
(mean +/- one standard deviation) as a self-contained SVG.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from html import escape

import numpy as np

from ..errors import InputError
from ..geometry import displacement_from_poses
from .displacement import mean_pose
from .sequence import ImageMeasurement

__all__ = ["StageStep", "StageValidation", "validate_stage", "stage_plot_svg", "REFERENCE_TABLE_I"]

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
        raise InputError(
            "no usable reference image (nominal 0): " + "; ".join(f"{a}: {b}" for a, b in failed)
        )
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
        raise InputError("no usable image of a moved stage: " + "; ".join(f"{a}: {b}" for a, b in failed))
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


def stage_plot_svg(result: StageValidation, title: str = "Stage validation") -> str:
    """SVG of measured vs nominal displacement and of the error per step (mean +/- 1 std)."""
    W, H = 760, 340
    pw, ph = 300, 230
    panels = [(70, 50), (440, 50)]
    steps = result.steps
    noms = np.array([s.nominal_mm for s in steps])
    means = np.array([s.mean_mm for s in steps])
    stds = np.nan_to_num(np.array([s.std_mm for s in steps]))
    errs = means - noms
    xmax = max(float(noms.max()), 1e-6) * 1.08
    ymax = max(float((means + stds).max()), xmax) * 1.02
    emax = max(float(np.max(np.abs(errs) + stds)), 1e-6) * 1.3
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" '
        'font-size="12">',
        f'<text x="{W / 2}" y="22" text-anchor="middle" font-size="15">{escape(title)}</text>',
    ]

    def panel(x0, y0, ylo, yhi, ylabel, pts, line):
        sx = lambda v: x0 + pw * v / xmax  # noqa: E731
        sy = lambda v: y0 + ph * (1 - (v - ylo) / (yhi - ylo))  # noqa: E731
        out.append(f'<rect x="{x0}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>')
        for k in range(5):
            xv = xmax * k / 4
            yv = ylo + (yhi - ylo) * k / 4
            out.append(
                f'<text x="{sx(xv):.1f}" y="{y0 + ph + 16}" text-anchor="middle">{xv:.3g}</text>'
                f'<text x="{x0 - 6}" y="{sy(yv) + 4:.1f}" text-anchor="end">{yv:.3g}</text>'
            )
        out.append(
            f'<text x="{x0 + pw / 2}" y="{y0 + ph + 34}" text-anchor="middle">'
            "nominal displacement (mm)</text>"
            f'<text x="{x0 - 52}" y="{y0 + ph / 2}" text-anchor="middle" '
            f'transform="rotate(-90 {x0 - 52} {y0 + ph / 2})">{escape(ylabel)}</text>'
        )
        a, b = line
        out.append(
            f'<line x1="{sx(0):.1f}" y1="{sy(a):.1f}" x2="{sx(xmax):.1f}" y2="{sy(b):.1f}" '
            'stroke="#999" stroke-dasharray="4 3"/>'
        )
        for xv, yv, sv in pts:
            out.append(
                f'<line x1="{sx(xv):.1f}" y1="{sy(yv - sv):.1f}" x2="{sx(xv):.1f}" y2="{sy(yv + sv):.1f}" '
                'stroke="#1f5fbf"/>'
                f'<circle cx="{sx(xv):.1f}" cy="{sy(yv):.1f}" r="3.5" fill="#1f5fbf"/>'
            )

    panel(*panels[0], 0.0, ymax, "measured (mm)", list(zip(noms, means, stds, strict=True)), (0.0, xmax))
    panel(
        *panels[1], -emax, emax, "measured - nominal (mm)", list(zip(noms, errs, stds, strict=True)), (0, 0)
    )
    out.append("</svg>")
    return "\n".join(out) + "\n"
