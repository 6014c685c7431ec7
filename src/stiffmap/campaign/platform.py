"""A campaign's robot whose platform turns (a ``dim = 6`` legs TOML: a hexapod, a 3-RPS).

A vision campaign moves the platform to positions (x, y, z) with the platform level (roll,
pitch, yaw 0: :func:`level_poses`), hangs its loads at ``loads.point_mm`` (tool frame,
which keeps the base's axes) and measures the platform's 6-DOF displacements. Two things
follow from the robot's 6 x 6 stiffness K6 at the tool point:

- the K the campaign identifies from forces hung at r (:func:`hung_force_stiffness`): the
  tool point moves by ``C_tt F + C_tr (r x F)`` with C = K6^-1, so K = (C_tt + C_tr [r]x)^-1
  (with r = 0 the stiffness a pure force sees, the model's K);
- the model's parameters (leg stiffnesses) fitted to the measured displacements themselves
  (:func:`fit_platform`: translations and rotations under the wrenches (F, r x F), each
  displacement whitened by its full covariance plus an estimated extra noise,
  :func:`~stiffmap.models.fit.fit_deflections6`), as a serial robot's joint stiffnesses are.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..models.base import POSE_DIM, Mechanism, ModelMap
from ..models.fit import ModelFit, fit_deflections6

__all__ = ["is_platform", "level_poses", "hung_force_stiffness", "platform_map", "fit_platform"]


def is_platform(model: Mechanism) -> bool:
    """Whether ``model``'s platform turns (its points are poses of six coordinates)."""
    return int(getattr(model, "dim", 0)) == POSE_DIM


def level_poses(positions) -> np.ndarray:
    """Poses (n, 6) of the positions (n, 3) mm with the platform level (roll, pitch, yaw 0);
    poses (n, 6: a campaign's ``positions.poses``, rad) as they are."""
    P = np.asarray(positions, dtype=np.float64)
    if P.ndim == 2 and P.shape[1] == 6:
        return P.copy()
    P = P.reshape(-1, 3)
    return np.concatenate([P, np.zeros_like(P)], axis=1)


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def hung_force_stiffness(K6, lever_mm) -> np.ndarray:
    """The 3 x 3 stiffness (N/mm) that forces hung at ``lever_mm`` from the tool point see.

    Parameters
    ----------
    K6 : array_like, shape (..., 6, 6)
        At the tool point, base frame (N/mm, N, N*mm/rad blocks).
    lever_mm : array_like, shape (3,)
        Where the loads act, from the tool point, base axes, mm.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``(C_tt + C_tr [r]x)^-1`` with C = K6^-1 (module docstring).
    """
    C = np.linalg.inv(np.asarray(K6, dtype=np.float64))
    return np.linalg.inv(C[..., :3, :3] + C[..., :3, 3:] @ _skew(np.asarray(lever_mm, dtype=np.float64)))


def platform_map(model: Mechanism, positions, lever_mm) -> ModelMap:
    """The model's map at the positions with the platform level, K the K of the loads hung at
    ``lever_mm`` (:func:`hung_force_stiffness`: what the campaign identifies) and ``det``,
    ``eigenvalues``, ``min_principal`` and ``condition`` those of that K; ``K6`` as the model's.

    Parameters
    ----------
    model : Mechanism
        With ``dim = 6``.
    positions : array_like, shape (n, 3), mm
    lever_mm : array_like, shape (3,)
    """
    mm = model.evaluate(level_poses(positions))
    v = mm.valid
    K = np.full_like(mm.K, np.nan)
    if np.any(v):
        K[v] = hung_force_stiffness(mm.K6[v], lever_mm)
    safe = np.where(v[:, None, None], K, np.eye(3))
    lam = np.linalg.eigvalsh(0.5 * (safe + np.swapaxes(safe, 1, 2)))
    nan = np.where(v, 1.0, np.nan)
    return replace(
        mm,
        K=K,
        det=np.linalg.det(safe) * nan,
        eigenvalues=lam * nan[:, None],
        min_principal=lam[:, 0] * nan,
        condition=lam[:, -1] / lam[:, 0] * nan,
    )


def fit_platform(
    model: Mechanism,
    positions,
    position_index,
    forces,
    lever_mm,
    displacements,
    covariances,
    params,
    *,
    correlated: bool = True,
    extra_noise: bool = True,
) -> ModelFit:
    """The model's parameters fitted to measured 6-DOF displacements of the platform.

    Each displacement is weighed by its full covariance (whitened by its Cholesky factor: the
    camera's translation along its line of sight and its rotation across it are strongly
    correlated) plus a shared 6 x 6 extra noise estimated from the residuals (the stated
    covariances are too small in some directions: :func:`~stiffmap.models.fit.fit_deflections6`,
    ``extra_noise``); the result's ``extra_covariance`` holds it, a note gives its std per axis.

    Parameters
    ----------
    model : Mechanism
        With ``dim = 6`` (:func:`is_platform`).
    positions : array_like, shape (n_positions, 3), mm
        The campaign's positions (the platform level at each).
    position_index : array_like of int, shape (m,)
        The position of each measurement.
    forces : array_like, shape (m, 3), N
        The load of each measurement, base axes.
    lever_mm : array_like, shape (3,)
        Where the loads act from the tool point (``loads.point_mm``), mm.
    displacements : array_like, shape (m, 6)
        Measured u (mm) and rotation vector (rad) of the platform at the tool point, base frame.
    covariances : array_like, shape (m, 6, 6)
        Their covariances. With the extra noise the standard errors are those of the inflated
        covariances; without it, the fit's covariance is scaled by its reduced chi-square.
    params : sequence of str
    correlated : bool
        Whiten by the full covariances (default); False: by their diagonals alone (each
        component weighed alone, the fit before issue 30, kept for comparison).
    extra_noise : bool
        Estimate and add the extra noise (default).

    Returns
    -------
    ModelFit
        ``kind = "deflection6"``.
    """
    poses = level_poses(positions)[np.asarray(position_index, dtype=int)]
    F = np.asarray(forces, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(lever_mm, dtype=np.float64)
    W = np.concatenate([F, np.cross(r, F)], axis=1)
    cov = np.asarray(covariances, dtype=np.float64)
    if not correlated:
        cov = np.einsum("mii,ij->mij", cov, np.eye(6))
    return fit_deflections6(model, poses, W, displacements, params=params, cov=cov, extra_noise=extra_noise)
