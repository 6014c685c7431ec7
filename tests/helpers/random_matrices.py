"""Random draws of the matrices the round-trip tests feed the library: rotations, SPD matrices."""

from __future__ import annotations

import numpy as np


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix, shape (3, 3) (from a random unit quaternion)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_spd(rng: np.random.Generator, m: int = 3, lo: float = 0.5, hi: float = 20.0) -> np.ndarray:
    """A random symmetric positive-definite matrix, shape (m, m), with eigenvalues in [lo, hi]."""
    Q, _ = np.linalg.qr(rng.normal(size=(m, m)))
    return Q @ np.diag(rng.uniform(lo, hi, size=m)) @ Q.T
