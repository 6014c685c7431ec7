"""Units at the input/output boundary.

Inside stiffmap everything is in the consistent N-mm-MPa system: length mm,
force N, moment N*mm, angle rad, translational stiffness N/mm, rotational
stiffness N*mm/rad, Young's modulus MPa. Masses in kg, kgf, micrometres and
degrees are converted here, once, where data enter or leave.
"""

from __future__ import annotations

import math

__all__ = [
    "G_STANDARD",
    "G_REFERENCE_PAPER",
    "newton_from_kg",
    "newton_from_kgf",
    "mm_from_um",
    "um_from_mm",
    "rad_from_deg",
    "deg_from_rad",
]

#: Standard gravity, m/s^2 (ISO 80000-3); the campaign default.
G_STANDARD = 9.80665
#: The gravity the reference vision study used (its forces 4.905, 1.962, 0.981 N).
G_REFERENCE_PAPER = 9.81


def newton_from_kg(mass_kg: float, g: float = G_STANDARD) -> float:
    """Weight in N of a mass in kg under gravity ``g`` (m/s^2)."""
    if not math.isfinite(mass_kg):
        raise ValueError(f"mass must be finite, got {mass_kg!r} kg")
    if not (math.isfinite(g) and g > 0):
        raise ValueError(f"g must be a positive number of m/s^2, got {g!r}")
    return float(mass_kg) * float(g)


def newton_from_kgf(force_kgf: float, g: float = G_STANDARD) -> float:
    """Force in N from kilogram-force (1 kgf = g N; the milling study used g = 9.81)."""
    return newton_from_kg(force_kgf, g)


def mm_from_um(x):
    """Millimetres from micrometres (scalars or arrays)."""
    return x * 1e-3


def um_from_mm(x):
    """Micrometres from millimetres (scalars or arrays)."""
    return x * 1e3


def rad_from_deg(x):
    """Radians from degrees (scalars or arrays)."""
    return x * (math.pi / 180.0)


def deg_from_rad(x):
    """Degrees from radians (scalars or arrays)."""
    return x * (180.0 / math.pi)
