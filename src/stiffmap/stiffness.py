"""Properties of a stiffness matrix: conversions, indices, directional stiffness.

The vocabulary every layer that holds a stiffness matrix shares (identification,
models, the report), in NumPy alone. Shapes: 2x2 (planar), 3x3 (N/mm) or 6x6
(N/mm, N/rad, N*mm/mm, N*mm/rad blocks); see ``docs/identification.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DISPLACEMENT_FLOOR_MM",
    "LARGE_DISPLACEMENT_MM",
    "MAX_DISPLACEMENT_MM",
    "MAX_POSITION_MM",
    "MAX_ROTATION_RAD",
    "MAX_STIFFNESS_N_PER_MM",
    "StiffnessIndices",
    "stiffness_indices",
    "directional_stiffness",
    "compliance_from_stiffness",
    "stiffness_from_compliance",
    "check_stiffness_matrix",
]


#: Plausibility limits of measured quantities at the input boundary: far beyond any
#: stiffness test, so that only a broken file (or a wrong unit) meets them. A compliant
#: displacement of 1 km, a rotation of a full turn, a stiffness of 1e12 N/mm, a robot
#: position 1 km from its base (forces: :data:`stiffmap.loads.MAX_FORCE_N`).
MAX_DISPLACEMENT_MM = 1e6
MAX_POSITION_MM = 1e6
MAX_ROTATION_RAD = 2 * np.pi
MAX_STIFFNESS_N_PER_MM = 1e12
#: Displacements that all stay below this (mm) measured nothing: a picometre, below the
#: resolution of any displacement sensor or camera.
DISPLACEMENT_FLOOR_MM = 1e-9
#: A compliant displacement beyond this (mm) is large for a stiffness model, which holds for small
#: displacements about a configuration: a robot's deflection under a load it is meant for stays
#: well below (the reference studies' 0.1-1.5 mm; the test-bed measures 0.5-4 mm best).
LARGE_DISPLACEMENT_MM = 4.0


def compliance_from_stiffness(K) -> np.ndarray:
    """Compliance C = K^-1 (mm/N for 3x3)."""
    return np.linalg.inv(np.asarray(K, dtype=np.float64))


def stiffness_from_compliance(C) -> np.ndarray:
    """Stiffness K = C^-1 (N/mm for 3x3)."""
    return np.linalg.inv(np.asarray(C, dtype=np.float64))


@dataclass(frozen=True)
class StiffnessIndices:
    """Scalar and directional summaries of a stiffness matrix.

    For a 6x6 matrix the principal values, directions and condition number are
    given for the translational block ``K[:3, :3]`` (N/mm) and, separately, for
    the rotational block ``K[3:, 3:]`` (N*mm/rad); the blocks have different
    units, so indices of the whole 6x6 matrix would mix them.
    """

    det: float
    eigenvalues: np.ndarray  # principal stiffnesses of the symmetric part, ascending
    directions: np.ndarray  # columns are the principal directions
    min_principal: float
    condition: float  # 2-norm condition number of the (block) matrix
    asymmetry: float  # ||K - K^T||_F / ||K||_F
    rotational_eigenvalues: np.ndarray | None = None
    rotational_directions: np.ndarray | None = None
    rotational_condition: float | None = None


def check_stiffness_matrix(K, name: str = "K") -> np.ndarray:
    """``K`` as a finite float64 2x2, 3x3 or 6x6 array, or a ValueError naming it."""
    K = np.asarray(K, dtype=np.float64)
    if K.shape not in ((3, 3), (6, 6), (2, 2)):
        raise ValueError(f"{name} must be 2x2, 3x3 or 6x6, got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return K


def _principal(Kb: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    S = 0.5 * (Kb + Kb.T)
    w, V = np.linalg.eigh(S)
    s = np.linalg.svd(Kb, compute_uv=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    return w, V, cond


def stiffness_indices(K) -> StiffnessIndices:
    """Indices of a stiffness matrix.

    Parameters
    ----------
    K : array_like, shape (2, 2), (3, 3) or (6, 6)
        Stiffness, N/mm (translational block).

    Returns
    -------
    StiffnessIndices
        ``det`` is det(K) of the whole matrix (the reference paper's map value;
        (N/mm)^3 for 3x3). Principal stiffnesses are the eigenvalues of the
        symmetric part (K + K^T)/2.
    """
    K = check_stiffness_matrix(K)
    m = K.shape[0]
    Kt = K[:3, :3] if m == 6 else K
    w, V, cond = _principal(Kt)
    nK = np.linalg.norm(K)
    asym = float(np.linalg.norm(K - K.T) / nK) if nK > 0 else 0.0
    rot = (None, None, None)
    if m == 6:
        rot = _principal(K[3:, 3:])
    return StiffnessIndices(
        det=float(np.linalg.det(K)),
        eigenvalues=w,
        directions=V,
        min_principal=float(w[0]),
        condition=cond,
        asymmetry=asym,
        rotational_eigenvalues=rot[0],
        rotational_directions=rot[1],
        rotational_condition=rot[2],
    )


def directional_stiffness(K, u) -> float:
    """Stiffness felt along a unit direction u: 1 / (u^T K^-1 u).

    A force F u applied to the robot moves it by K^-1 F u; the component of
    that displacement along u is F u^T K^-1 u, so this is the force over the
    displacement along the force's own direction (N/mm for 3x3).

    Parameters
    ----------
    K : array_like, shape (m, m)
    u : array_like, shape (m,)
        Direction (normalised here).
    """
    K = check_stiffness_matrix(K)
    u = np.asarray(u, dtype=np.float64)
    if u.shape != (K.shape[0],):
        raise ValueError(f"direction must have shape ({K.shape[0]},), got {u.shape}")
    n = np.linalg.norm(u)
    if not np.isfinite(n) or n == 0:
        raise ValueError("direction must be a non-zero finite vector")
    u = u / n
    return float(1.0 / (u @ np.linalg.solve(K, u)))
