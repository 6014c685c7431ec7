"""Checks of the mechanism models: random reachable poses away from singularities, Jacobian vs FD."""

from __future__ import annotations

import numpy as np

from helpers.finite_difference import central_jacobian


def random_reachable_poses(
    model, rng: np.random.Generator, n: int, lo, hi, margin: float = 0.05
) -> np.ndarray:
    """``n`` uniformly drawn poses in the box [lo, hi] (mm) that the model evaluates, with both
    singularity measures above ``margin`` (so finite differences stay meaningful)."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    out = []
    while sum(len(o) for o in out) < n:
        P = rng.uniform(lo, hi, size=(4 * n, lo.size))
        s, p = model.singularity_measures(P)
        ok = model.evaluate(P).valid & (s > margin) & (p > margin)
        out.append(P[ok])
    return np.concatenate(out)[:n]


def assert_jacobian_matches_fd(model, points: np.ndarray, h: float, atol: float) -> np.ndarray:
    """Check ``model.jacobian`` (dq/dx) against central differences of its inverse kinematics.

    Each pose's matrices are compared relative to the analytic one's Frobenius norm, to
    ``atol`` (dimensionless); ``h`` is the step in mm. Returns the analytic J, shape (N, n_joints, dim).
    """
    J = model.jacobian(points)
    Jn = central_jacobian(lambda x: model.inverse_kinematics(x).q, points, h)
    scale = np.linalg.norm(J, axis=(1, 2))[:, None, None]
    np.testing.assert_allclose(J / scale, Jn / scale, rtol=0, atol=atol)
    return J
