"""Example report data: a vision campaign and a sensor campaign, synthetic but complete.

These exist to show and test the report: every optional part is filled. They
are **not** the mechanism models (those live in ``stiffmap.models``) and their
numbers describe no real robot.

- :func:`example_vision`: the reference vision study's layout (48 positions, 16
  on each of the planes z = -200, -310, -400 mm, x, y in [-200, 200] mm), its
  nine load cases (Table II) and ten repeats. A smooth stiffness field, stiffer
  at the centre and on the upper plane as the study found, gives the true K;
  displacements are simulated with camera-like noise and K is identified from
  them with :func:`stiffmap.identify.identify_stiffness`, so K, its standard
  errors and flags are real results. Two positions fail, one has missing
  repeats and one has a mislabelled load case (its flags show it). The
  "model" is a second field with one fitted scale parameter, and the
  calibration numbers are the study's Table IV with simulated residuals.
- :func:`example_sensor`: 22 points of a planar workspace measured in x and y
  under 50 kgf, with a static-error field that grows toward the workspace
  border, a "model" with a fitted prismatic-joint stiffness ``kj``, a dense
  model map and one failed recording.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from .. import __version__
from ..identify import identify_stiffness
from ..loads import forces_matrix, paper9
from . import data as rd  # the report's data contract
from .figure_data import displacement_residuals

__all__ = ["example_vision", "example_sensor", "example_field", "REFERENCE_PLANES_Z"]

#: The reference study's planes, mm.
REFERENCE_PLANES_Z = (-200.0, -310.0, -400.0)


def _rot(axis: int, a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (0, 2), (0, 1)][axis]
    R[..., axis, axis] = 1
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def example_field(points, *, soften: float = 0.55, coupling: float = 1.0) -> np.ndarray:
    """A smooth stiffness field, shape (g, 3, 3), N/mm, at points (g, 3) mm.

    Principal stiffnesses (6, 7.5, 19) N/mm at the centre of the plane z = -200,
    falling toward the border (factor 1 - ``soften`` r^2, r = radius / 283 mm) and
    with depth (factor 1 - 0.45 (-z - 200)/200), turned by a position-dependent
    rotation scaled by ``coupling``.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    r2 = (p[:, 0] ** 2 + p[:, 1] ** 2) / 283.0**2
    t = (-p[:, 2] - 200.0) / 200.0
    f = (1.0 - soften * r2) * (1.0 - 0.45 * t)
    k = np.array([6.0, 7.5, 19.0]) * f[:, None]
    R = _rot(2, coupling * 0.3 * p[:, 0] / 200.0) @ _rot(0, coupling * 0.15 * p[:, 1] / 200.0)
    return R @ (k[:, :, None] * np.swapaxes(R, 1, 2))


def _camera(rng: np.random.Generator) -> tuple[dict, np.ndarray]:
    views, res = [], []
    grid = np.array([(i, j) for j in range(6) for i in range(9)], dtype=float) - (4.0, 2.5)
    for v in range(15):
        r = rng.normal(0.0, rng.uniform(0.12, 0.3), size=(54, 2))
        res.append(r)
        # A 9x6 board somewhere in the 2928 x 1808 image, turned and scaled (the coverage map).
        a, s = rng.uniform(-0.5, 0.5), rng.uniform(60.0, 110.0)
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        centre = rng.uniform((500.0, 350.0), (2428.0, 1458.0))
        views.append(
            {
                "image": f"calib_{v + 1:02d}.png",
                "used": True,
                "rms_px": float(np.sqrt(np.mean(r**2) * 2)),
                "reason": "",
                "corners_px": np.round(centre + s * grid @ rot.T, 3).tolist(),
                "residuals_px": np.round(r, 3).tolist(),
            }
        )
    views.append({"image": "calib_16.png", "used": False, "rms_px": None, "reason": "board not found"})
    res = np.concatenate(res)
    cam = {
        # Intrinsics of the reference vision study (its Table IV).
        "image_size": [2928, 1808],
        "fx": 3733.27,
        "fy": 3722.85,
        "cx": 1466.77,
        "cy": 904.81,
        "dist": [-0.09, 0.11, 0.0, 0.0, 0.0],
        "std": {"fx": 39.96, "fy": 36.86, "cx": 24.65, "cy": 40.23, "dist": [0.0011, 0.04632, 0.0, 0.0, 0.0]},
        "rms_px": float(np.sqrt(np.mean(np.sum(res**2, axis=1)))),
        "residual_std_px": [float(np.std(res[:, 0])), float(np.std(res[:, 1]))],
        "views": views,
    }
    return cam, res


def example_vision(
    seed: int = 0,
    *,
    repeats: int = 10,
    noise_mm: float = 0.004,
    planes: Sequence[float] = REFERENCE_PLANES_Z,
    per_side: int = 4,
) -> rd.ReportData:
    """A complete vision campaign, see the module docstring.

    By default the reference layout: ``per_side`` x ``per_side`` positions with x, y in
    [-200, 200] mm on each of ``planes`` (48 positions), the nine load cases, ``repeats``
    repeats. Positions 14 and 39 fail (when they exist), position 6 loses two repeats of
    load case 3 and position 45 (the last but three when fewer) has two load cases swapped.
    """
    rng = np.random.default_rng(seed)
    g = np.linspace(-200.0, 200.0, per_side)
    pos = np.array([(x, y, z) for z in planes for y in g for x in g])
    n = len(pos)
    loads = paper9()
    F = forces_matrix(loads)  # (3, L)
    L = F.shape[1]
    Kt = example_field(pos)
    failed = {13: "pos14_load5_rep3.png: mobile board not found", 38: "pos39_load2_rep1.png: file not found"}
    failed = {i: msg for i, msg in failed.items() if i < n}
    swapped = 44 if n > 44 else n - 4
    K, measured, vectors = _identified(rng, pos, Kt, F, repeats, noise_mm, failed, swapped)
    model = _example_model(pos, K, measured, planes)
    cam, res = _camera(rng)
    return rd.ReportData(
        campaign=rd.CampaignInfo(
            name="Example vision campaign (synthetic)",
            kind="vision",
            version=__version__,
            date="2026-11-22T10:00:00",
            campaign_dir="examples/vision",
            notes=(
                f"Synthetic data in the reference study's layout: {n} positions, the nine load cases "
                f"of its Table II, {repeats} repeats. Position {swapped + 1} had two load cases swapped "
                "by the operator."
            ),
        ),
        measured=measured,
        loads=rd.LoadData(
            tuple(ld.label for ld in loads),
            F.T,
            np.linalg.norm(vectors, axis=3),
            vectors=vectors,
            residuals=displacement_residuals(K, F.T, vectors, offset=False),
        ),
        model=model,
        truth=rd.TruthStiffness(Kt),
        calibration=rd.CalibrationData(cam, res),
        failures=tuple(rd.Failure(f"position {i + 1}", m) for i, m in failed.items())
        + (rd.Failure("calib_16.png", "board not found; view not used"),),
        setup=tuple(
            rd.SetupItem(a, b)
            for a, b in (
                ("robot", "example (a smooth synthetic field)"),
                ("positions", f"{n} on {len(planes)} plane(s) z = {', '.join(f'{z:g}' for z in planes)} mm"),
                (
                    "load cases",
                    f"{L}, {repeats} repeat(s) each: "
                    + "; ".join(f"{j + 1}: {ld.label}" for j, ld in enumerate(loads)),
                ),
                ("camera", "2928x1808 px, the reference study's Table IV, calibrated from 15 of 16 views"),
                ("stiffness", f"{int(measured.ok.sum())} of {n} positions identified, {len(failed)} failed"),
                ("failures", f"{len(failed) + 1} (each listed under Failures)"),
            )
        ),  # fmt: skip
    )


def _identified(rng, pos, Kt, F, repeats: int, noise_mm: float, failed: dict, swapped: int):
    """K identified at each position from simulated displacements under the load cases ``F``
    (3, L): two load cases swapped at ``swapped``, two repeats lost at position 6, the ``failed``
    positions failed; K, the measured stiffness and the displacement vectors (n, L, repeats, 3)."""
    n = len(pos)
    L = F.shape[1]
    K = np.full((n, 3, 3), np.nan)
    K_std = np.full((n, 3, 3), np.nan)
    flags: list[tuple[str, ...]] = []
    status, messages = [], []
    vectors = np.full((n, L, repeats, 3), np.nan)
    for i in range(n):
        Fi = F.copy()
        if i == swapped:
            Fi[:, 0], Fi[:, 1] = F[:, 1].copy(), F[:, 0].copy()  # two load cases swapped by the operator
        D = np.linalg.solve(Kt[i], Fi)[:, :, None] + rng.normal(0.0, noise_mm, size=(3, L, repeats))
        if i == 5:
            D[:, 2, 8:] = np.nan  # two repeats lost
        vectors[i] = np.moveaxis(D, 0, -1)
        if i in failed:
            vectors[i, 4 if i == 13 else 1, :] = np.nan
            status.append("failed")
            messages.append(failed[i])
            flags.append(())
            continue
        keep = np.isfinite(D[0])
        FF = np.repeat(F[:, :, None], repeats, axis=2)[:, keep]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = identify_stiffness(FF, D[:, keep])
        K[i], K_std[i] = fit.K, fit.K_std
        status.append("ok")
        messages.append("")
        flags.append(fit.flags)
    measured = rd.MeasuredStiffness.from_K(pos, K, K_std, status=status, messages=messages, flags=flags)
    return K, measured, vectors


def _example_model(pos, K, measured, planes) -> rd.ModelStiffness:
    """An illustrative model: a softer-coupled field with one fitted scale s (least squares on K)."""
    shape = example_field(pos, soften=0.5, coupling=0.7)
    ok = measured.ok
    a, b = shape[ok].ravel(), K[ok].ravel()
    s = float(a @ b / (a @ a))
    s_std = float(np.sqrt(np.sum((b - s * a) ** 2) / (a.size - 1) / (a @ a)))
    gx = np.linspace(-220.0, 220.0, 23)
    mp = np.array([(x, y, z) for z in planes for y in gx for x in gx])
    Km = s * example_field(mp, soften=0.5, coupling=0.7)
    det = np.linalg.det(Km)
    minp = np.linalg.eigvalsh(0.5 * (Km + np.swapaxes(Km, 1, 2)))[:, 0]
    return rd.ModelStiffness.from_K(
        "illustrative field (example)",
        [rd.Parameter("s", s, s_std, "-"), rd.Parameter("soften", 0.5, unit="-")],
        s * shape,
        map=rd.ModelMap(mp, det, minp),
    )


def example_sensor(seed: int = 0) -> rd.ReportData:
    """A complete sensor campaign: 22 points, x and y loads of 50 kgf, see the module docstring."""
    rng = np.random.default_rng(seed)
    pts, labels = _sensor_points()
    kj_true = 525.0
    rows_p, rows_d, rows_l, err, std, ml = [], [], [], [], [], []
    for d in ("x", "y"):
        e = _shape_um(pts, d) * (525.0 / kj_true) * (1 + rng.normal(0, 0.03, len(pts)))
        if d == "x":
            e *= 1.08  # mirror set-up: the study saw more scatter in x
        rows_p.append(pts)
        rows_d += [d] * len(pts)
        rows_l += labels
        err.append(e)
        std.append(np.abs(e) * rng.uniform(0.01, 0.03, len(pts)) + 2.6)
        ml.append(np.arange(len(pts)) < 8)  # the middle line: the first 8 points
    P = np.concatenate(rows_p)
    err = np.concatenate(err)
    std = np.concatenate(std)
    fail_row = rows_l.index("13")  # point 13, direction x
    err[fail_row] = np.nan
    std[fail_row] = np.nan
    g = np.concatenate([_shape_um(P[k : k + 1], rows_d[k]) for k in range(len(P))]) * 525.0
    ok = np.isfinite(err)
    cinv = float(g[ok] @ err[ok] / (g[ok] @ g[ok]))  # err = g / kj
    sig = np.sqrt(np.sum((err[ok] - g[ok] * cinv) ** 2) / (ok.sum() - 1))
    kj = 1.0 / cinv
    kj_std = float(sig / np.sqrt(g[ok] @ g[ok]) / cinv**2)
    model = g / kj
    maps = _sensor_model_maps(kj)
    loads_n, steps, slope, icpt = _sensor_steps(rng, err, ok)
    return rd.ReportData(
        campaign=rd.CampaignInfo(
            name="Example sensor campaign (synthetic)",
            kind="sensor",
            version=__version__,
            date="2026-11-22T10:00:00",
            campaign_dir="examples/sensor",
            notes="Synthetic static errors at 22 points of a planar workspace, loads of 50 kgf in x and y.",
        ),
        sensor=rd.SensorResults(
            points=P,
            direction=tuple(rows_d),
            error_um=err,
            error_std_um=std,
            labels=tuple(rows_l),
            model_error_um=model,
            middle_line=np.concatenate(ml),
            reference_load_n=490.5,
            model_name="illustrative 3PRR-like field (example)",
            parameters=(rd.Parameter("kj", kj, kj_std, "N/mm"), rd.Parameter("kb", 9800.0, unit="N/mm")),
            maps=maps,
            step_load_n=np.where(ok[:, None], loads_n, np.nan),
            step_um=steps,
            fit_um_per_n=slope,
            fit_intercept_um=icpt,
        ),
        failures=(rd.Failure("point 13, x", "rec_13_x.csv: saturated from 12.1 s to 14.3 s"),),
        setup=(
            rd.SetupItem("robot", "example (an illustrative 3PRR-like field)"),
            rd.SetupItem("recordings", f"{int(ok.sum())} of {len(err)} analysed, {int((~ok).sum())} failed"),
            rd.SetupItem("points", f"{len(pts)}, loaded along x, y"),
            rd.SetupItem("load steps", "0, 10, 20, 30, 40, 50 kgf"),
            rd.SetupItem("reference load", "490.5 N (the static error is given at it)"),
        ),
    )


#: The centroid of the example sensor campaign's rails' triangle (mm).
_SENSOR_CENTRE = np.array([500.0, 1000.0 / (2 * np.sqrt(3.0))])


def _sensor_points() -> tuple[np.ndarray, list[str]]:
    """The 22 points (mm): the 8 of the middle line first, with the milling study's labels."""
    mid = [(500.0, y) for y in np.linspace(150.0, 465.0, 8)]
    side = [(x, y) for x in (400.0, 600.0) for y in np.linspace(170.0, 420.0, 5)]
    outer = [(x, y) for x in (300.0, 700.0) for y in (230.0, 330.0)]
    pts = np.array(mid + side + outer)
    # The milling study numbers its middle-line points 2, 5, 8, 22, 15, 19, 20, 21.
    mid_labels = ["2", "5", "8", "22", "15", "19", "20", "21"]
    rest = [str(k) for k in range(1, 23) if str(k) not in mid_labels]
    return pts, mid_labels + rest


def _shape_um(p: np.ndarray, d: str) -> np.ndarray:
    """The example's static error along ``d`` (µm at kj = 525 N/mm), growing toward the border."""
    q = (p - _SENSOR_CENTRE) / 300.0
    rho2 = np.sum(q**2, axis=-1)
    return 350.0 * (1 + 2.5 * rho2) if d == "y" else 420.0 * (1 + 2.0 * rho2 + 0.5 * q[..., 1])


def _sensor_model_maps(kj: float) -> tuple[rd.SensorMap, ...]:
    """The model's dense maps in x and y over an illustrative reachable region."""
    gx = np.linspace(250.0, 750.0, 41)
    gy = np.linspace(100.0, 520.0, 36)
    grid = np.array([(x, y) for y in gy for x in gx])
    reach = np.hypot(*(grid - _SENSOR_CENTRE).T) < 280.0  # an illustrative reachable region
    return tuple(
        rd.SensorMap(d, grid, np.where(reach, _shape_um(grid, d) * 525.0 / kj, np.nan)) for d in ("x", "y")
    )


def _sensor_steps(rng, err: np.ndarray, ok: np.ndarray):
    """Each recording's plateaus (0, 10, ..., 50 kgf) and the least-squares line through them:
    the loads (N), the plateaus' displacements (µm), the slopes and intercepts."""
    loads_n = np.arange(6) * 98.1
    steps = np.where(ok[:, None], err[:, None] * loads_n / 490.5, np.nan)
    steps = steps + rng.normal(0.0, 0.8, steps.shape) + rng.normal(0.0, 1.5, (len(err), 1))
    slope, icpt = np.full(len(err), np.nan), np.full(len(err), np.nan)
    for k in np.flatnonzero(ok):
        slope[k], icpt[k] = np.polyfit(loads_n, steps[k], 1)
    return loads_n, steps, slope, icpt
