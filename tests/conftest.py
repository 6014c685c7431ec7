"""Shared test fixtures and paths."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
#: Real data nobody on this project made (see ../shared/data/*/README.md).
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix."""
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
    """A random symmetric positive-definite matrix with eigenvalues in [lo, hi]."""
    Q, _ = np.linalg.qr(rng.normal(size=(m, m)))
    return Q @ np.diag(rng.uniform(lo, hi, size=m)) @ Q.T
