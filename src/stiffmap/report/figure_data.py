"""What the report's figures draw, computed once for both back-ends.

:mod:`~stiffmap.report.interactive_figures` (plotly, in the HTML page) and
:mod:`~stiffmap.report.static_figures` (matplotlib, PNGs for papers) draw the
same figures; everything they compute from :class:`~stiffmap.report.data.ReportData`
(planes, grids, marker sizes, colour scales, which rows are which) lives here,
so the two modules only draw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .data import ModelStiffness, ReportData, SensorMap

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


@dataclass(frozen=True)
class DetMarkers:
    """The markers of the 3D stiffness map (the reference study's Fig. 12), for both back-ends.

    Attributes
    ----------
    diameters : ndarray, shape (n,)
        :func:`det_diameters` of det K at the measured positions (NaN elsewhere).
    good : ndarray of bool, shape (n,)
        Measured with det K > 0: drawn with their diameter.
    bad : ndarray of bool, shape (n,)
        Measured with det K <= 0 (flagged): their own symbol.
    failed : ndarray of bool, shape (n,)
    lo, hi : float, (N/mm)³
        Colour scale of det K over the good positions.
    """

    diameters: np.ndarray
    good: np.ndarray
    bad: np.ndarray
    failed: np.ndarray
    lo: float
    hi: float


def det_markers(data: ReportData) -> DetMarkers | None:
    """Marker sizes, groups and colour scale of the 3D map; None without measurements."""
    m = data.measured
    if m is None:
        return None
    diam = det_diameters(np.where(m.ok, m.det, np.nan))
    good = m.ok & np.isfinite(diam)
    bad = m.ok & ~good
    lo, hi = finite_range(m.det[good]) if good.any() else (0.0, 1.0)
    return DetMarkers(diam, good, bad, ~m.ok, lo, hi)


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


def spans_plane(points: np.ndarray) -> bool:
    """True when at least 3 points that are not all on one line (a triangulation exists)."""
    p = np.asarray(points, dtype=float)
    return len(p) >= 3 and np.linalg.matrix_rank(p - p.mean(axis=0)) >= 2


def interpolate_measured(points: np.ndarray, values: np.ndarray, n: int = 60) -> SensorGrid | None:
    """Linear interpolation (Delaunay) of scattered values on a regular grid; None if < 3 points.

    Outside the convex hull of the points the grid holds NaN: no extrapolation.
    """
    from scipy.interpolate import griddata

    ok = np.isfinite(values)
    p, v = points[ok], values[ok]
    if not spans_plane(p):
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


@dataclass(frozen=True)
class PlaneMapValues:
    """What a per-plane map of one quantity draws, for both figure back-ends.

    Attributes
    ----------
    title, unit : str
        The quantity's name and unit (:data:`QUANTITIES`).
    values : ndarray, shape (n,)
        Measured values, NaN at failed positions.
    planes : ndarray, shape (p,), mm
        Distinct z of the positions, upper plane first.
    model : ModelStiffness or None
    model_values : ndarray, shape (n,) or None
        The model at the positions.
    map_values : ndarray, shape (g,) or None
        The model's dense map, when given.
    flagged : ndarray of bool, shape (n,)
        Positions with flags (clipped to the colour scale, outlined in red).
    lo, hi : float
        Colour scale of measured and model values (flagged positions left out).
    residuals : ndarray, shape (n,) or None
        Measured minus model.
    residual_range : float
        Half-width of the residuals' diverging scale (1 without a model).
    """

    title: str
    unit: str
    values: np.ndarray
    planes: np.ndarray
    model: ModelStiffness | None
    model_values: np.ndarray | None
    map_values: np.ndarray | None
    flagged: np.ndarray
    lo: float
    hi: float
    residuals: np.ndarray | None
    residual_range: float


def plane_map_values(data: ReportData, quantity: str) -> PlaneMapValues | None:
    """The values, planes and colour scales of ``quantity`` per plane; None without measurements."""
    m = data.measured
    if m is None:
        return None
    title, unit = QUANTITIES[quantity]
    vals = np.where(m.ok, getattr(m, quantity), np.nan)
    model = data.model
    mv = getattr(model, quantity) if model is not None else None
    mapv = getattr(model.map, quantity) if model is not None and model.map is not None else None
    flagged = np.array([bool(f) for f in m.flags])
    # Flagged positions (a non-positive-definite K, say) would stretch the scale: they keep
    # their red outline and hover value, and are clipped to the scale's end.
    lo, hi = finite_range(np.where(flagged, np.nan, vals), mv, mapv)
    res = getattr(data.residuals, quantity) if model is not None else None
    rr = symmetric_range(np.where(flagged, np.nan, res)) if res is not None else 1.0
    return PlaneMapValues(
        title, unit, vals, plane_values(m.positions[:, 2]), model, mv, mapv, flagged, lo, hi, res, rr
    )


def model_plane_grid(
    model: ModelStiffness, map_values: np.ndarray, z: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The model's dense map on plane ``z`` as a grid ``(xs, ys, Z)`` (:func:`as_grid`).

    None when there is no dense map, fewer than 4 of its points lie on the plane,
    or they do not fill a grid.
    """
    if model.map is None:
        return None
    on = on_plane(model.map.points[:, 2], z)
    if on.sum() < 4:
        return None
    return as_grid(model.map.points[on, :2], map_values[on])


@dataclass(frozen=True)
class ModelVsMeasured:
    """One quantity measured against modelled, for a scatter about the identity line.

    Attributes
    ----------
    model, measured : ndarray, shape (k,)
        The values at the positions where both are finite.
    rows : ndarray of bool, shape (n,)
        Those positions.
    lo, hi : float
        Range of both (the identity line's ends).
    """

    model: np.ndarray
    measured: np.ndarray
    rows: np.ndarray
    lo: float
    hi: float


def model_vs_measured(data: ReportData, quantity: str) -> ModelVsMeasured:
    """``quantity`` ("det" or "min_principal") of the model and of the measured positions."""
    m, mod = data.measured, data.model
    a, b = getattr(mod, quantity), np.where(m.ok, getattr(m, quantity), np.nan)
    ok = np.isfinite(a) & np.isfinite(b)
    lo, hi = finite_range(a[ok], b[ok])
    return ModelVsMeasured(a[ok], b[ok], ok, lo, hi)


@dataclass(frozen=True)
class TruthEntries:
    """Recovered against true K of the measured positions (virtual test-bed), for both back-ends.

    Attributes
    ----------
    true, recovered, std : ndarray, shape (9 k,), N/mm
        Every entry of the true K, the recovered K and its standard error at the k
        measured positions.
    diagonal : ndarray of bool, shape (9 k,)
        Entries on the diagonal.
    lo, hi : float, N/mm
        Range of true and recovered entries (the identity line's ends).
    error : ndarray, shape (n,)
        Relative Frobenius error per position (``ReportData.truth_error``).
    worst : int or None
        Index of the largest finite error.
    flagged : ndarray of bool, shape (n,)
        Positions with flags.
    """

    true: np.ndarray
    recovered: np.ndarray
    std: np.ndarray
    diagonal: np.ndarray
    lo: float
    hi: float
    error: np.ndarray
    worst: int | None
    flagged: np.ndarray


def truth_entries(data: ReportData) -> TruthEntries | None:
    """The K entries and errors of the recovered-vs-true figure; None without a truth."""
    if data.truth is None:
        return None
    m, t = data.measured, data.truth
    err = data.truth_error
    ok = m.ok
    tv = t.K[ok].reshape(-1)
    rv = m.K[ok].reshape(-1)
    sv = m.K_std[ok].reshape(-1)
    diag = np.tile(np.eye(3, dtype=bool).ravel(), ok.sum())
    lo, hi = finite_range(tv, rv)
    worst = int(np.nanargmax(err)) if np.isfinite(err).any() else None
    flagged = np.array([bool(f) for f in m.flags])
    return TruthEntries(tv, rv, sv, diag, lo, hi, err, worst, flagged)


@dataclass(frozen=True)
class CalibrationPanels:
    """The calibration figure's data: per-view RMS, corner residuals and coverage (px).

    Attributes
    ----------
    views : list of dict
        The ``views`` of ``camera.json`` (may be empty).
    rms : ndarray, shape (v,), px
        RMS reprojection error per view, NaN when absent.
    used : ndarray of bool, shape (v,)
    residuals : ndarray, shape (c, 2), px, or None
        Every corner's residual, observed - projected.
    residual_range : float, px
        Half-width of the residual panel's axes (before its 5 % margin).
    corners : CalibrationCorners or None
        Where the used views put their corners in the image (the coverage panel).
    panels : int
        1 to 3: the views' RMS, the residuals, the coverage, those present.
    """

    views: list
    rms: np.ndarray
    used: np.ndarray
    residuals: np.ndarray | None
    residual_range: float
    corners: CalibrationCorners | None
    panels: int


def calibration_panels(data: ReportData) -> CalibrationPanels | None:
    """What the calibration figure draws; None without views and residuals."""
    c = data.calibration
    if c is None:
        return None
    views = c.camera.get("views") or []
    cc = calibration_corners(data)
    r = c.corner_residuals_px
    if r is None and cc is not None:  # the residuals camera.json keeps per view
        r = cc.residuals
    if not views and r is None:
        return None
    rms, used = view_rms(views)
    half = symmetric_range(r) if r is not None else 1.0
    panels = int(bool(views)) + int(r is not None) + int(cc is not None)
    return CalibrationPanels(views, rms, used, r, half, cc, panels)


def sensor_has_model(data: ReportData) -> bool:
    """True when the sensor results have a model (at the points or as dense maps): a second column."""
    s = data.sensor
    return s.model_error_um is not None or bool(s.maps)


@dataclass(frozen=True)
class SensorDirection:
    """The sensor rows of one load direction, for both figure back-ends.

    Attributes
    ----------
    rows : ndarray of int, shape (k,)
        Indices of the direction's rows in ``data.sensor``.
    points : ndarray, shape (k, 2), mm
    error_um : ndarray, shape (k,), µm
        Measured static error, NaN where the recording failed.
    model_um : ndarray, shape (k,), µm, or None
        The model at the points.
    dense : SensorMap or None
        The model's dense map of this direction.
    dense_grid : tuple (xs, ys, Z) or None
        That map as a grid (:func:`as_grid`), when it fills one.
    lo, hi : float
        Colour scale over measured, model and dense values.
    """

    rows: np.ndarray
    points: np.ndarray
    error_um: np.ndarray
    model_um: np.ndarray | None
    dense: SensorMap | None
    dense_grid: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    lo: float
    hi: float


def sensor_direction(data: ReportData, direction: str) -> SensorDirection:
    """Rows, values and colour scale of one load direction of ``data.sensor``."""
    s = data.sensor
    idx = sensor_rows(data, direction)
    e = s.error_um[idx]
    model = s.model_error_um[idx] if s.model_error_um is not None else None
    dense = next((mp for mp in s.maps if mp.direction == direction), None)
    lo, hi = finite_range(e, model, dense.error_um if dense is not None else None)
    grid = as_grid(dense.points, dense.error_um) if dense is not None else None
    return SensorDirection(idx, s.points[idx], e, model, dense, grid, lo, hi)


def view_names(views: list[dict]) -> list[str]:
    """The views' image names without the folder they share (``calibrate`` keeps the paths given)."""
    names = [str(v.get("image", f"view {k + 1}")) for k, v in enumerate(views)]
    parts = [n.replace("\\", "/").split("/") for n in names]
    common = 0
    while len(names) > 1 and all(len(p) > common + 1 and p[common] == parts[0][common] for p in parts):
        common += 1
    return ["/".join(p[common:]) for p in parts]


def view_rms(views: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Per-view RMS reprojection error (px, NaN when absent) and the used mask of ``camera.json`` views."""
    rms = np.array(
        [v.get("rms_px") if isinstance(v.get("rms_px"), (int, float)) else np.nan for v in views],
        dtype=float,
    )
    used = np.array([bool(v.get("used", True)) for v in views])
    return rms, used


# --------------------------------------------------------------------------- reviewer's diagnostics
def error_axis(values: np.ndarray, outlier: float = 4.0) -> tuple[float, np.ndarray]:
    """A linear axis from zero for non-negative values (errors, %): its top and the values above it.

    The axis is 15 % above the largest value, unless some values exceed ``outlier`` times the
    90th percentile: those are drawn at the top of an axis fitted to the others (and say their
    value), so that one mislabelled position does not flatten every other dot onto zero.

    Returns
    -------
    top : float
    above : ndarray of bool, shape of ``values``
        The values drawn at the top, beyond the axis.
    """
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v)
    above = np.zeros(v.shape, dtype=bool)
    if not ok.any():
        return 1.0, above
    q = float(np.percentile(v[ok], 90))
    if q > 0:
        above = ok & (v > outlier * q)
    rest = v[ok & ~above]
    top = 1.15 * float(rest.max() if rest.size else v[ok].max())
    return (top if top > 0 else 1.0), above


def position_dtick(n: int, most: int = 24) -> int:
    """Step of the position axis' ticks: a whole number (positions are counted), at most ``most`` ticks."""
    return max(1, -(-int(n) // most))


@dataclass(frozen=True)
class LoadDirection:
    """Load cases along one direction: their displacement against the force (linearity).

    Attributes
    ----------
    label : str
        ``"+y"``, ``"-x"`` for an axis, else the unit vector (``"(0.6, 0.8, 0)"``).
    unit : ndarray, shape (3,)
        The direction of the force.
    loads : ndarray of int, shape (k,)
        The load cases along it, by increasing force.
    magnitude : ndarray, shape (k,), N
        Their force magnitudes.
    """

    label: str
    unit: np.ndarray
    loads: np.ndarray
    magnitude: np.ndarray


def load_directions(forces: np.ndarray) -> list[LoadDirection]:
    """The load cases grouped by the direction of their force (zero forces left out), in order."""
    F = np.asarray(forces, dtype=float)
    mag = np.linalg.norm(F, axis=1)
    groups: dict[tuple, list[int]] = {}
    for j in np.flatnonzero(mag > 0):
        groups.setdefault(tuple(np.round(F[j] / mag[j], 6)), []).append(int(j))
    out = []
    for key, loads in groups.items():
        u = np.array(key)
        order = np.argsort(mag[loads], kind="stable")
        idx = np.array(loads)[order]
        axis = np.flatnonzero(np.abs(u) > 1 - 1e-9)
        if axis.size == 1:
            label = ("+" if u[axis[0]] > 0 else "-") + "xyz"[axis[0]]
        else:
            label = "(" + ", ".join(f"{v:.3g}" for v in u) + ")"
        out.append(LoadDirection(label, u, idx, mag[idx]))
    return out


def displacement_residuals(
    K: np.ndarray, forces: np.ndarray, vectors: np.ndarray, *, offset: bool
) -> np.ndarray:
    """What each position's identified K leaves of its displacements: d - C F (- b).

    Parameters
    ----------
    K : ndarray, shape (n, 3, 3), N/mm
        NaN for a position without a stiffness.
    forces : ndarray, shape (L, 3), N
    vectors : ndarray, shape (n, L, R, 3), mm
        The displacements (NaN where missing).
    offset : bool
        The displacements were measured against one (mean) reference per position, so the
        fit also estimated their common offset b (``identify_stiffness(offset=True)``):
        given C, its least-squares value is the mean of d - C F, which is taken out.

    Returns
    -------
    ndarray, shape (n, L, R, 3), mm
        NaN where the displacement or K is missing.
    """
    out = np.full(vectors.shape, np.nan)
    for i in np.flatnonzero(np.all(np.isfinite(K), axis=(1, 2))):
        r = vectors[i] - (np.linalg.solve(K[i], forces.T).T)[:, None, :]  # (L, R, 3)
        if offset and np.isfinite(r).any():
            r = r - np.nanmean(r.reshape(-1, 3), axis=0)
        out[i] = r
    return out


def residual_rms(data: ReportData) -> np.ndarray | None:
    """RMS over load cases and repeats of each residual component of d = C F, shape (n, 3), mm.

    NaN for a position without residuals; None when the data hold none.
    """
    ld = data.loads
    if ld is None or ld.residuals is None:
        return None
    r = ld.residuals
    cnt = np.sum(np.isfinite(r), axis=(1, 2))
    ss = np.nansum(r**2, axis=(1, 2))
    out = np.full(cnt.shape, np.nan)
    np.divide(ss, cnt, out=out, where=cnt > 0)
    return np.sqrt(out)


@dataclass(frozen=True)
class Ellipsoids:
    """Compliance ellipsoids at the positions whose K is positive definite.

    The ellipsoid of a position has the principal directions of the symmetric part of K
    as axes and the principal compliances 1/k (mm/N) as semi-axes, times ``scale`` (the
    same for every position, so sizes compare): the displacement a unit force in each
    direction causes, drawn at the position.

    Attributes
    ----------
    index : ndarray of int, shape (k,)
        The positions drawn.
    centers : ndarray, shape (k, 3), mm
    directions : ndarray, shape (k, 3, 3)
        Columns: the principal directions (unit), stiffest last.
    stiffness : ndarray, shape (k, 3), N/mm
        Principal stiffnesses, ascending.
    scale : float
        Drawing length per compliance, mm per (mm/N).
    skipped : ndarray of int
        Positions with a K that is not positive definite (no ellipsoid).
    """

    index: np.ndarray
    centers: np.ndarray
    directions: np.ndarray
    stiffness: np.ndarray
    scale: float
    skipped: np.ndarray

    def semi_axes(self) -> np.ndarray:
        """Drawn semi-axes, shape (k, 3), mm."""
        return self.scale / self.stiffness

    def mesh(self, k: int, nu: int = 18, nv: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y, z (mm) of ellipsoid ``k``'s surface, each shape (nv, nu)."""
        u = np.linspace(0.0, 2 * np.pi, nu)
        v = np.linspace(0.0, np.pi, nv)
        sphere = np.stack(
            [np.outer(np.sin(v), np.cos(u)), np.outer(np.sin(v), np.sin(u)), np.outer(np.cos(v), np.ones(nu))]
        )
        pts = np.einsum("ij,j,jab->iab", self.directions[k], self.semi_axes()[k], sphere)
        return tuple(pts[i] + self.centers[k, i] for i in range(3))

    def triangles(self, nu: int = 14, nv: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every ellipsoid as one triangle mesh (one plot trace draws them all).

        Returns
        -------
        vertices : ndarray, shape (k * nv * nu, 3), mm
        faces : ndarray of int, shape (k * 2 * (nv - 1) * (nu - 1), 3)
            Vertex indices of each triangle.
        owner : ndarray of int, shape (k * nv * nu,)
            The ellipsoid (row of ``index``) of each vertex.
        """
        a = np.arange(nv * nu).reshape(nv, nu)
        p, q, r, s = a[:-1, :-1].ravel(), a[:-1, 1:].ravel(), a[1:, :-1].ravel(), a[1:, 1:].ravel()
        quad = np.concatenate([np.stack([p, q, s], 1), np.stack([p, s, r], 1)])
        verts, faces = [], []
        for k in range(len(self.index)):
            verts.append(np.stack([c.ravel() for c in self.mesh(k, nu, nv)], axis=1))
            faces.append(quad + k * nv * nu)
        owner = np.repeat(np.arange(len(self.index)), nv * nu)
        return np.concatenate(verts), np.concatenate(faces), owner


def compliance_ellipsoids(data: ReportData, fill: float = 0.45) -> Ellipsoids | None:
    """The ellipsoids of the measured K (None without a positive definite one).

    ``fill``: the largest semi-axis drawn, as a share of the smallest distance between two
    positions (of the positions' extent with one position).
    """
    m = data.measured
    if m is None:
        return None
    keep, skipped, dirs, ks = [], [], [], []
    for i in np.flatnonzero(m.ok):
        w, V = np.linalg.eigh(0.5 * (m.K[i] + m.K[i].T))
        if w[0] <= 0:
            skipped.append(i)
            continue
        keep.append(i)
        dirs.append(V)
        ks.append(w)
    if not keep:
        return None
    idx = np.array(keep)
    P = m.positions[idx]
    d = np.linalg.norm(P[:, None] - P[None], axis=2)
    d = d[d > 1e-9]  # two positions at one place: not a spacing
    spacing = float(d.min()) if d.size else 100.0
    ks = np.array(ks)
    scale = fill * spacing * float(ks.min())  # the softest direction's semi-axis = fill x spacing
    return Ellipsoids(idx, P, np.array(dirs), ks, scale, np.array(skipped, dtype=int))


@dataclass(frozen=True)
class CalibrationCorners:
    """Where the calibration's views put corners in the image, and their residuals.

    Attributes
    ----------
    corners : ndarray, shape (N, 2), px
    residuals : ndarray, shape (N, 2), px
        Observed - projected.
    view : ndarray of int, shape (N,)
        The view (index in ``camera.json``'s ``views``) of each corner.
    size : (int, int)
        [w, h] of the image, px.
    """

    corners: np.ndarray
    residuals: np.ndarray
    view: np.ndarray
    size: tuple[int, int]

    def coverage(self, cells: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Corners per cell of a grid over the image: counts (rows, cols), x edges, y edges (px).

        ``cells`` along the longer side; square cells.
        """
        w, h = self.size
        side = max(w, h) / cells
        xe = np.linspace(0.0, w, max(1, round(w / side)) + 1)
        ye = np.linspace(0.0, h, max(1, round(h / side)) + 1)
        counts, _, _ = np.histogram2d(self.corners[:, 1], self.corners[:, 0], bins=[ye, xe])
        return counts, xe, ye


def calibration_corners(data: ReportData) -> CalibrationCorners | None:
    """The used views' corners and residuals from ``camera.json`` (None when it keeps none)."""
    c = data.calibration
    if c is None:
        return None
    cs, rs, vs = [], [], []
    for k, v in enumerate(c.camera.get("views") or []):
        if not v.get("used", True) or "corners_px" not in v:
            continue
        cs.append(np.asarray(v["corners_px"], dtype=float).reshape(-1, 2))
        rs.append(np.asarray(v["residuals_px"], dtype=float).reshape(-1, 2))
        vs.append(np.full(len(cs[-1]), k))
    if not cs:
        return None
    w, h = c.camera["image_size"]
    return CalibrationCorners(np.concatenate(cs), np.concatenate(rs), np.concatenate(vs), (int(w), int(h)))


@dataclass(frozen=True)
class SensorLines:
    """The sensor recordings' plateaus against the load, with their fitted lines.

    Attributes
    ----------
    rows : ndarray of int, shape (k,)
        The recordings (rows of ``SensorResults``) with plateaus and a fitted line.
    load, displacement, residual : list of ndarray
        Per recording: each plateau's load (N), displacement (um) and what the line leaves
        of it (um).
    line_load, line_um : list of ndarray, shape (2,)
        The fitted line's ends, from no load to the largest (N, um).
    """

    rows: np.ndarray
    load: list
    displacement: list
    residual: list
    line_load: list
    line_um: list


def sensor_lines(data: ReportData) -> SensorLines | None:
    """What the linearity figures of a sensor campaign draw; None without plateaus."""
    s = data.sensor
    if s is None or s.step_load_n is None or s.fit_um_per_n is None:
        return None
    rows, load, disp, res, ll, lu = [], [], [], [], [], []
    for i in range(s.m):
        f, u = s.step_load_n[i], s.step_um[i]
        ok = np.isfinite(f) & np.isfinite(u)
        a, b = s.fit_um_per_n[i], s.fit_intercept_um[i] if s.fit_intercept_um is not None else 0.0
        if not ok.any() or not (np.isfinite(a) and np.isfinite(b)):
            continue
        rows.append(i)
        load.append(f[ok])
        disp.append(u[ok])
        res.append(u[ok] - (b + a * f[ok]))
        ends = np.array([0.0, max(float(f[ok].max()), 0.0)])
        ll.append(ends)
        lu.append(b + a * ends)
    if not rows:
        return None
    return SensorLines(np.array(rows), load, disp, res, ll, lu)
