"""The self-contained HTML page: one inline plotly.js, figures as JSON, tables, no network.

Every text that comes from the data (campaign name, notes, flags, messages,
file names) is escaped. Figures are embedded as strict JSON in
``<script type="application/json">`` blocks and drawn by a small script that
sets ``window.stiffmapReady = true`` once every figure is rendered (the
browser test waits for it). The page requests nothing: no CDN, no fonts, no
images (the PNGs beside it are linked, not loaded).
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence

import numpy as np

from ..io import to_jsonable
from ..textfmt import fmt, fmt_pm
from ._assets import CSS, JS
from .data import ReportData
from .figure_data import position_labels
from .interactive_figures import (
    board_image_figure,
    calibration_figure,
    ellipsoid_figure,
    loads_overview,
    loads_payload,
    model_scatter,
    orientation_figure,
    plane_maps,
    residual_figure,
    sensor_line,
    sensor_linearity,
    sensor_maps,
    stiffness_map_3d,
    truth_figure,
)

__all__ = ["build_html", "figure_json"]


def _reject_constant(name: str):
    raise ValueError(f"non-standard JSON constant {name} in a figure")


def figure_json(fig) -> str:
    """Strict JSON of a plotly figure, safe inside a ``<script>`` element."""
    import plotly.io as pio

    text = pio.to_json(fig, validate=False, pretty=False, remove_uids=True)
    json.loads(text, parse_constant=_reject_constant)  # NaN/Infinity would break JSON.parse
    return text.replace("<", "\\u003c")


def _json_block(obj) -> str:
    return json.dumps(to_jsonable(obj), allow_nan=False, separators=(",", ":")).replace("<", "\\u003c")


def _e(s) -> str:
    return html.escape(str(s), quote=True)


def _matrix(K: np.ndarray, S: np.ndarray) -> str:
    rows = []
    for i in range(3):
        cells = []
        for j in range(3):
            v = f"{K[i, j]:+.4g}"
            if np.isfinite(S[i, j]):
                v += f" ±{S[i, j]:.2g}"
            cells.append(f"{v:>17}")
        rows.append(" ".join(cells))
    return "\n".join(rows)


def _k_table(data: ReportData) -> str:
    m = data.measured
    err = data.truth_error
    labels = position_labels(data)
    head = (
        "<tr><th>#</th><th class=l>position x, y, z (mm)</th><th class=l>status</th>"
        "<th class=l>K (N/mm), ± 1 standard error</th><th>det K<br>(N/mm)³</th>"
        "<th>principal stiffnesses<br>(N/mm)</th>"
        + ("<th>model det K<br>(N/mm)³</th>" if data.model is not None else "")
        + ("<th>error vs true<br>(%)</th>" if err is not None else "")
        + "<th class='l flags'>flags</th></tr>"
    )
    body = []
    for i in range(m.n):
        x, y, z = m.positions[i]
        pos = f"{x:.5g}, {y:.5g}, {z:.5g}"
        if m.status[i] != "ok":
            ncols = 4 + (data.model is not None) + (err is not None)
            body.append(
                f"<tr class=failed><td>{i + 1}</td><td class=l>{_e(pos)}</td><td class=l>failed</td>"
                f"<td class=l colspan={ncols}>{_e(m.messages[i])}</td></tr>"
            )
            continue
        cls = " class=flagged" if m.flags[i] else ""
        ev = ", ".join(fmt(v, 4) for v in m.eigenvalues[i])
        cells = [
            f"<td>{i + 1}</td>",
            f"<td class=l title='{_e(labels[i])}'>{_e(pos)}</td>",
            "<td class=l>ok</td>",
            f"<td class='l m'>{_e(_matrix(m.K[i], m.K_std[i]))}</td>",
            f"<td>{fmt(m.det[i], 4)}</td>",
            f"<td>{ev}</td>",
        ]
        if data.model is not None:
            cells.append(f"<td>{fmt(data.model.det[i], 4)}</td>")
        if err is not None:
            cells.append(f"<td>{fmt(100 * err[i], 3)}</td>")
        flags = "<br>".join(_e(f) for f in m.flags[i]) or "—"
        cells.append(f"<td class='l flags'>{flags}</td>")
        body.append(f"<tr{cls}>{''.join(cells)}</tr>")
    return f"<table class=k><thead>{head}</thead><tbody>{''.join(body)}</tbody></table>"


def _params_table(params) -> str:
    rows = "".join(
        f"<tr><td class=l>{_e(p.name)}</td><td>{_e(fmt_pm(p.value, p.std, 5, omit_unknown_std=True))}</td>"
        f"<td class=l>{_e(p.unit)}</td>"
        f"<td class=l>{'fitted' if np.isfinite(p.std) else 'fixed'}</td></tr>"
        for p in params
    )
    return (
        "<table><thead><tr><th class=l>parameter</th><th>value ± 1 standard error</th><th class=l>unit</th>"
        f"<th class=l></th></tr></thead><tbody>{rows}</tbody></table>"
    )


def _camera_table(cam: dict) -> str:
    std = cam.get("std") or {}
    rows = []
    for k in ("fx", "fy", "cx", "cy"):
        s = std.get(k) if isinstance(std, dict) else None
        s = s if isinstance(s, (int, float)) else np.nan
        rows.append((k + " (px)", fmt_pm(cam[k], s, 6, omit_unknown_std=True)))
    dist = cam.get("dist", [])
    sd = std.get("dist") if isinstance(std, dict) else None
    names = ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4"]
    if cam.get("model") == "fisheye":  # OpenCV's fisheye model: k1..k4 of the angle off axis
        names = ["k1", "k2", "k3", "k4"]
        rows.append(("lens model", "fisheye (OpenCV's: equidistant, k1..k4)"))
    for j, v in enumerate(dist):
        s = sd[j] if isinstance(sd, list) and j < len(sd) and isinstance(sd[j], (int, float)) else np.nan
        rows.append((names[j], fmt_pm(v, s, 4, omit_unknown_std=True)))
    if "image_size" in cam:
        rows.append(("image size (px)", " × ".join(str(v) for v in cam["image_size"])))
    if cam.get("rms_px") is not None:
        rows.append(("RMS reprojection error (px)", fmt(cam["rms_px"], 3)))
    if cam.get("residual_std_px") is not None:
        rows.append(("residual std x, y (px)", ", ".join(fmt(v, 3) for v in cam["residual_std_px"])))
    views = cam.get("views") or []
    if views:
        used = sum(1 for v in views if v.get("used", True))
        rows.append(("views used", f"{used} of {len(views)}"))
    return (
        "<table class=kv>"
        + "".join(f"<tr><td>{_e(a)}</td><td>{_e(b)}</td></tr>" for a, b in rows)
        + "</table>"
    )


def _rig_table(cameras: tuple[dict, ...]) -> str:
    """Per camera of a rig: its pose relative to the first, its intrinsics and its residuals."""
    if not cameras:
        return ""
    rows = []
    for c in cameras:
        cam = c["camera"]
        T = np.asarray(c.get("cam2rig", np.eye(4)), dtype=float)
        angle = float(np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1.0, 1.0))))
        rms = c.get("rms_px")
        p95 = c.get("rms_px_p95")
        rows.append(
            (
                c["name"],
                f"{np.linalg.norm(T[:3, 3]):.1f}",
                f"{angle:.1f}",
                f"{cam['fx']:.1f}, {cam['fy']:.1f}",
                f"{cam['cx']:.1f}, {cam['cy']:.1f}",
                f"{c.get('seen', 0)} of {c.get('sets', 0)}",
                "—" if rms is None else f"{rms:.3f}" + ("" if p95 is None else f" ({p95:.3f})"),
            )
        )
    head = (
        "camera",
        "distance from the first (mm)",
        "angle to the first (°)",
        "fx, fy (px)",
        "cx, cy (px)",
        "image sets with a board",
        "median RMS (95th percentile), px",
    )
    errors = [f"{c['name']}: {e}" for c in cameras for e in (c.get("errors") or [])[:2]]
    out = (
        "<p>Several cameras: each image set was measured by every camera that saw a board, its "
        "poses fused in the rig frame (the first camera's).</p><table><thead><tr>"
        + "".join(f"<th>{_e(h)}</th>" for h in head)
        + "</tr></thead><tbody>"
        + "".join("<tr>" + "".join(f"<td>{_e(v)}</td>" for v in r) + "</tr>" for r in rows)
        + "</tbody></table>"
    )
    if errors:
        out += "<p>" + _e("Some of the cameras' problems: " + "; ".join(errors)) + "</p>"
    return out


def _calibration_share(share: np.ndarray | None) -> str:
    """A sentence on how much of K's uncertainty the calibration's error makes."""
    if share is None:
        return ""
    known = share[np.all(np.isfinite(share), axis=1)]
    if known.size == 0:
        text = (
            "K's uncertainty leaves out the calibration's: this camera file gives no covariance "
            "or standard deviations."
        )
    else:
        text = (
            "The calibration's share of the variance of k11, k22, k33: median "
            f"{100 * np.median(known):.1f} %, largest {100 * known.max():.1f} % over {len(known)} "
            "positions. It is included in every K standard error, as an error common to all "
            "positions (it does not average out)."
        )
    return f"<p>{_e(text)}</p>"


def _sensor_table(data: ReportData) -> str:
    s = data.sensor
    has_model = s.model_error_um is not None
    head = (
        "<tr><th class=l>point</th><th>x (mm)</th><th>y (mm)</th><th class=l>direction</th>"
        "<th>measured (µm)</th>"
        + ("<th>model (µm)</th><th>measured − model (µm)</th>" if has_model else "")
        + "</tr>"
    )
    body = []
    for i in range(s.m):
        failed = not np.isfinite(s.error_um[i])
        measured = fmt_pm(s.error_um[i], s.error_std_um[i], 4, omit_unknown_std=True)
        cells = [
            f"<td class=l>{_e(s.labels[i])}</td><td>{s.points[i, 0]:g}</td><td>{s.points[i, 1]:g}</td>",
            f"<td class=l>{_e(s.direction[i])}</td>",
            f"<td>{'no measurement' if failed else _e(measured)}</td>",
        ]
        if has_model:
            cells.append(f"<td>{fmt(s.model_error_um[i], 4)}</td>")
            cells.append(f"<td>{fmt(s.error_um[i] - s.model_error_um[i], 3)}</td>")
        body.append(f"<tr{' class=failed' if failed else ''}>{''.join(cells)}</tr>")
    return f"<table><thead>{head}</thead><tbody>{''.join(body)}</tbody></table>"


def _summary(data: ReportData) -> str:
    pills = []
    m = data.measured
    if m is not None:
        ok = m.ok
        nflag = sum(1 for i in range(m.n) if ok[i] and m.flags[i])
        pills.append(f"<span class=pill>{int(ok.sum())} of {m.n} positions with a stiffness</span>")
        if (~ok).any():
            pills.append(f"<span class='pill bad'>{int((~ok).sum())} failed</span>")
        if nflag:
            pills.append(f"<span class='pill warn'>{nflag} flagged</span>")
        if ok.any():
            pills.append(
                f"<span class=pill>det K {fmt(np.nanmin(m.det[ok]), 4)} … "
                f"{fmt(np.nanmax(m.det[ok]), 4)} (N/mm)³</span>"
                f"<span class=pill>smallest principal {fmt(np.nanmin(m.min_principal[ok]), 4)} … "
                f"{fmt(np.nanmax(m.min_principal[ok]), 4)} N/mm</span>"
            )
        if data.loads is not None:
            L, R = data.loads.norms.shape[1:]
            pills.append(f"<span class=pill>{L} load cases × {R} repeats</span>")
    err = data.truth_error
    if err is not None and np.isfinite(err).any():
        pills.append(f"<span class=pill>worst relative K error vs true: {100 * np.nanmax(err):.3g} %</span>")
    s = data.sensor
    if s is not None:
        ok = np.isfinite(s.error_um)
        pills.append(f"<span class=pill>{int(ok.sum())} of {s.m} point-direction measurements</span>")
        if (~ok).any():
            pills.append(f"<span class='pill bad'>{int((~ok).sum())} failed</span>")
        for p in s.parameters:
            value = fmt_pm(p.value, p.std, 4, omit_unknown_std=True)
            pills.append(f"<span class=pill>{_e(p.name)} = {_e(value)} {_e(p.unit)}</span>")
    if data.failures:
        pills.append(f"<span class='pill bad'>{len(data.failures)} failure(s) listed below</span>")
    return "".join(pills)


class _Page:
    """The report page's sections (id, title, html) and the figures their divs show (div id, json),
    in page order."""

    def __init__(self) -> None:
        self.sections: list[tuple[str, str, str]] = []
        self.figures: list[tuple[str, str]] = []

    def fig_div(self, fid: str, fig, note: str = "") -> str:
        if fig is None:
            return ""
        self.figures.append((fid, figure_json(fig)))
        return f"<div class=fig id='{fid}'></div>" + (f"<p class=note>{note}</p>" if note else "")


def build_html(data: ReportData, png_names: Sequence[str] = ()) -> str:
    """The report page.

    Parameters
    ----------
    data : ReportData
    png_names : sequence of str
        PNG files written beside the page (linked in its last section).
    """
    page = _Page()
    page.sections.append(("summary", "Summary", f"<p>{_summary(data)}</p>"))
    if data.setup:
        rows = "".join(f"<tr><td>{_e(x.what)}</td><td>{_e(x.value)}</td></tr>" for x in data.setup)
        page.sections.append(("setup", "Set-up", f"<table class=kv>{rows}</table>"))
    if data.board_image is not None:
        _image_section(page, data)
    if data.measured is not None:
        _map_sections(page, data)
    if data.loads is not None:
        _loads_section(page, data)
    if data.model is not None:
        _model_section(page, data)
    _truth_and_calibration_sections(page, data)
    if data.measured is not None:
        _k_table_section(page, data)
    if data.sensor is not None:
        _sensor_section(page, data)
    _closing_sections(page, data, png_names)
    return _page_html(data.campaign, page)


def _image_section(page: _Page, data: ReportData) -> None:
    """An image with the boards' corners projected from its poses."""
    body = page.fig_div(
        "fig-board-image",
        board_image_figure(data),
        "The boards' inner corners projected from the poses measured in this image through the "
        "calibrated camera: where they fall on the printed corners, detection, pose and camera agree. "
        "The image is shown reduced"
        + (f" {data.board_image.scale:g} times" if data.board_image.scale > 1 else "")
        + "; coordinates are those of the full image.",
    )
    page.sections.append(("image", "An image and its boards", body))


def _map_sections(page: _Page, data: ReportData) -> None:
    """The stiffness map (3-D and per plane) and the principal directions."""
    body = page.fig_div(
        "fig-map3d",
        stiffness_map_3d(data),
        "Marker diameter proportional to det K, as in the reference study's stiffness map (Fig. 12), "
        "floored at 3 px so that soft positions stay visible; colour also shows det K. "
        "Red crosses: det K ≤ 0 (flagged); grey diamonds: failed positions. Drag to rotate.",
    )
    body += page.fig_div("fig-planes-minp", plane_maps(data, "min_principal"))
    body += page.fig_div(
        "fig-planes-det",
        plane_maps(data, "det"),
        "One panel per z plane; squares are measured positions "
        "(red outline: flagged; grey cross: failed)."
        + (
            " With a model: its map (dense where given, black dots are the measured positions) "
            "and the residual measured − model on a diverging scale."
            if data.model is not None
            else ""
        ),
    )
    page.sections.append(("map", "Stiffness map", body))
    body = page.fig_div(
        "fig-ellipsoids",
        ellipsoid_figure(data),
        "At each position, the compliance ellipsoid of the symmetric part of K: its axes are the "
        "principal directions, its semi-axes the principal compliances 1/k (mm/N), on one scale for "
        "every position (the longest, the softest direction anywhere, fills about half the spacing "
        "of the positions). Colour: the smallest principal stiffness. Hover for the principal "
        "stiffnesses and directions; a red cross marks a K that is not positive definite.",
    )
    if body:
        page.sections.append(("principal", "Principal directions", body))


def _loads_section(page: _Page, data: ReportData) -> None:
    """The load cases per position: overview, detail, linearity and residuals."""
    body = page.fig_div("fig-loads-overview", loads_overview(data))
    body += (
        "<p><label class=ctl>position <select id=pos-select></select></label>"
        "<label class=ctl>load case <select id=load-select></select></label></p>"
        "<div class=fig id=fig-load-detail></div>"
        "<p class=note>Left: displacement norm of each load case, mean ± std (n − 1) over the repeats, "
        "with every repeat as a dot (the reference's Fig. 10). "
        "Right: the repeats of the chosen load case "
        "with their mean (red line) ± std (band) (its Fig. 9).</p>"
    )
    if data.loads.vectors is not None and data.loads.residuals is not None:
        body += (
            "<div class=fig id=fig-linearity></div>"
            "<p class=note>Linearity: for each direction in which loads were applied, every component "
            "of the measured displacement against the force's magnitude (a dot per repeat), and the line "
            "the identified K predicts (d = C·F, C = K⁻¹, with the common offset when the position was "
            "measured against one reference). A linear, elastic robot puts the dots on the lines.</p>"
            "<div class=fig id=fig-residual-detail></div>"
        )
        body += page.fig_div(
            "fig-residuals",
            residual_figure(data),
            "The residuals of d = C·F: what K does not explain (noise, non-linearity, a load case "
            "mislabelled). Above: the chosen position's, per load case. Here: their RMS per position "
            "and component, on an axis from zero.",
        )
    body += f"<script type='application/json' id=loads-data>{_json_block(loads_payload(data))}</script>"
    page.sections.append(("loads", "Load cases per position", body))


def _model_section(page: _Page, data: ReportData) -> None:
    """The model's parameters, its scatter against the measurements and its orientations."""
    mod = data.model
    body = f"<p><b>{_e(mod.name)}</b></p>" + _params_table(mod.parameters)
    body += "".join(f"<p class=note>Fit: {_e(n)}</p>" for n in mod.notes)
    body += page.fig_div(
        "fig-model",
        model_scatter(data),
        "Per-plane maps of the model and residuals are under Stiffness map.",
    )
    body += page.fig_div(
        "fig-orientations",
        orientation_figure(data),
        "A platform that turns: the model with its tool point at one measured position (where the "
        "campaign measured the most orientations) and the platform turned over roll and pitch. Left: "
        "the smallest principal stiffness of the K the loads hung at loads.point_mm see, what the "
        "campaign identifies (squares: measured there, on the same colour scale); right: the smallest "
        "a pure moment sees (K_rot). The maps over positions are at the orientation the campaign's "
        "positions share (level when they do not share one).",
    )
    page.sections.append(("model", "Measured and modelled", body))


def _truth_and_calibration_sections(page: _Page, data: ReportData) -> None:
    """The test-bed's truth and the camera calibration, when the report has them."""
    if data.truth is not None:
        body = page.fig_div(
            "fig-truth",
            truth_figure(data),
            "Virtual test-bed: the identified K against the ground truth. Red bars: flagged positions.",
        )
        page.sections.append(("truth", "Recovered vs true", body))
    if data.calibration is not None:
        body = _rig_table(data.calibration.cameras)
        body += _camera_table(data.calibration.camera)
        body += _calibration_share(data.calibration.k_share)
        body += page.fig_div("fig-calibration", calibration_figure(data))
        page.sections.append(("calibration", "Camera calibration", body))


def _k_table_section(page: _Page, data: ReportData) -> None:
    """Every K, in a table that can show only the flagged or failed positions."""
    body = (
        "<p><label class=ctl><input type=checkbox id=only-flagged> "
        "show only flagged or failed positions</label></p>"
        f"<div class=tablewrap>{_k_table(data)}</div>"
        "<p class=note>K in the base frame, N/mm; ± is one standard error of each entry. "
        "Principal stiffnesses are the eigenvalues of the symmetric part (K + Kᵀ)/2, ascending. "
        "Flagged rows are highlighted.</p>"
    )
    page.sections.append(("table", "Every K", body))


def _sensor_section(page: _Page, data: ReportData) -> None:
    """The sensor recordings' static error: maps, line, linearity and table."""
    s = data.sensor
    body = ""
    if s.parameters:
        body += f"<p><b>{_e(s.model_name or 'model')}</b></p>" + _params_table(s.parameters)
    body += page.fig_div(
        "fig-sensor-maps",
        sensor_maps(data),
        "Left: measured static error, linearly interpolated between the measured points (circles, "
        "labelled) inside their convex hull — no extrapolation. "
        "Right: the model (dense map where given). "
        "Same colour scale in a row. After the milling study's Figs. 13-14.",
    )
    body += page.fig_div("fig-sensor-line", sensor_line(data), "After the milling study's Figs. 11-12.")
    body += page.fig_div(
        "fig-sensor-linearity",
        sensor_linearity(data),
        "Linearity of each recording (choose it above the figure): the displacement on every static "
        "plateau of the stepped load against the load, the line fitted to them (its value at the "
        "reference load is the static error) and what the line leaves of each plateau.",
    )
    body += f"<div class=tablewrap>{_sensor_table(data)}</div>"
    page.sections.append(("sensor", "Static error", body))


def _closing_sections(page: _Page, data: ReportData, png_names: Sequence[str]) -> None:
    """The failures and the PNG files beside the page, when there are any."""
    if data.failures:
        items = "".join(f"<li><b>{_e(f.item)}</b>: {_e(f.message)}</li>" for f in data.failures)
        page.sections.append(("failures", "Failures", f"<ul class=fail>{items}</ul>"))
    if png_names:
        items = "".join(f"<li><a href='{_e(n)}'>{_e(n)}</a></li>" for n in png_names)
        page.sections.append(
            (
                "figures",
                "Figures for papers",
                f"<p class=note>PNG files beside this page:</p><ul>{items}</ul>",
            )
        )


def _page_html(c, page: _Page) -> str:
    """The whole page: header, navigation, the sections, plotly and the figures' data."""
    from plotly.offline import get_plotlyjs

    sections, figures = page.sections, page.figures
    nav = "".join(f"<a href='#{sid}'>{_e(t)}</a>" for sid, t, _ in sections)
    main = "".join(f"<section id='{sid}'><h2>{_e(t)}</h2>{b}</section>" for sid, t, b in sections)
    figs = "".join(f"<script type='application/json' data-figure='{fid}'>{j}</script>" for fid, j in figures)
    meta = [f"{c.kind} campaign", f"stiffmap {c.version}"]
    if c.date:
        meta.append(c.date)
    if c.campaign_dir:
        meta.append(c.campaign_dir)
    units = (
        "Units: positions and displacements mm, forces N, stiffness N/mm, det K (N/mm)³, "
        "static error µm, image residuals px; positions and K in the robot base frame."
    )
    notes = f"<p>{_e(c.notes)}</p>" if c.notes else ""
    return (
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
        "<meta name=viewport content='width=device-width, initial-scale=1'>"
        f"<title>{_e(c.name)} — stiffmap report</title><style>{CSS}</style></head><body>"
        f"<header><h1>{_e(c.name)}</h1><p>{_e(' · '.join(meta))}</p><p>{_e(units)}</p>{notes}</header>"
        f"<nav>{nav}</nav><main>{main}</main>"
        f"<script>{get_plotlyjs()}</script>{figs}<script>{JS}</script></body></html>\n"
    )
