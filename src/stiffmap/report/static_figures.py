"""The report's static figures for papers: matplotlib, written as PNG files.

One function per figure; each returns a ``matplotlib.figure.Figure`` (or None
when its data are absent). The same figures, interactive, are drawn with plotly
for the HTML page by :mod:`~stiffmap.report.interactive_figures`; what both draw
is computed once in :mod:`~stiffmap.report.figure_data`. No pyplot: figures are
built on the object interface and rendered by :func:`png_bytes`, so nothing
global changes and no display is needed.
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import FormatStrFormatter, MultipleLocator

from .data import ReportData
from .figure_data import (
    QUANTITIES,
    calibration_panels,
    det_markers,
    error_axis,
    finite_range,
    middle_line_order,
    model_plane_grid,
    model_vs_measured,
    on_plane,
    plane_map_values,
    position_dtick,
    position_labels,
    residual_rms,
    sensor_direction,
    sensor_has_model,
    spans_plane,
    truth_entries,
    view_names,
)

__all__ = [
    "png_bytes",
    "stiffness_map_3d",
    "plane_maps",
    "loads_small_multiples",
    "model_scatter",
    "truth_figure",
    "calibration_figure",
    "residual_figure",
    "sensor_maps",
    "sensor_line",
    "ALL_FIGURES",
]

SEQ = "viridis"
DIV = "RdBu_r"
BAD = "#d62728"
FAILED = "#9a9a9a"
DPI = 150


def _position_axis(ax, n: int) -> None:
    """Positions 1..n on the x axis: ticks on whole numbers only."""
    ax.set_xlim(0.5, n + 0.5)
    ax.xaxis.set_major_locator(MultipleLocator(position_dtick(n)))
    ax.xaxis.set_major_formatter(FormatStrFormatter("%d"))


def png_bytes(fig: Figure, dpi: int = DPI) -> bytes:
    """PNG of a figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    return buf.getvalue()


def stiffness_map_3d(data: ReportData) -> Figure | None:
    """Markers at the positions, diameter proportional to det K (the reference study's Fig. 12)."""
    dm = det_markers(data)
    if dm is None:
        return None
    m = data.measured
    fig = Figure(figsize=(7.5, 6.5))
    ax = fig.add_subplot(projection="3d")
    p = m.positions
    good, bad, f = dm.good, dm.bad, dm.failed
    sc = ax.scatter(
        p[good, 0], p[good, 1], p[good, 2], s=dm.diameters[good] ** 2, c=m.det[good], cmap=SEQ,
        vmin=dm.lo, vmax=dm.hi, alpha=0.85, edgecolors="k", linewidths=0.3,
        label="det K > 0 (diameter ∝ det K)",
    )  # fmt: skip
    if bad.any():
        ax.scatter(p[bad, 0], p[bad, 1], p[bad, 2], s=40, marker="x", c=BAD, label="det K ≤ 0 (flagged)")
    if f.any():
        ax.scatter(
            p[f, 0], p[f, 1], p[f, 2], s=20, marker="D", facecolors="none", edgecolors=FAILED, label="failed"
        )
    fig.colorbar(sc, ax=ax, shrink=0.6, pad=0.1, label="det K (N/mm)³")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title("Stiffness map: marker diameter ∝ det K")
    leg = ax.legend(loc="upper left", fontsize=8)
    leg.legend_handles[0].set_sizes([60.0])  # the legend's marker, not the largest det
    ax.view_init(elev=22, azim=-60)
    return fig


def plane_maps(data: ReportData, quantity: str) -> Figure | None:
    """One panel per z plane: measured [, model and residual] of ``quantity``."""
    pv = plane_map_values(data, quantity)
    if pv is None:
        return None
    m = data.measured
    title, unit, vals, planes, model = pv.title, pv.unit, pv.values, pv.planes, pv.model
    rows = 3 if model is not None else 1
    mv, res, rr = pv.model_values, pv.residuals, pv.residual_range
    norm = Normalize(pv.lo, pv.hi)
    fig = Figure(figsize=(4.0 * len(planes) + 1.2, 3.9 * rows), layout="constrained")
    axes = np.atleast_2d(fig.subplots(rows, len(planes), sharex=True, sharey=True, squeeze=False))
    flagged = pv.flagged & m.ok
    im = imr = None
    for c, z in enumerate(planes):
        sel = on_plane(m.positions[:, 2], z)
        ok = sel & m.ok
        ax = axes[0, c]
        im = ax.scatter(
            m.positions[ok, 0], m.positions[ok, 1], c=vals[ok], cmap=SEQ, norm=norm, marker="s", s=420,
            edgecolors=np.where(flagged[ok], BAD, "white"), linewidths=np.where(flagged[ok], 2.5, 0.5),
        )  # fmt: skip
        for x, y, v in zip(m.positions[ok, 0], m.positions[ok, 1], vals[ok], strict=True):
            ax.annotate(f"{v:.3g}", (x, y), ha="center", va="center", fontsize=6.5, color="white")
        f = sel & ~m.ok
        if f.any():
            ax.scatter(m.positions[f, 0], m.positions[f, 1], marker="x", s=120, c=FAILED, linewidths=2)
        ax.set_title(f"measured, z = {z:g} mm", fontsize=10)
        if model is None:
            continue
        ax = axes[1, c]
        grid = model_plane_grid(model, pv.map_values, z)
        if grid is not None:
            ax.pcolormesh(grid[0], grid[1], grid[2], cmap=SEQ, norm=norm, shading="nearest")
            ax.plot(m.positions[sel, 0], m.positions[sel, 1], "k.", ms=3)
        else:
            ax.scatter(
                m.positions[sel, 0], m.positions[sel, 1], c=mv[sel], cmap=SEQ, norm=norm, marker="s", s=420
            )
        ax.set_title(f"model, z = {z:g} mm", fontsize=10)
        ax = axes[2, c]
        imr = ax.scatter(
            m.positions[ok, 0], m.positions[ok, 1], c=res[ok], cmap=DIV, vmin=-rr, vmax=rr, marker="s", s=420
        )
        ax.set_title(f"measured − model, z = {z:g} mm", fontsize=10)
    for ax in axes.ravel():
        ax.set_aspect("equal")
        ax.margins(0.12)
    for ax in axes[-1]:
        ax.set_xlabel("x (mm)")
    for ax in axes[:, 0]:
        ax.set_ylabel("y (mm)")
    fig.colorbar(im, ax=axes[: 2 if model is not None else 1].ravel().tolist(), label=f"{title} ({unit})")
    if imr is not None:
        fig.colorbar(imr, ax=axes[2].ravel().tolist(), label=f"residual ({unit})")
    fig.suptitle(f"{title} per plane")
    return fig


def loads_small_multiples(data: ReportData, ncols: int = 8) -> Figure | None:
    """Displacement norm per load case for every position (mean ± std bars, repeats as dots)."""
    if data.loads is None:
        return None
    ld = data.loads
    mean, std, _ = ld.summary()
    n, L, R = ld.norms.shape
    ncols = min(ncols, n)
    nrows = -(-n // ncols)
    h = 1.75 * nrows + 0.9
    fig = Figure(figsize=(2.1 * ncols, h))
    # Fixed margins: a layout engine costs seconds with dozens of panels.
    grid = dict(left=0.05, right=0.99, bottom=0.55 / h, top=1 - 0.75 / h, wspace=0.35, hspace=0.5)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False, gridspec_kw=grid).ravel())
    labels = position_labels(data)
    x = np.arange(L)
    off = np.linspace(-0.28, 0.28, R) if R > 1 else np.zeros(1)
    for i in range(n):
        ax = axes[i]
        ax.bar(
            x,
            np.nan_to_num(mean[i]),
            yerr=np.nan_to_num(std[i]),
            color="#9ecae1",
            ecolor="#2b5d8a",
            capsize=1.5,
            width=0.8,
        )
        xr = (x[:, None] + off[None, :]).ravel()
        yr = ld.norms[i].ravel()
        ax.plot(xr, yr, ".", ms=1.5, color="#08306b")
        ok = data.measured.status[i] == "ok"
        ax.set_title(labels[i] + ("" if ok else " FAILED"), fontsize=6.5, color="k" if ok else BAD)
        ax.tick_params(labelsize=6)
        ax.set_ylim(bottom=0)
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax in axes[(nrows - 1) * ncols : n]:
        ax.set_xticks(x, [str(k + 1) for k in x])
        ax.set_xlabel("load case", fontsize=7)
    for r in range(nrows):
        axes[r * ncols].set_ylabel("norm (mm)", fontsize=7)
    legend = ", ".join(f"{k + 1}: {lab}" for k, lab in enumerate(ld.labels))
    fig.suptitle(
        f"Displacement norm per load case, mean ± std over {R} repeats (dots)\nload cases {legend}",
        fontsize=9,
    )
    return fig


def model_scatter(data: ReportData) -> Figure | None:
    """Measured against modelled det K and smallest principal stiffness."""
    if data.model is None:
        return None
    m, mod = data.measured, data.model
    fig = Figure(figsize=(10, 4.4), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, q in zip(axes, ("det", "min_principal"), strict=True):
        title, unit = QUANTITIES[q]
        mm = model_vs_measured(data, q)
        ax.plot([mm.lo, mm.hi], [mm.lo, mm.hi], "--", color="#888", label="measured = model")
        sc = ax.scatter(mm.model, mm.measured, c=m.positions[mm.rows, 2], cmap="cividis", s=22)
        ax.set_xlabel(f"model {title} ({unit})")
        ax.set_ylabel(f"measured {title} ({unit})")
        ax.legend(loc="upper left", fontsize=8)
    fig.colorbar(sc, ax=axes.tolist(), label="z (mm)")
    fig.suptitle(f"Measured vs model: {mod.name}")
    return fig


def orientation_figure(data: ReportData) -> Figure | None:
    """A platform that turns: the model's smallest principal stiffnesses over roll and pitch at
    one position, the orientations measured there as squares on the translational panel's scale."""
    om = None if data.model is None else data.model.orientations
    if om is None:
        return None
    fig = Figure(figsize=(10, 4.4), layout="constrained")
    axes = fig.subplots(1, 2)
    meas = om.measured_min_principal
    lo, hi = finite_range(om.min_principal, meas)
    panels = (
        (om.min_principal, "smallest principal stiffness (N/mm)", Normalize(lo, hi)),
        (om.min_principal_rot, "smallest rotational stiffness (N*mm/rad)", None),
    )
    for ax, (z, title, norm) in zip(axes, panels, strict=True):
        im = ax.pcolormesh(om.roll_deg, om.pitch_deg, z, shading="nearest", cmap="viridis", norm=norm)
        fig.colorbar(im, ax=ax)
        ax.set_xlabel("roll (deg)")
        ax.set_ylabel("pitch (deg)")
        ax.set_title(title, fontsize=10)
    ok = np.isfinite(meas)
    rpy = om.measured_rpy_deg
    axes[0].scatter(rpy[ok, 0], rpy[ok, 1], c=meas[ok], cmap="viridis", norm=Normalize(lo, hi),
                    marker="s", s=70, edgecolors="white", label="measured")  # fmt: skip
    axes[0].scatter(rpy[~ok, 0], rpy[~ok, 1], marker="x", c="red", s=40, label="failed")
    at = ", ".join(f"{v:g}" for v in om.position)
    fig.suptitle(f"Model over orientations at ({at}) mm, yaw {om.yaw_deg:g} deg; squares: measured")
    return fig


def truth_figure(data: ReportData) -> Figure | None:
    """Recovered vs true K entries, and the relative Frobenius error per position."""
    te = truth_entries(data)
    if te is None:
        return None
    m, err = data.measured, te.error
    fig = Figure(figsize=(12, 4.4), layout="constrained")
    a1, a2 = fig.subplots(1, 2, width_ratios=[0.4, 0.6])
    tv, rv, sv, diag = te.true, te.recovered, te.std, te.diagonal
    a1.plot([te.lo, te.hi], [te.lo, te.hi], "--", color="#888", label="recovered = true")
    for mask, name, col in ((diag, "diagonal", "#1f77b4"), (~diag, "off-diagonal", "#ff7f0e")):
        a1.errorbar(
            tv[mask],
            rv[mask],
            yerr=np.nan_to_num(sv[mask]),
            fmt=".",
            ms=4,
            color=col,
            elinewidth=0.6,
            label=name,
        )
    a1.set_xlabel("true K entry (N/mm)")
    a1.set_ylabel("recovered K entry (N/mm)")
    a1.legend(fontsize=8)
    colors = np.where(te.flagged, BAD, "#2ca02c")
    pct = 100 * err
    top, above = error_axis(pct)
    ok = np.isfinite(pct) & ~above
    x = np.arange(1, m.n + 1)
    # A dot per position on a linear axis from zero (a bar from a log axis' baseline would
    # mislead); an outlier at the top, with its value.
    a2.scatter(x[ok], pct[ok], c=colors[ok], s=22, zorder=3)
    a2.scatter(x[above], np.full(int(above.sum()), 0.97 * top), marker="^", c=BAD, s=40, zorder=3)
    for i in np.flatnonzero(above):
        a2.annotate(f"{pct[i]:.3g} % ", (x[i], 0.97 * top), ha="right", va="center", fontsize=7, color=BAD)
    a2.set_ylim(0.0, top)
    _position_axis(a2, m.n)
    a2.set_xlabel("position")
    a2.set_ylabel("|K − K_true|_F / |K_true|_F (%)")
    if te.worst is not None:
        w = te.worst
        a2.set_title(f"worst {100 * err[w]:.3g} % at P{w + 1}", fontsize=10)
    for i in np.flatnonzero(~m.ok):
        a2.annotate(
            "failed",
            (i + 1, a2.get_ylim()[0]),
            rotation=90,
            fontsize=6,
            color=FAILED,
            ha="center",
            va="bottom",
        )
    fig.suptitle("Recovered vs true stiffness")
    return fig


def calibration_figure(data: ReportData) -> Figure | None:
    """Per-view RMS reprojection error, corner residuals (px) and the coverage of the image."""
    cp = calibration_panels(data)
    if cp is None:
        return None
    views, r, rms, used = cp.views, cp.residuals, cp.rms, cp.used
    fig = Figure(figsize=(5.5 * cp.panels, 4.2), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, cp.panels))
    k = 0
    if views:
        ax = axes[k]
        x = np.arange(len(views))
        ax.bar(x[used], rms[used], color="#1f77b4", label="used")
        if (~used).any():
            ax.plot(x[~used], np.zeros((~used).sum()), "x", color=BAD, ms=8, label="not used")
        ax.set_xticks(x, view_names(views), rotation=60, ha="right", fontsize=6)
        ax.set_ylabel("RMS reprojection error (px)")
        ax.legend(fontsize=8)
        k += 1
    if r is not None:
        ax = axes[k]
        ax.plot(r[:, 0], r[:, 1], ".", ms=2, alpha=0.5, color="#444")
        a = cp.residual_range * 1.05
        ax.set_xlim(-a, a)
        ax.set_ylim(-a, a)
        ax.set_aspect("equal")
        ax.set_xlabel("Δu (px)")
        ax.set_ylabel("Δv (px)")
        ax.set_title("corner residuals, observed − projected", fontsize=10)
        k += 1
    if cp.corners is not None:
        ax = axes[k]
        counts, xe, ye = cp.corners.coverage()
        ax.pcolormesh(xe, ye, np.where(counts > 0, counts, np.nan), cmap="Blues")
        ax.plot(cp.corners.corners[:, 0], cp.corners.corners[:, 1], ".", ms=1, color="#d95f02", alpha=0.6)
        w, h = cp.corners.size
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_aspect("equal")
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
        ax.set_title("coverage: corners in the image", fontsize=10)
    fig.suptitle("Camera calibration residuals")
    return fig


def residual_figure(data: ReportData) -> Figure | None:
    """RMS per position of each component of d − C F (µm), dots on an axis from zero."""
    rr = residual_rms(data)
    if rr is None or not np.isfinite(rr).any():
        return None
    n = rr.shape[0]
    fig = Figure(figsize=(max(6.0, 0.18 * n + 3), 3.6), layout="constrained")
    ax = fig.subplots()
    colours = ("#1f77b4", "#2ca02c", "#9467bd")
    for c, (name, color) in enumerate(zip(("dx", "dy", "dz"), colours, strict=True)):
        ax.plot(np.arange(1, n + 1) + (c - 1) * 0.15, 1e3 * rr[:, c], "o", ms=4, color=color, label=name)
    ax.set_ylim(0.0, 1.15 * 1e3 * float(np.nanmax(rr)))
    _position_axis(ax, n)
    ax.set_xlabel("position")
    ax.set_ylabel("RMS of d − C·F (µm)")
    ax.set_title("What K leaves of the displacements, per position and component", fontsize=10)
    ax.legend(fontsize=8, ncols=3)
    return fig


def sensor_maps(data: ReportData) -> Figure | None:
    """Static-error maps, measured beside modelled, one row per direction (milling study, Figs. 13-14)."""
    s = data.sensor
    if s is None:
        return None
    dirs = s.directions
    has_model = sensor_has_model(data)
    cols = 2 if has_model else 1
    fig = Figure(figsize=(5.2 * cols + 1, 4.4 * len(dirs)), layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(dirs), cols, sharex=True, sharey=True, squeeze=False))
    for r, d in enumerate(dirs):
        sd = sensor_direction(data, d)
        idx, p, e, model, g = sd.rows, sd.points, sd.error_um, sd.model_um, sd.dense_grid
        norm = Normalize(sd.lo, sd.hi)
        ok = np.isfinite(e)
        ax = axes[r, 0]
        if spans_plane(p[ok]):
            ax.tricontourf(p[ok, 0], p[ok, 1], e[ok], levels=14, cmap=SEQ, norm=norm)
        sc = ax.scatter(
            p[ok, 0], p[ok, 1], c=e[ok], cmap=SEQ, norm=norm, s=45, edgecolors="k", linewidths=0.6
        )
        for i in idx[ok]:
            ax.annotate(
                s.labels[i], s.points[i], xytext=(0, 5), textcoords="offset points", ha="center", fontsize=7
            )
        if (~ok).any():
            ax.scatter(p[~ok, 0], p[~ok, 1], marker="x", c=BAD, s=60, label="no measurement")
            ax.legend(fontsize=7, loc="lower right")
        ax.set_title(f"measured, load along {d}", fontsize=10)
        if has_model:
            ax = axes[r, 1]
            if g is not None:
                ax.pcolormesh(g[0], g[1], g[2], cmap=SEQ, norm=norm, shading="nearest")
            elif model is not None and spans_plane(p[np.isfinite(model)]):
                mk = np.isfinite(model)
                ax.tricontourf(p[mk, 0], p[mk, 1], model[mk], levels=14, cmap=SEQ, norm=norm)
            if model is not None:
                ax.scatter(
                    p[:, 0], p[:, 1], c=model, cmap=SEQ, norm=norm, s=30, edgecolors="k", linewidths=0.6
                )
            ax.set_title(f"model, load along {d}", fontsize=10)
        fig.colorbar(sc, ax=axes[r].tolist(), label=f"static error (µm), {d}")
    for ax in axes.ravel():
        ax.set_aspect("equal")
    for ax in axes[-1]:
        ax.set_xlabel("x (mm)")
    for ax in axes[:, 0]:
        ax.set_ylabel("y (mm)")
    fig.suptitle(f"Static error at {s.reference_load_n:g} N")
    return fig


def sensor_line(data: ReportData) -> Figure | None:
    """Measured (± std) and modelled static error along the middle line (Figs. 11-12 of the milling study)."""
    s = data.sensor
    if s is None:
        return None
    dirs = s.directions
    fig = Figure(figsize=(5.5 * len(dirs), 4.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(dirs)))
    for ax, d in zip(axes, dirs, strict=True):
        rows = middle_line_order(data, d)
        x = np.arange(len(rows))
        ax.errorbar(
            x,
            s.error_um[rows],
            yerr=np.nan_to_num(s.error_std_um[rows]),
            fmt="o",
            color="#1f77b4",
            capsize=3,
            label="measured ± std",
        )
        if s.model_error_um is not None:
            ax.plot(x, s.model_error_um[rows], "D-", color="#ff7f0e", ms=5, label="model")
        ax.set_xticks(x, [s.labels[i] for i in rows])
        ax.set_xlabel("point (ordered by y)")
        ax.set_ylabel("static error (µm)")
        ax.set_ylim(bottom=0)
        where = "middle line" if s.middle_line is not None else "all points"
        ax.set_title(f"load along {d}, {where}", fontsize=10)
        ax.legend(fontsize=8)
    fig.suptitle(f"Static error at {s.reference_load_n:g} N, measured vs model")
    return fig


#: (file name, builder) of every PNG the report writes when its data are present.
ALL_FIGURES = (
    ("stiffness_map_3d.png", stiffness_map_3d),
    ("planes_min_principal.png", lambda d: plane_maps(d, "min_principal")),
    ("planes_det.png", lambda d: plane_maps(d, "det")),
    ("loads_per_position.png", loads_small_multiples),
    ("residuals_per_position.png", residual_figure),
    ("model_vs_measured.png", model_scatter),
    ("model_over_orientations.png", orientation_figure),
    ("recovered_vs_true.png", truth_figure),
    ("calibration.png", calibration_figure),
    ("static_error_maps.png", sensor_maps),
    ("static_error_middle_line.png", sensor_line),
)
