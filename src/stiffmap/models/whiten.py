"""Whitening of measured displacements by their covariances: the one home of the idea.

A displacement d (mm, and rad for a 6-DOF one) measured with covariance ``C = L L^T`` (its
Cholesky factor L) is whitened by ``L^-1``: ``L^-1 r`` of a residual r has the identity as
covariance, so least squares on whitened residuals minimises ``sum_m r_m^T C_m^-1 r_m`` with
the correlations between a displacement's components (a camera's translation along its
line of sight and its rotation about an axis across it, for instance) taken into account.
The joint fit (:mod:`~stiffmap.models.joint_fit`) and the 6-DOF deflection fit
(:func:`~stiffmap.models.fit.fit_deflections6`) both whiten by :func:`whitener`.

Bad input raises :class:`~stiffmap.errors.InputError` naming the argument (``cov``) and the
row.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["whitener", "as_float", "first_bad_row", "check_finite", "SYMMETRY_RTOL"]

#: Relative tolerance of a covariance's symmetry.
SYMMETRY_RTOL = 1e-9


def as_float(x, name: str) -> np.ndarray:
    """``x`` as float64, or an InputError naming ``name``."""
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: expected numbers, got {type(x).__name__} ({exc})") from None


def first_bad_row(ok_rows: np.ndarray) -> int:
    """The first row that is not ok."""
    return int(np.flatnonzero(~ok_rows)[0])


def check_finite(a: np.ndarray, name: str, unit: str) -> None:
    """An InputError naming ``name`` and the first row with NaN or infinite values."""
    ok = np.all(np.isfinite(a.reshape(a.shape[0], -1)), axis=1)
    if not np.all(ok):
        i = first_bad_row(ok)
        raise InputError(f"{name}: row {i} contains NaN or infinite values; expected finite {unit}")


def _from_std(C: np.ndarray, d: int) -> np.ndarray:
    ok = np.all(np.isfinite(C) & (C > 0), axis=1)
    if not np.all(ok):
        i = first_bad_row(ok)
        raise InputError(
            f"cov: row {i} has standard deviations {C[i].tolist()}; expected positive finite numbers "
            "(mm, rad)"
        )
    Linv = np.zeros((C.shape[0], d, d))
    Linv[:, np.arange(d), np.arange(d)] = 1.0 / C
    return Linv


def whitener(cov, M: int, d: int) -> np.ndarray:
    """``L^-1`` of each row's covariance ``L L^T``.

    Parameters
    ----------
    cov : array_like, shape (M, d, d) or (M, d), or None
        A covariance per displacement (mm^2, mm*rad, rad^2; symmetric positive definite), or
        standard deviations (a diagonal covariance); None: unit weights.
    M, d : int
        The number of displacements and their size (3 or 6).

    Returns
    -------
    ndarray, shape (M, d, d)
        Lower triangular; the identity when ``cov`` is None.

    Raises
    ------
    InputError
        A wrong shape, non-finite values, a covariance not symmetric or not positive
        definite (the row named).
    """
    if cov is None:
        return np.broadcast_to(np.eye(d), (M, d, d)).copy()
    C = as_float(cov, "cov")
    if C.shape == (M, d):
        return _from_std(C, d)
    if C.shape != (M, d, d):
        raise InputError(
            f"cov: expected shape ({M}, {d}, {d}) (a covariance per displacement) or ({M}, {d}) "
            f"(standard deviations), got {C.shape}"
        )
    check_finite(C, "cov", "mm^2, mm*rad and rad^2")
    scale = np.max(np.abs(np.diagonal(C, axis1=1, axis2=2)), axis=1)
    asym = np.max(np.abs(C - np.swapaxes(C, 1, 2)), axis=(1, 2))
    ok = asym <= SYMMETRY_RTOL * scale
    if not np.all(ok):
        i = first_bad_row(ok)
        raise InputError(
            f"cov: row {i} is not symmetric (largest asymmetry {asym[i]:.3g}); expected a covariance"
        )
    C = 0.5 * (C + np.swapaxes(C, 1, 2))
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(C)[:, 0]
        i = first_bad_row(eig > 0)
        raise InputError(
            f"cov: row {i} is not positive definite (smallest eigenvalue {eig[i]:.3g}); expected the "
            "covariance of a measured displacement"
        ) from None
    I = np.broadcast_to(np.eye(d), C.shape)
    return np.linalg.solve(L, I)
