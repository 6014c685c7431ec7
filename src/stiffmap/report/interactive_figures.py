"""The report's interactive figures: plotly, embedded in the HTML page.

One function per figure; each takes a :class:`~stiffmap.report.data.ReportData`
and returns a ``plotly.graph_objects.Figure`` (or None when the data it draws
are absent). The same figures, static, are drawn with matplotlib for papers by
:mod:`~stiffmap.report.static_figures`; what both draw is computed once in
:mod:`~stiffmap.report.figure_data`. NaN values (failed positions, missing
repeats, unreachable model points) are drawn as gaps or with their own symbol,
never as numbers.
"""

from __future__ import annotations

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from ..textfmt import fmt
from .data import ReportData
from .figure_data import (
    calibration_panels,
    compliance_ellipsoids,
    det_markers,
    error_axis,
    finite_range,
    interpolate_measured,
    load_directions,
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
    sensor_lines,
    truth_entries,
    view_names,
)

TEMPLATE = "plotly_white"
SEQ = "Viridis"
DIV = "RdBu_r"
FAILED = "#9a9a9a"
BAD = "#d62728"
#: Colours of the displacement components dx, dy, dz, and of the boards drawn on an image.
COMPONENT_COLOURS = ("#1f77b4", "#2ca02c", "#9467bd")
BOARD_COLOURS = ("#ff7f0e", "#17becf", "#e377c2")


def position_axis(n: int) -> dict:
    """A position axis (positions 1..n): ticks on whole numbers only."""
    return dict(tickmode="linear", tick0=1, dtick=position_dtick(n), range=[0.5, n + 0.5])


def _hover_positions(data: ReportData) -> list[str]:
    m = data.measured
    labels = position_labels(data)
    out = []
    for i, lab in enumerate(labels):
        if m.status[i] != "ok":
            out.append(f"{lab}<br>failed: {m.messages[i]}")
            continue
        s = (
            f"{lab}<br>det K = {fmt(m.det[i], 4)} (N/mm)³"
            f"<br>smallest principal = {fmt(m.min_principal[i], 4)} N/mm"
        )
        if m.flags[i]:
            s += "<br>flags: " + "; ".join(m.flags[i])
        out.append(s)
    return out


# --------------------------------------------------------------------------- stiffness map
def stiffness_map_3d(data: ReportData) -> go.Figure | None:
    """3D markers at the positions, diameter proportional to det K (the reference's Fig. 12)."""
    dm = det_markers(data)
    if dm is None:
        return None
    m = data.measured
    p, det = m.positions, m.det
    hover = np.array(_hover_positions(data))

    def markers(sel: np.ndarray, name: str, marker: dict) -> go.Scatter3d:
        return go.Scatter3d(
            x=p[sel, 0],
            y=p[sel, 1],
            z=p[sel, 2],
            mode="markers",
            name=name,
            marker=marker,
            text=hover[sel],
            hovertemplate="%{text}<extra></extra>",
        )

    fig = go.Figure()
    good = dm.good
    fig.add_trace(
        markers(
            good,
            "det K > 0 (diameter ∝ det K)",
            dict(
                size=dm.diameters[good],
                sizemode="diameter",
                color=det[good],
                colorscale=SEQ,
                cmin=dm.lo,
                cmax=dm.hi,
                opacity=0.9,
                line=dict(width=0),
                colorbar=dict(title=dict(text="det K<br>(N/mm)³"), len=0.75),
            ),
        )
    )
    if dm.bad.any():
        fig.add_trace(markers(dm.bad, "det K ≤ 0 (flagged)", dict(size=7, symbol="x", color=BAD)))
    if dm.failed.any():
        fig.add_trace(markers(dm.failed, "failed", dict(size=5, symbol="diamond-open", color=FAILED)))
    fig.update_layout(
        template=TEMPLATE,
        height=560,
        margin=dict(l=0, r=0, t=30, b=0),
        title=dict(text="Stiffness map: marker diameter ∝ det K", x=0.01),
        legend=dict(x=0.01, y=0.95),
        scene=dict(
            xaxis_title="x (mm)",
            yaxis_title="y (mm)",
            zaxis_title="z (mm)",
            aspectmode="data",
            camera=dict(eye=dict(x=1.5, y=-1.6, z=0.9)),
        ),
    )
    return fig


def _xy_axes(fig: go.Figure, rows: int) -> None:
    """Label the x axes of the bottom row and the y axes of the first column; equal scales."""
    fig.update_xaxes(title_text="x (mm)", row=rows)
    fig.update_yaxes(title_text="y (mm)", col=1)
    fig.update_yaxes(scaleanchor="x", scaleratio=1)


def _identity_line(lo: float, hi: float, name: str, **kw) -> go.Scatter:
    """The dashed line y = x from ``lo`` to ``hi`` (measured against modelled or true)."""
    return go.Scatter(
        x=[lo, hi],
        y=[lo, hi],
        mode="lines",
        line=dict(color="#888", dash="dash"),
        name=name,
        hoverinfo="skip",
        **kw,
    )


def _colorbar(row: int, rows: int, span: int, title: str) -> dict:
    """A colour bar beside ``span`` rows starting at ``row`` (0-based, from the top)."""
    h = 1.0 / rows
    return dict(title=dict(text=title), y=1 - (row + span / 2) * h, len=span * h * 0.9, yanchor="middle")


def plane_maps(data: ReportData, quantity: str) -> go.Figure | None:
    """One panel per z plane of ``quantity`` ("min_principal" or "det").

    Rows: measured; with a model, the model (its dense map when given) and the
    residual measured - modelled.
    """
    pv = plane_map_values(data, quantity)
    if pv is None:
        return None
    m = data.measured
    title, unit, planes, model = pv.title, pv.unit, pv.planes, pv.model
    rows = 3 if model is not None else 1
    names = ["measured"] + (["model", "measured − model"] if model is not None else [])
    titles = [f"{r}, z = {z:g} mm" for r in names for z in planes]
    fig = make_subplots(
        rows=rows,
        cols=len(planes),
        subplot_titles=titles,
        shared_xaxes=True,
        shared_yaxes=True,
        horizontal_spacing=0.03,
        vertical_spacing=0.09 if rows > 1 else 0.0,
    )
    hover = np.array(_hover_positions(data))
    for c, z in enumerate(planes, start=1):
        sel = on_plane(m.positions[:, 2], z)
        ok = sel & m.ok
        _measured_plane(fig, m, pv, hover, sel, c)
        if model is None:
            continue
        _model_plane(fig, m.positions, pv, z, sel, c)
        fig.add_trace(
            go.Scatter(
                x=m.positions[ok, 0],
                y=m.positions[ok, 1],
                mode="markers",
                marker=dict(symbol="square", size=24, color=pv.residuals[ok], coloraxis="coloraxis2"),
                customdata=pv.residuals[ok],
                text=hover[ok],
                hovertemplate=f"%{{text}}<br>measured − model = %{{customdata:.4g}} {unit}<extra></extra>",
                showlegend=False,
            ),
            row=3,
            col=c,
        )
    span = 2 if model is not None else 1
    layout = dict(
        template=TEMPLATE,
        height=330 * rows + 40,
        margin=dict(l=60, r=20, t=60, b=50),
        title=dict(text=f"{title} ({unit}) per plane", x=0.01),
        coloraxis=dict(colorscale=SEQ, cmin=pv.lo, cmax=pv.hi, colorbar=_colorbar(0, rows, span, unit)),
    )
    if model is not None:
        r = pv.residual_range
        layout["coloraxis2"] = dict(colorscale=DIV, cmin=-r, cmax=r, colorbar=_colorbar(2, rows, 1, unit))
    fig.update_layout(**layout)
    _xy_axes(fig, rows)
    return fig


def _measured_plane(fig: go.Figure, m, pv, hover: np.ndarray, sel: np.ndarray, c: int) -> None:
    """Row 1 of :func:`plane_maps` at column ``c``: the measured positions of the plane ``sel``
    (squares, flagged outlined) and its failed ones (crosses)."""
    ok = sel & m.ok
    flagged = pv.flagged & ok
    fig.add_trace(
        go.Scatter(
            x=m.positions[ok, 0],
            y=m.positions[ok, 1],
            mode="markers",
            marker=dict(
                symbol="square",
                size=24,
                color=pv.values[ok],
                coloraxis="coloraxis",
                line=dict(color=np.where(flagged[ok], BAD, "white"), width=np.where(flagged[ok], 3, 1)),
            ),
            text=hover[ok],
            hovertemplate="%{text}<extra></extra>",
            showlegend=False,
        ),
        row=1,
        col=c,
    )
    if (sel & ~m.ok).any():
        f = sel & ~m.ok
        fig.add_trace(
            go.Scatter(
                x=m.positions[f, 0],
                y=m.positions[f, 1],
                mode="markers",
                marker=dict(symbol="x-thin", size=16, line=dict(color=FAILED, width=2)),
                text=hover[f],
                hovertemplate="%{text}<extra></extra>",
                showlegend=False,
            ),
            row=1,
            col=c,
        )


def _model_plane(fig: go.Figure, positions: np.ndarray, pv, z: float, sel: np.ndarray, c: int) -> None:
    """Row 2 of :func:`plane_maps` at column ``c``: the model's dense map of the plane with the
    measured positions as dots, or without one the model at the measured positions."""
    title, unit = pv.title, pv.unit
    grid = model_plane_grid(pv.model, pv.map_values, z)
    if grid is not None:
        xs, ys, Z = grid
        fig.add_trace(
            go.Heatmap(
                x=xs,
                y=ys,
                z=Z,
                coloraxis="coloraxis",
                hovertemplate=(f"x %{{x}} mm, y %{{y}} mm<br>{title} %{{z:.4g}} {unit}<extra>model</extra>"),
            ),
            row=2,
            col=c,
        )
        fig.add_trace(
            go.Scatter(
                x=positions[sel, 0],
                y=positions[sel, 1],
                mode="markers",
                marker=dict(size=4, color="black"),
                hoverinfo="skip",
                showlegend=False,
            ),
            row=2,
            col=c,
        )
        return
    mv = pv.model_values
    fig.add_trace(
        go.Scatter(
            x=positions[sel, 0],
            y=positions[sel, 1],
            mode="markers",
            marker=dict(symbol="square", size=24, color=mv[sel], coloraxis="coloraxis"),
            customdata=mv[sel],
            hovertemplate=f"model {title} %{{customdata:.4g}} {unit}<extra></extra>",
            showlegend=False,
        ),
        row=2,
        col=c,
    )


# --------------------------------------------------------------------------- loads
def loads_overview(data: ReportData) -> go.Figure | None:
    """Mean displacement norm (mm) per position (columns) and load case (rows); click to inspect."""
    if data.loads is None:
        return None
    mean, std, cnt = data.loads.summary()
    labels = position_labels(data)
    n, L = mean.shape
    custom = np.dstack([std.T, cnt.T])
    fig = go.Figure(
        go.Heatmap(
            x=np.arange(1, n + 1),
            y=list(data.loads.labels),
            z=mean.T,
            customdata=custom,
            text=np.tile(np.array(labels), (L, 1)),
            colorscale=SEQ,
            colorbar=dict(title=dict(text="mm")),
            hovertemplate=(
                "%{text}<br>load %{y}<br>mean %{z:.4g} mm ± %{customdata[0]:.2g} "
                "(n = %{customdata[1]})<extra></extra>"
            ),
            xgap=1,
            ygap=1,
        )
    )
    fig.update_layout(
        template=TEMPLATE,
        height=120 + 26 * L,
        margin=dict(l=110, r=20, t=40, b=50),
        title=dict(text="Mean displacement norm (mm) per position and load case — click a cell", x=0.01),
        xaxis=dict(title="position", tickfont=dict(size=9), **position_axis(n)),
        yaxis=dict(autorange="reversed"),
    )
    return fig


def loads_payload(data: ReportData) -> dict | None:
    """The per-position data the page's selector draws from (Figs. 9-10 of the reference)."""
    if data.loads is None:
        return None
    ld = data.loads
    mean, std, cnt = ld.summary()
    out = {
        "labels": list(ld.labels),
        "forces": ld.forces,
        "positions": position_labels(data),
        "status": list(data.measured.status),
        "messages": list(data.measured.messages),
        "norms": ld.norms,
        "mean": mean,
        "std": std,
        "count": cnt,
    }
    if ld.vectors is not None and ld.residuals is not None:
        # To the nanometre: the page carries every repeat's vector (a few characters each).
        out["vectors"] = np.round(ld.vectors, 6)
        out["residuals"] = np.round(ld.residuals, 6)
        out["directions"] = [
            {"label": g.label, "loads": g.loads, "magnitude": g.magnitude} for g in load_directions(ld.forces)
        ]
    return out


# --------------------------------------------------------------------------- model / truth
def model_scatter(data: ReportData) -> go.Figure | None:
    """Measured against modelled det K and smallest principal stiffness, with the identity line."""
    if data.model is None:
        return None
    m = data.measured
    fig = make_subplots(
        rows=1,
        cols=2,
        subplot_titles=["det K ((N/mm)³)", "smallest principal stiffness (N/mm)"],
        horizontal_spacing=0.1,
    )
    labels = np.array(position_labels(data))
    for c, q in enumerate(("det", "min_principal"), start=1):
        mm = model_vs_measured(data, q)
        ok = mm.rows
        fig.add_trace(_identity_line(mm.lo, mm.hi, "measured = model", showlegend=c == 1), row=1, col=c)
        fig.add_trace(
            go.Scatter(
                x=mm.model,
                y=mm.measured,
                mode="markers",
                marker=dict(
                    size=8,
                    color=m.positions[ok, 2],
                    colorscale="Cividis",
                    showscale=c == 2,
                    colorbar=dict(title=dict(text="z (mm)")),
                ),
                text=labels[ok],
                hovertemplate="%{text}<br>model %{x:.4g}<br>measured %{y:.4g}<extra></extra>",
                name="positions",
                showlegend=False,
            ),
            row=1,
            col=c,
        )
        fig.update_xaxes(title_text="model", row=1, col=c)
        fig.update_yaxes(title_text="measured", row=1, col=c)
    fig.update_layout(
        template=TEMPLATE, height=420, margin=dict(l=60, r=20, t=50, b=50), legend=dict(x=0.01, y=1.0)
    )
    return fig


def orientation_figure(data: ReportData) -> go.Figure | None:
    """A platform that turns: the model's smallest principal stiffnesses over roll and pitch at
    one position (translational, of the hung loads' K, and rotational), the orientations
    measured there as markers coloured by their identified K on the same scale."""
    om = None if data.model is None else data.model.orientations
    if om is None:
        return None
    at = ", ".join(f"{v:g}" for v in om.position)
    fig = make_subplots(
        rows=1,
        cols=2,
        subplot_titles=[
            "smallest principal stiffness (N/mm), model and measured",
            "smallest rotational stiffness (N·mm/rad), model",
        ],
        horizontal_spacing=0.14,
    )
    meas = om.measured_min_principal
    lo, hi = finite_range(om.min_principal, meas)
    for c, (z, title) in enumerate(((om.min_principal, "N/mm"), (om.min_principal_rot, "N·mm/rad")), start=1):
        bar = dict(title=dict(text=title), x=0.43 if c == 1 else 1.0, len=0.9)
        fig.add_trace(
            go.Heatmap(
                x=om.roll_deg, y=om.pitch_deg, z=z, colorscale="Viridis", colorbar=bar,
                zmin=lo if c == 1 else None, zmax=hi if c == 1 else None,
                hovertemplate="roll %{x:.3g}°, pitch %{y:.3g}°<br>model %{z:.4g}<extra></extra>",
            ),
            row=1, col=c,
        )  # fmt: skip
        fig.update_xaxes(title_text="roll (deg)", row=1, col=c)
        fig.update_yaxes(title_text="pitch (deg)", row=1, col=c)
    ok = np.isfinite(meas)
    fig.add_trace(
        go.Scatter(
            x=om.measured_rpy_deg[:, 0], y=om.measured_rpy_deg[:, 1], mode="markers",
            marker=dict(size=13, color=np.where(ok, meas, lo), colorscale="Viridis", cmin=lo, cmax=hi,
                        line=dict(color=np.where(ok, "white", "red"), width=2), symbol="square"),
            text=[fmt(v) if np.isfinite(v) else "failed" for v in meas],
            hovertemplate="measured at roll %{x:.3g}°, pitch %{y:.3g}°: %{text} N/mm<extra></extra>",
            name="measured", showlegend=False,
        ),
        row=1, col=1,
    )  # fmt: skip
    fig.update_layout(
        template=TEMPLATE, height=440, margin=dict(l=60, r=20, t=70, b=50),
        title=dict(text=f"Over orientations at ({at}) mm, yaw {om.yaw_deg:g}°", font=dict(size=13)),
    )  # fmt: skip
    return fig


def truth_figure(data: ReportData) -> go.Figure | None:
    """Recovered against true K entries, and the relative Frobenius error per position."""
    te = truth_entries(data)
    if te is None:
        return None
    m, err = data.measured, te.error
    fig = make_subplots(
        rows=1,
        cols=2,
        column_widths=[0.4, 0.6],
        subplot_titles=[
            "K entries: recovered vs true (N/mm), ± 1 standard error",
            "relative Frobenius error |K − K_true| / |K_true| (%)",
        ],
        horizontal_spacing=0.08,
    )
    tv, rv, sv, diag = te.true, te.recovered, te.std, te.diagonal
    fig.add_trace(_identity_line(te.lo, te.hi, "recovered = true"), row=1, col=1)
    for mask, name, color in ((diag, "diagonal", "#1f77b4"), (~diag, "off-diagonal", "#ff7f0e")):
        fig.add_trace(
            go.Scatter(
                x=tv[mask],
                y=rv[mask],
                error_y=dict(type="data", array=np.nan_to_num(sv[mask]), visible=True, thickness=1, width=0),
                mode="markers",
                marker=dict(size=5, color=color),
                name=name,
                hovertemplate="true %{x:.4g}<br>recovered %{y:.4g}<extra>" + name + "</extra>",
            ),
            row=1,
            col=1,
        )
    labels = np.array(position_labels(data))
    # A dot per position on a linear axis from zero: the dots' heights compare (a bar from
    # an arbitrary baseline of a log axis would not). An outlier sits at the top, with its value.
    pct = 100 * err
    top, above = error_axis(pct)
    x = np.arange(1, m.n + 1)
    inside = ~above
    fig.add_trace(
        go.Scatter(
            x=x[inside],
            y=pct[inside],
            mode="markers",
            marker=dict(size=8, color=np.where(te.flagged, BAD, "#2ca02c")[inside]),
            hovertext=labels[inside],
            hovertemplate="%{hovertext}<br>%{y:.3g} %<extra></extra>",
            name="relative error",
            showlegend=False,
        ),
        row=1,
        col=2,
    )
    if above.any():
        fig.add_trace(
            go.Scatter(
                x=x[above], y=np.full(int(above.sum()), 0.97 * top), mode="markers+text",
                marker=dict(size=10, symbol="triangle-up", color=BAD),
                text=[f"{v:.3g} %" for v in pct[above]], textposition="middle left",
                hovertext=labels[above], customdata=pct[above],
                hovertemplate="%{hovertext}<br>%{customdata:.3g} % (beyond the axis)<extra></extra>",
                name="beyond the axis", showlegend=False,
            ),
            row=1, col=2,
        )  # fmt: skip
    if te.worst is not None and not above[te.worst]:
        w = te.worst
        fig.add_annotation(
            x=w + 1, y=float(pct[w]), text=f"worst {pct[w]:.3g} % (P{w + 1})", showarrow=True, row=1, col=2
        )
    fig.update_xaxes(title_text="true (N/mm)", row=1, col=1)
    fig.update_yaxes(title_text="recovered (N/mm)", row=1, col=1)
    fig.update_xaxes(title_text="position", row=1, col=2, **position_axis(m.n))
    fig.update_yaxes(title_text="%", type="linear", range=[0.0, top], row=1, col=2)
    fig.update_layout(
        template=TEMPLATE, height=440, margin=dict(l=60, r=20, t=50, b=50), legend=dict(x=0.01, y=1.0)
    )
    return fig


# --------------------------------------------------------------------------- calibration
def calibration_figure(data: ReportData) -> go.Figure | None:
    """Per-view RMS reprojection error and, when given, every corner's residual (px)."""
    cp = calibration_panels(data)
    if cp is None:
        return None
    views, rms, used = cp.views, cp.rms, cp.used
    has_res = cp.residuals is not None
    cols = cp.panels
    titles = (
        (["RMS reprojection error per view (px)"] if views else [])
        + (
            [
                "corner residuals, observed − projected (px)"
                if cols < 3
                else "residuals, observed − projected (px)"
            ]
            if has_res
            else []
        )
        + (["coverage: corners in the image (px)"] if cp.corners is not None else [])
    )
    widths = {1: None, 2: [0.6, 0.4], 3: [0.4, 0.27, 0.33]}[cols]
    fig = make_subplots(rows=1, cols=cols, subplot_titles=titles, column_widths=widths)
    col = 1
    if views:
        names = view_names(views)
        reason = [str(v.get("reason", "")) for v in views]
        fig.add_trace(
            go.Bar(
                x=names,
                y=np.where(used, rms, np.nan),
                marker_color="#1f77b4",
                name="used",
                hovertemplate="%{x}<br>%{y:.3g} px<extra></extra>",
            ),
            row=1,
            col=col,
        )
        if (~used).any():
            fig.add_trace(
                go.Scatter(
                    x=[n for n, u in zip(names, used, strict=True) if not u],
                    y=[0] * int((~used).sum()),
                    mode="markers",
                    marker=dict(symbol="x", size=10, color=BAD),
                    text=[r for r, u in zip(reason, used, strict=True) if not u],
                    hovertemplate="%{x}: not used, %{text}<extra></extra>",
                    name="not used",
                ),
                row=1,
                col=col,
            )
        fig.update_yaxes(title_text="px", row=1, col=col)
        col += 1
    if has_res:
        r = cp.residuals
        scatter = go.Scattergl if len(r) > 5000 else go.Scatter  # WebGL for many corners
        fig.add_trace(
            scatter(
                x=r[:, 0],
                y=r[:, 1],
                mode="markers",
                marker=dict(size=3, color="#444", opacity=0.5),
                name="corners",
                hovertemplate="(%{x:.3f}, %{y:.3f}) px<extra></extra>",
            ),
            row=1,
            col=col,
        )
        a = cp.residual_range
        fig.update_xaxes(title_text="Δu (px)", range=[-a * 1.05, a * 1.05], row=1, col=col)
        fig.update_yaxes(title_text="Δv (px)", range=[-a * 1.05, a * 1.05], row=1, col=col)
        col += 1
    if cp.corners is not None:
        _coverage_panel(fig, cp.corners, col)
    fig.update_layout(template=TEMPLATE, height=400, margin=dict(l=60, r=20, t=50, b=80), showlegend=False)
    return fig


def _coverage_panel(fig: go.Figure, cc, col: int) -> None:
    """Corners per cell of the image (heat map; empty cells: no corner there) and the corners."""
    counts, xe, ye = cc.coverage()
    w, h = cc.size
    fig.add_trace(
        go.Heatmap(
            x=0.5 * (xe[1:] + xe[:-1]),
            y=0.5 * (ye[1:] + ye[:-1]),
            z=counts,
            colorscale="Blues",
            showscale=False,
            hovertemplate="%{z:.0f} corners around (%{x:.0f}, %{y:.0f}) px<extra></extra>",
        ),
        row=1,
        col=col,
    )
    fig.add_trace(
        go.Scattergl(
            x=cc.corners[:, 0],
            y=cc.corners[:, 1],
            mode="markers",
            marker=dict(size=2, color="#d95f02", opacity=0.6),
            customdata=cc.view + 1,
            hovertemplate="view %{customdata}: (%{x:.1f}, %{y:.1f}) px<extra></extra>",
        ),
        row=1,
        col=col,
    )
    axis = "x" if col == 1 else f"x{col}"
    fig.update_xaxes(title_text="x (px)", range=[0, w], constrain="domain", row=1, col=col)
    fig.update_yaxes(title_text="y (px)", range=[h, 0], scaleanchor=axis, row=1, col=col)


# --------------------------------------------------------------------------- sensor
def sensor_maps(data: ReportData) -> go.Figure | None:
    """Static-error maps measured beside modelled, one row per direction (the milling study's Figs. 13-14)."""
    s = data.sensor
    if s is None:
        return None
    dirs = s.directions
    rows = len(dirs)
    has_model = sensor_has_model(data)
    cols = 2 if has_model else 1
    titles = []
    for d in dirs:
        titles.append(f"measured, load along {d} (linear between points)")
        if has_model:
            titles.append(f"model, load along {d}")
    fig = make_subplots(
        rows=rows,
        cols=cols,
        subplot_titles=titles,
        shared_xaxes=True,
        shared_yaxes=True,
        horizontal_spacing=0.06,
        vertical_spacing=0.1,
    )
    layout: dict = {}
    for r, d in enumerate(dirs, start=1):
        sd = sensor_direction(data, d)
        ax = "coloraxis" if r == 1 else f"coloraxis{r}"
        layout[ax] = dict(
            colorscale=SEQ, cmin=sd.lo, cmax=sd.hi, colorbar=_colorbar(r - 1, rows, 1, f"µm ({d})")
        )
        _measured_sensor_map(fig, s, sd, ax, r)
        if has_model:
            _model_sensor_map(fig, s, sd, ax, r)
    fig.update_layout(
        template=TEMPLATE,
        height=380 * rows + 40,
        margin=dict(l=60, r=20, t=60, b=50),
        title=dict(text=f"Static error (µm) at {s.reference_load_n:g} N", x=0.01),
        **layout,
    )
    _xy_axes(fig, rows)
    return fig


def _measured_sensor_map(fig: go.Figure, s, sd, ax: str, r: int) -> None:
    """Row ``r``, column 1 of :func:`sensor_maps`: the measured static error interpolated between
    the points (inside their hull), the points labelled, and crosses where none was measured."""
    idx, p, e = sd.rows, sd.points, sd.error_um
    grid = interpolate_measured(p, e)
    if grid is not None:
        fig.add_trace(
            go.Heatmap(
                x=grid.xs,
                y=grid.ys,
                z=grid.Z,
                coloraxis=ax,
                hovertemplate="x %{x:.0f} mm, y %{y:.0f} mm<br>%{z:.4g} µm (interpolated)<extra></extra>",
            ),
            row=r,
            col=1,
        )
    ok = np.isfinite(e)
    hover = [
        f"point {s.labels[i]} ({s.points[i, 0]:g}, {s.points[i, 1]:g}) mm<br>"
        f"{fmt(s.error_um[i], 4)} ± {fmt(s.error_std_um[i], 2)} µm"
        for i in idx
    ]
    fig.add_trace(
        go.Scatter(
            x=p[ok, 0],
            y=p[ok, 1],
            mode="markers+text",
            text=[s.labels[i] for i in idx[ok]],
            textposition="top center",
            textfont=dict(size=9),
            marker=dict(size=11, color=e[ok], coloraxis=ax, line=dict(color="black", width=1)),
            hovertext=np.array(hover)[ok],
            hovertemplate="%{hovertext}<extra>measured</extra>",
            showlegend=False,
        ),
        row=r,
        col=1,
    )
    if (~ok).any():
        fig.add_trace(
            go.Scatter(
                x=p[~ok, 0],
                y=p[~ok, 1],
                mode="markers",
                marker=dict(symbol="x-thin", size=14, line=dict(color=BAD, width=2)),
                hovertext=[f"point {s.labels[i]}: no measurement" for i in idx[~ok]],
                hovertemplate="%{hovertext}<extra></extra>",
                showlegend=False,
            ),
            row=r,
            col=1,
        )


def _model_sensor_map(fig: go.Figure, s, sd, ax: str, r: int) -> None:
    """Row ``r``, column 2 of :func:`sensor_maps`: the model's dense map (or its values at the
    points interpolated) and its values at the points."""
    idx, p, model, g = sd.rows, sd.points, sd.model_um, sd.dense_grid
    if g is not None:
        fig.add_trace(
            go.Heatmap(
                x=g[0],
                y=g[1],
                z=g[2],
                coloraxis=ax,
                hovertemplate="x %{x:.0f} mm, y %{y:.0f} mm<br>%{z:.4g} µm<extra>model</extra>",
            ),
            row=r,
            col=2,
        )
    elif model is not None:
        mg = interpolate_measured(p, model)
        if mg is not None:
            fig.add_trace(go.Heatmap(x=mg.xs, y=mg.ys, z=mg.Z, coloraxis=ax, hoverinfo="skip"), row=r, col=2)
    if model is not None:
        fig.add_trace(
            go.Scatter(
                x=p[:, 0],
                y=p[:, 1],
                mode="markers",
                marker=dict(size=8, color=model, coloraxis=ax, line=dict(color="black", width=1)),
                hovertext=[
                    f"point {s.labels[i]}: model {fmt(v, 4)} µm" for i, v in zip(idx, model, strict=True)
                ],
                hovertemplate="%{hovertext}<extra></extra>",
                showlegend=False,
            ),
            row=r,
            col=2,
        )


def sensor_line(data: ReportData) -> go.Figure | None:
    """Measured (± std) and modelled static error point by point along the middle line (Figs. 11-12)."""
    s = data.sensor
    if s is None:
        return None
    dirs = s.directions
    where = "along the middle line" if s.middle_line is not None else "at every point"
    fig = make_subplots(
        rows=1,
        cols=len(dirs),
        subplot_titles=[f"load along {d}, {where}" for d in dirs],
        horizontal_spacing=0.08,
    )
    for c, d in enumerate(dirs, start=1):
        rows = middle_line_order(data, d)
        x = [f"{s.labels[i]} (y {s.points[i, 1]:g})" for i in rows]
        fig.add_trace(
            go.Scatter(
                x=x,
                y=s.error_um[rows],
                error_y=dict(type="data", array=np.nan_to_num(s.error_std_um[rows]), visible=True),
                mode="markers",
                marker=dict(size=9, color="#1f77b4"),
                name="measured ± std",
                showlegend=c == 1,
                hovertemplate="point %{x}<br>%{y:.4g} µm<extra>measured</extra>",
            ),
            row=1,
            col=c,
        )
        if s.model_error_um is not None:
            fig.add_trace(
                go.Scatter(
                    x=x,
                    y=s.model_error_um[rows],
                    mode="lines+markers",
                    line=dict(color="#ff7f0e"),
                    marker=dict(symbol="diamond", size=8),
                    name="model",
                    showlegend=c == 1,
                    hovertemplate="point %{x}<br>%{y:.4g} µm<extra>model</extra>",
                ),
                row=1,
                col=c,
            )
        fig.update_xaxes(title_text="point (ordered by y, mm)", type="category", row=1, col=c)
        fig.update_yaxes(title_text="static error (µm)", rangemode="tozero", row=1, col=c)
    fig.update_layout(
        template=TEMPLATE, height=420, margin=dict(l=60, r=20, t=50, b=90), legend=dict(x=0.01, y=1.0)
    )
    return fig


# --------------------------------------------------------------------------- reviewer's diagnostics
def residual_figure(data: ReportData) -> go.Figure | None:
    """RMS per position of each component of d − C F (µm), dots on an axis from zero."""
    rr = residual_rms(data)
    if rr is None or not np.isfinite(rr).any():
        return None
    n = rr.shape[0]
    labels = np.array(position_labels(data))
    fig = go.Figure()
    for c, (name, color) in enumerate(zip(("dx", "dy", "dz"), COMPONENT_COLOURS, strict=True)):
        fig.add_trace(
            go.Scatter(
                x=np.arange(1, n + 1) + (c - 1) * 0.15,
                y=1e3 * rr[:, c],
                mode="markers",
                marker=dict(size=7, color=color),
                name=name,
                text=labels,
                hovertemplate="%{text}<br>" + name + " residual RMS %{y:.3g} µm<extra></extra>",
            )
        )
    top = 1.15 * 1e3 * float(np.nanmax(rr))
    fig.update_layout(
        template=TEMPLATE,
        height=330,
        margin=dict(l=60, r=20, t=50, b=50),
        title=dict(text="What K leaves of the displacements: RMS of d − C·F per position (µm)", x=0.01),
        xaxis=dict(title="position", **position_axis(n)),
        yaxis=dict(title="µm", range=[0.0, top]),
        legend=dict(orientation="h", x=0.7, y=1.12),
    )
    return fig


def ellipsoid_figure(data: ReportData) -> go.Figure | None:
    """Compliance ellipsoids at the positions: principal directions, semi-axes ∝ 1/k (mm/N)."""
    el = compliance_ellipsoids(data)
    if el is None:
        return None
    labels = position_labels(data)
    kmin = el.stiffness[:, 0]
    lo, hi = float(kmin.min()), float(kmin.max())
    hi = hi if hi > lo else lo + 1.0
    V, faces, owner = el.triangles()
    # One mesh for every ellipsoid; what its hover shows rides on each vertex as a few float32
    # numbers (position, principal stiffnesses, softest direction), not text: a page stays small.
    soft = el.directions[:, :, 0]
    info = np.column_stack([el.index + 1, el.stiffness, soft])[owner].astype(np.float32)
    fig = go.Figure(
        go.Mesh3d(
            x=V[:, 0].astype(np.float32), y=V[:, 1].astype(np.float32), z=V[:, 2].astype(np.float32),
            i=faces[:, 0].astype(np.int32), j=faces[:, 1].astype(np.int32), k=faces[:, 2].astype(np.int32),
            intensity=kmin[owner].astype(np.float32), cmin=lo, cmax=hi, colorscale=SEQ, customdata=info,
            colorbar=dict(title=dict(text="smallest<br>principal<br>N/mm")), name="compliance ellipsoids",
            hovertemplate=(
                "P%{customdata[0]:.0f}<br>principal stiffnesses %{customdata[1]:.4g}, %{customdata[2]:.4g}, "
                "%{customdata[3]:.4g} N/mm<br>softest along (%{customdata[4]:+.2f}, %{customdata[5]:+.2f}, "
                "%{customdata[6]:+.2f})<extra></extra>"
            ),
        )
    )  # fmt: skip
    if el.skipped.size:
        p = data.measured.positions[el.skipped]
        fig.add_trace(
            go.Scatter3d(
                x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers", marker=dict(symbol="x", size=8, color=BAD),
                text=[labels[i] for i in el.skipped], name="K not positive definite",
                hovertemplate="%{text}: K not positive definite (no ellipsoid)<extra></extra>",
            )
        )  # fmt: skip
    fig.update_layout(
        template=TEMPLATE,
        height=560,
        margin=dict(l=0, r=0, t=40, b=0),
        title=dict(
            text="Compliance ellipsoids: principal directions, semi-axes ∝ 1/k (drag to rotate)", x=0.01
        ),
        scene=dict(xaxis_title="x (mm)", yaxis_title="y (mm)", zaxis_title="z (mm)", aspectmode="data"),
    )
    return fig


def board_image_figure(data: ReportData) -> go.Figure | None:
    """One image of the campaign with the boards' corners where their measured poses put them."""
    bi = data.board_image
    if bi is None:
        return None
    w, h = (float(v) for v in bi.image_size)
    fig = go.Figure()
    boards = list(dict.fromkeys(bi.corner_board))
    for k, name in enumerate(boards):
        sel = np.array([b == name for b in bi.corner_board])
        fig.add_trace(
            go.Scatter(
                x=bi.corners_px[sel, 0],
                y=bi.corners_px[sel, 1],
                mode="markers",
                marker=dict(size=5, color=BOARD_COLOURS[k % len(BOARD_COLOURS)], symbol="circle-open"),
                name=name,
                hovertemplate=name + ": (%{x:.1f}, %{y:.1f}) px<extra></extra>",
            )
        )
    fig.add_layout_image(
        dict(
            source="data:image/png;base64," + bi.png_base64,
            xref="x", yref="y", x=0, y=0, sizex=w, sizey=h, sizing="stretch", layer="below",
        )
    )  # fmt: skip
    fig.update_layout(
        template=TEMPLATE,
        height=min(640, int(60 + 880 * h / w)),
        margin=dict(l=50, r=20, t=50, b=40),
        title=dict(text=f"{bi.name}: the boards where their measured poses put them", x=0.01),
        xaxis=dict(range=[0, w], showgrid=False, title="x (px)", constrain="domain"),
        yaxis=dict(range=[h, 0], showgrid=False, title="y (px)", scaleanchor="x"),
        legend=dict(orientation="h", x=0.0, y=-0.08),
    )
    return fig


def sensor_linearity(data: ReportData) -> go.Figure | None:
    """Each recording's plateaus against the load with the fitted line, and what the line leaves."""
    lin = sensor_lines(data)
    if lin is None:
        return None
    s = data.sensor
    fig = make_subplots(
        rows=1,
        cols=2,
        column_widths=[0.6, 0.4],
        subplot_titles=["displacement on each plateau (µm) against the load (N)", "plateau − line (µm)"],
    )
    buttons = []
    for k, i in enumerate(lin.rows):
        show = k == 0
        dots = dict(mode="markers", visible=show)
        fig.add_trace(
            go.Scatter(x=lin.load[k], y=lin.displacement[k], marker=dict(size=8, color="#1f77b4"), **dots,
                       hovertemplate="%{x:.4g} N: %{y:.5g} µm<extra>plateau</extra>"),
            row=1, col=1,
        )  # fmt: skip
        fig.add_trace(
            go.Scatter(x=lin.line_load[k], y=lin.line_um[k], mode="lines", line=dict(color=BAD),
                       visible=show, hoverinfo="skip"),
            row=1, col=1,
        )  # fmt: skip
        fig.add_trace(
            go.Scatter(x=lin.load[k], y=lin.residual[k], marker=dict(size=8, color="#444"), **dots,
                       hovertemplate="%{x:.4g} N: %{y:.3g} µm<extra>plateau − line</extra>"),
            row=1, col=2,
        )  # fmt: skip
        vis = [False] * (3 * len(lin.rows))
        vis[3 * k : 3 * k + 3] = [True] * 3
        label = f"{s.labels[i]} ({s.direction[i]})"
        buttons.append(
            dict(label=label, method="update", args=[{"visible": vis}, {"title.text": _lin_title(s, i)}])
        )
    fig.update_xaxes(title_text="load (N)", rangemode="tozero", row=1, col=1)
    fig.update_yaxes(title_text="µm", row=1, col=1)
    fig.update_xaxes(title_text="load (N)", rangemode="tozero", row=1, col=2)
    fig.update_yaxes(title_text="µm", zeroline=True, row=1, col=2)
    fig.update_layout(
        template=TEMPLATE,
        height=420,
        margin=dict(l=60, r=20, t=90, b=50),
        showlegend=False,
        title=dict(text=_lin_title(s, int(lin.rows[0])), x=0.01, y=0.97),
        updatemenus=[dict(buttons=buttons, x=1.0, xanchor="right", y=1.22, yanchor="top", active=0)],
    )
    return fig


def _lin_title(s, i: int) -> str:
    x, y = s.points[i]
    return f"recording {s.labels[i]}: point ({x:g}, {y:g}) mm, load along {s.direction[i]}"
