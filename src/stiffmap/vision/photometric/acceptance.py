"""When a photometric fit is accepted, and the covariance of its pose.

A converged Gauss-Newton fit (:mod:`~stiffmap.vision.photometric.solver`) is refused,
with a :class:`~stiffmap.vision.photometric.pixels.PhotometricError` saying why (the
corner pose then stays), when its pose is undetermined (singular normal matrix), its
blur is implausible (outside 0.2-10 px), too many pixels are down-weighted as outliers
(an obstructed board, another pattern), or its contrast is not positive or fades out
over part of the board (hidden or very unevenly lit).

Covariance: cov = s^2 (J^T W J)^-1, pose block (t, r), s^2 = sum w r^2 / (N - p)
with r the residuals in units of the modelled noise sigma. Pixels' noise is
taken as independent (true of sensor noise, not of JPEG artefacts or of a model
error correlated along an edge, which make the covariance optimistic).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import poly
from .pixels import PhotometricError, PhotometricSetup
from .solver import Solution, wsum

__all__ = ["AcceptedFit", "accept_fit", "check_blur", "MIN_CONTRAST_RATIO", "BLUR_RANGE_PX"]

#: Least contrast (1st percentile over the pixels) relative to its median: below, part of the
#: board is hidden (the contrast polynomial fades out there) or lit far too unevenly.
MIN_CONTRAST_RATIO = 0.3
#: Plausible effective blur sigma, px.
BLUR_RANGE_PX = (0.2, 10.0)


@dataclass(frozen=True)
class AcceptedFit:
    """The pose covariance and quality of an accepted fit.

    Attributes
    ----------
    cov : ndarray, shape (6, 6)
        Covariance of the pose (t mm, r rad), symmetrised.
    s2 : float
        sum w r^2 / (N - p): the residuals' variance in units of the modelled noise.
    outlier_fraction : float
        Fraction of the pixels down-weighted by the Huber weights.
    condition : float
        Condition number of the pose's information matrix, rotations expressed as
        lateral motions at the board's distance (as for the corner pose).
    """

    cov: np.ndarray
    s2: float
    outlier_fraction: float
    condition: float


def check_blur(blur_px: np.ndarray) -> None:
    """Refuse an implausible fitted blur (its mean over the edges' directions, ``blur_px[0]``)."""
    lo, hi = BLUR_RANGE_PX
    if not lo <= blur_px[0] <= hi:
        raise PhotometricError(f"implausible blur sigma {blur_px[0]:.2f} px (expected {lo:g}-{hi:g} px)")


def accept_fit(
    sol: Solution, setup: PhotometricSetup, max_iter: int, max_outlier_fraction: float
) -> AcceptedFit:
    """Check a fit's solution (module docstring) and compute its pose covariance.

    Raises
    ------
    PhotometricError
        Not converged, undetermined pose, implausible blur, too many outliers, or a
        contrast that is not positive or fades out over part of the board.
    """
    st = sol.state
    if not sol.converged:
        raise PhotometricError(f"did not converge in {max_iter} iterations")
    e, var, hw, A = sol.e, sol.var, sol.hw, sol.A
    # s^2 with the noise variance of the normal matrix A (a warm fit's A may be a previous
    # image's linearisation, weighted by that image's noise model: a scale error in the weights
    # then cancels in s^2 A^-1) and this image's Huber weights, as the fit's last step.
    w = hw / (sol.lin.evaluator.var_lin if sol.lin is not None else var)
    outliers = float(np.mean(hw < 1.0))
    p, N = A.shape[0], e.size
    s2 = wsum(w, e) / max(N - p, 1)
    try:
        cov_all = s2 * np.linalg.inv(A)
    except np.linalg.LinAlgError:
        raise PhotometricError("the pose is undetermined (singular normal matrix)") from None
    cov = 0.5 * (cov_all[:6, :6] + cov_all[:6, :6].T)
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        raise PhotometricError("the pose is undetermined (singular normal matrix)")
    check_blur(st.sig)
    if outliers > max_outlier_fraction:
        raise PhotometricError(
            f"{100 * outliers:.0f} % of the pixels do not fit the model (more than "
            f"{100 * max_outlier_fraction:.0f} %: obstructed board or another pattern)"
        )
    # A polynomial of degree <= 2 over the board: every 16th pixel is plenty (its 1st percentile
    # and median, the order statistics of one partition).
    bvals = poly(st.b, setup.basis[:, ::16])
    k_low, k_mid = int(0.01 * (bvals.size - 1)), (bvals.size - 1) // 2
    part = np.partition(bvals, (k_low, k_mid))
    low, contrast = float(part[k_low]), float(part[k_mid])
    if contrast <= 0:
        raise PhotometricError(
            f"the fitted contrast is not positive ({contrast:.1f} DN): inverted or wrong board"
        )
    if low < MIN_CONTRAST_RATIO * contrast:
        raise PhotometricError(
            f"the fitted contrast falls to {100 * low / contrast:.0f} % of its median over part of the "
            "board (obstructed or very unevenly lit board?)"
        )
    # Condition with rotations expressed as lateral motions at the board's distance (as pose.py).
    info = np.linalg.inv(cov_all[:6, :6] / s2)
    Ds = np.diag([1.0, 1.0, 1.0] + [1.0 / max(abs(st.T[2, 3]), 1.0)] * 3)
    condition = float(np.linalg.cond(Ds @ info @ Ds))
    return AcceptedFit(cov=cov, s2=s2, outlier_fraction=outliers, condition=condition)
