"""Helpers shared by the HTML (plotly) and PNG (matplotlib) figures: grouping, grids, sizes, labels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .data import ReportData

#: Units shown with each mapped quantity.
QUANTITIES = {
    "min_principal": ("smallest principal stiffness", "N/mm"),
    "det": ("det K", "(N/mm)³"),
}
#: Largest marker diameter of the 3D map (px in HTML, pt in PNG).
MAX_DIAMETER = 36.0
#: Markers are never drawn smaller than this, so that soft positions stay visible.
MIN_DIAMETER = 3.0


def plane_values(z: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Distinct z values (mm), upper plane first."""
    zs: list[float] = []
    for v in np.sort(np.asarray(z, dtype=np.float64))[::-1]:
        if not zs or abs(zs[-1] - v) > tol * max(1.0, abs(v)):
            zs.append(float(v))
    return np.array(zs)


def on_plane(z: np.ndarray, plane: float, tol: float = 1e-6) -> np.ndarray:
    """Mask of the values of ``z`` on ``plane``."""
    return np.abs(np.asarray(z) - plane) <= tol * max(1.0, abs(plane))


def as_grid(xy: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Points that fill a rectangular grid, as (xs, ys, Z[ny, nx]); None when they do not.

    Parameters
    ----------
    xy : ndarray, shape (g, 2)
    values : ndarray, shape (g,)
    """
    xs = np.unique(np.round(xy[:, 0], 9))
    ys = np.unique(np.round(xy[:, 1], 9))
    if len(xs) < 2 or len(ys) < 2 or len(xs) * len(ys) != len(xy):
        return None
    ix = np.searchsorted(xs, np.round(xy[:, 0], 9))
    iy = np.searchsorted(ys, np.round(xy[:, 1], 9))
    Z = np.full((len(ys), len(xs)), np.nan)
    seen = np.zeros(Z.shape, dtype=bool)
    for a, b, v in zip(iy, ix, values, strict=True):
        if seen[a, b]:
            return None
        seen[a, b] = True
        Z[a, b] = v
    return xs, ys, Z


def det_diameters(det: np.ndarray) -> np.ndarray:
    """Marker diameters proportional to det K (the reference study's Fig. 12).

    The largest positive det gets :data:`MAX_DIAMETER`; every diameter is
    floored at :data:`MIN_DIAMETER`. NaN or non-positive det gives NaN (those
    are drawn with their own symbol).
    """
    det = np.asarray(det, dtype=np.float64)
    pos = np.isfinite(det) & (det > 0)
    out = np.full(det.shape, np.nan)
    if pos.any():
        out[pos] = np.maximum(MAX_DIAMETER * det[pos] / det[pos].max(), MIN_DIAMETER)
    return out


def position_labels(data: ReportData) -> list[str]:
    """``P1 (x, y, z)`` for each measured position."""
    m = data.measured
    if m is None:
        return []
    return [f"P{i + 1} ({x:g}, {y:g}, {z:g})" for i, (x, y, z) in enumerate(np.round(m.positions, 1))]


def fmt(x: float, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; ``n/a`` for NaN."""
    x = float(x)
    if not np.isfinite(x):
        return "n/a"
    return f"{x:.{digits}g}"


def fmt_pm(x: float, s: float, digits: int = 4) -> str:
    return fmt(x, digits) if not np.isfinite(s) else f"{fmt(x, digits)} ± {fmt(s, 2)}"


def symmetric_range(*arrays: np.ndarray) -> float:
    """Largest |value| over finite entries (1 when none), for a diverging colour scale."""
    v = [np.abs(a[np.isfinite(a)]) for a in arrays if a is not None]
    v = [x for x in v if x.size]
    return float(max(x.max() for x in v)) if v and max(x.max() for x in v) > 0 else 1.0


def finite_range(*arrays: np.ndarray | None) -> tuple[float, float]:
    """(min, max) over the finite entries of the arrays; (0, 1) when none."""
    v = [np.asarray(a)[np.isfinite(a)] for a in arrays if a is not None]
    v = [x for x in v if x.size]
    if not v:
        return 0.0, 1.0
    lo = float(min(x.min() for x in v))
    hi = float(max(x.max() for x in v))
    return (lo, hi) if hi > lo else (lo - 0.5 * abs(lo) - 0.5, hi + 0.5 * abs(hi) + 0.5)


@dataclass(frozen=True)
class SensorGrid:
    """Measured static error of one direction, interpolated linearly between the points."""

    xs: np.ndarray
    ys: np.ndarray
    Z: np.ndarray  # (ny, nx), NaN outside the points' convex hull


def sensor_rows(data: ReportData, direction: str) -> np.ndarray:
    """Indices of the sensor rows of ``direction``."""
    s = data.sensor
    return np.array([i for i, d in enumerate(s.direction) if d == direction], dtype=int)


def interpolate_measured(points: np.ndarray, values: np.ndarray, n: int = 60) -> SensorGrid | None:
    """Linear interpolation (Delaunay) of scattered values on a regular grid; None if < 3 points.

    Outside the convex hull of the points the grid holds NaN: no extrapolation.
    """
    from scipy.interpolate import griddata

    ok = np.isfinite(values)
    p, v = points[ok], values[ok]
    if len(p) < 3 or np.linalg.matrix_rank(p - p.mean(axis=0)) < 2:
        return None
    xs = np.linspace(p[:, 0].min(), p[:, 0].max(), n)
    ys = np.linspace(p[:, 1].min(), p[:, 1].max(), n)
    X, Y = np.meshgrid(xs, ys)
    Z = griddata(p, v, (X, Y), method="linear")
    return SensorGrid(xs, ys, Z)


def middle_line_order(data: ReportData, direction: str) -> np.ndarray:
    """Rows of ``direction`` on the middle line (all rows when not marked), ordered by y then x."""
    s = data.sensor
    rows = sensor_rows(data, direction)
    if s.middle_line is not None:
        rows = rows[s.middle_line[rows]]
    order = np.lexsort((s.points[rows, 0], s.points[rows, 1]))
    return rows[order]
