"""A 6-UPS hexapod of our own (not the shipped hexapod.toml), as a user would bring it to
``stiffmap simulate --robot my_hexapod.toml``, and its closed-form K6.

Base joints on a 220 mm circle, platform joints on a 120 mm circle, at the angles below
(degrees; leg i joins base angle i to platform angle i: the legs cross as a Gough-Stewart
platform's), home height 260 mm, legs of six different stiffnesses (N/mm). Used by
``tests/test_simulate_own_legs.py`` and ``benchmarks/bench_own_legs.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stiffmap.models.legs6 import ups_legs
from stiffmap.models.legs_file import legs_text

BASE_DEG = (260.0, 280.0, 20.0, 40.0, 140.0, 160.0)
PLATFORM_DEG = (220.0, 320.0, 340.0, 80.0, 100.0, 200.0)
OWN_K = (350.0, 420.0, 500.0, 380.0, 460.0, 540.0)  # N/mm
NAMES = tuple(f"k_leg{i}" for i in range(1, 7))
HOME_MM = (0.0, 0.0, 260.0)


def circle(radius: float, degrees) -> np.ndarray:
    """Points (n, 3) mm on a circle of ``radius`` in the plane z = 0, at ``degrees``."""
    a = np.radians(degrees)
    return np.c_[radius * np.cos(a), radius * np.sin(a), np.zeros(len(a))]


B_MM, A_MM = circle(220.0, BASE_DEG), circle(120.0, PLATFORM_DEG)


def write_own_hexapod(path: Path, *, stroke_mm=None) -> Path:
    """The hexapod as a legs TOML named ``my_hexapod`` (``stroke_mm``: the legs' limits, mm)."""
    legs = ups_legs(B_MM, A_MM, HOME_MM, NAMES, stroke_mm=stroke_mm)
    path.write_text(legs_text("my_hexapod", 6, dict(zip(NAMES, OWN_K, strict=True)), legs, 1e-3))
    return path


def gosselin_k6(p, k=OWN_K, R=None) -> np.ndarray:
    """K6 = sum k_i a_i a_i^T, a_i = (n_i, r_i x n_i): legs that are springs along their line, the
    platform at p turned by R (r_i = R attach_i; n_i from the base joint to the platform joint)."""
    R = np.eye(3) if R is None else R
    K6 = np.zeros((6, 6))
    for b, a, ki in zip(B_MM, A_MM, k, strict=True):
        r = R @ a
        n = np.asarray(p) + r - b
        n /= np.linalg.norm(n)
        a6 = np.r_[n, np.cross(r, n)]
        K6 += ki * np.outer(a6, a6)
    return K6
