"""Figures of ``stiffmap compensate``: the deflection along the program before and after, the placement map.

:func:`write_compensation_figures` writes, beside the corrected program, a PNG (matplotlib)
and a self-contained interactive page (plotly, in the style of the campaign report: one
inline plotly.js, no network):

- the deflection |delta| along the program's feed moves (path length, mm) uncompensated,
  and the distance of the deflected path from the programmed one after compensation (um),
  with the tolerance;
- with ``--place auto``: the search's map of the objective over the placements of the
  program's origin (mm, base frame; blank where a point would be out of reach or near a
  singularity), the chosen placement marked.
"""

from __future__ import annotations

import html
import os
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
from matplotlib.figure import Figure
from plotly.offline import get_plotlyjs
from plotly.subplots import make_subplots

from ..io import atomic_write_bytes, atomic_write_text
from ..machining.run import CompensationResult
from ._assets import CSS, JS
from .html import figure_json
from .static_figures import png_bytes

__all__ = ["write_compensation_figures", "compensation_png", "compensation_page"]

#: At most this many points of each curve are drawn (evenly picked along the program).
MAX_DRAWN = 20000


def _thin(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    if x.size > MAX_DRAWN:
        k = np.linspace(0, x.size - 1, MAX_DRAWN).round().astype(int)
        x, y = x[k], y[k]
    return x, y


def _placement_grid(res: CompensationResult):
    """The placement map as (x axis, y axis, values (ny, nx)) in mm, or None."""
    p = res.placement
    if p is None:
        return None
    v = p.values
    if v.ndim == 3:  # spatial: the slice nearest the chosen z
        k = int(np.argmin(np.abs(p.grid[2] - p.place[2])))
        v = v[:, :, k]
    return p.grid[0], p.grid[1], v.T


def compensation_png(res: CompensationResult) -> bytes:
    """The static figure (PNG): deflection before and after, and the placement map if any."""
    c = res.compensation
    grid = _placement_grid(res)
    fig = Figure(figsize=(10, 6.5 if grid is None else 9.5))
    n = 3 if grid is not None else 2
    ax1 = fig.add_subplot(n, 1, 1)
    x, y = _thin(c.before_at, 1e3 * c.before)
    ax1.plot(x, y, lw=1.0, color="#1f77b4")
    ax1.set_ylabel("|δ| uncompensated (µm)")
    ax1.set_title("Deflection along the program's feed moves")
    ax2 = fig.add_subplot(n, 1, 2, sharex=ax1)
    x, y = _thin(c.after_at, 1e3 * c.after)
    ax2.plot(x, y, ".", ms=2, color="#2ca02c", label="compensated: distance to the programmed path")
    ax2.axhline(1e3 * c.tolerance_mm, color="#d62728", lw=1, ls="--", label="tolerance")
    ax2.set_ylabel("residual (µm)")
    ax2.set_xlabel("length along the feed moves (mm)")
    ax2.legend(loc="upper right", fontsize=8)
    if grid is not None:
        ax3 = fig.add_subplot(n, 1, 3)
        gx, gy, v = grid
        m = ax3.pcolormesh(gx, gy, 1e3 * np.ma.masked_invalid(v), shading="nearest", cmap="viridis")
        ax3.plot(*res.placement.place[:2], "r*", ms=12, label="chosen")
        ax3.set_xlabel("program origin x (mm, base)")
        ax3.set_ylabel("y (mm, base)")
        ax3.set_aspect("equal")
        ax3.set_title(f"{res.placement.objective} deflection over the placements (µm)")
        fig.colorbar(m, ax=ax3)
    fig.tight_layout()
    return png_bytes(fig)


def _figure(res: CompensationResult) -> go.Figure:
    c = res.compensation
    grid = _placement_grid(res)
    rows = 3 if grid is not None else 2
    fig = make_subplots(
        rows=rows,
        cols=1,
        vertical_spacing=0.08,
        subplot_titles=["|δ| uncompensated (µm)", "residual after compensation (µm)"]
        + (["placement map (µm)"] if grid is not None else []),
    )
    x, y = _thin(c.before_at, 1e3 * c.before)
    fig.add_trace(go.Scattergl(x=x, y=y, mode="lines", name="uncompensated"), row=1, col=1)
    x, y = _thin(c.after_at, 1e3 * c.after)
    fig.add_trace(
        go.Scattergl(x=x, y=y, mode="markers", marker={"size": 3}, name="compensated"), row=2, col=1
    )
    fig.add_hline(y=1e3 * c.tolerance_mm, line_dash="dash", line_color="#d62728", row=2, col=1)
    fig.update_xaxes(title_text="length along the feed moves (mm)", row=2, col=1)
    if grid is not None:
        gx, gy, v = grid
        fig.add_trace(
            go.Heatmap(
                x=gx,
                y=gy,
                z=np.where(np.isfinite(v), 1e3 * v, None),
                colorscale="Viridis",
                colorbar={"title": "µm", "len": 0.3, "y": 0.15},
                name="objective",
            ),
            row=3,
            col=1,
        )
        p = res.placement.place
        fig.add_trace(
            go.Scatter(
                x=[p[0]],
                y=[p[1]],
                mode="markers",
                marker={"symbol": "star", "size": 14, "color": "red"},
                name="chosen",
            ),
            row=3,
            col=1,
        )
        fig.update_xaxes(title_text="program origin x (mm, base frame)", row=3, col=1)
        fig.update_yaxes(title_text="y (mm)", scaleanchor="x3", row=3, col=1)
    fig.update_layout(height=420 * rows, margin={"l": 60, "r": 20, "t": 40, "b": 40}, showlegend=False)
    return fig


def compensation_page(res: CompensationResult) -> str:
    """The interactive page: a summary table and the plotly figure (self-contained)."""
    s = res.summary
    rows = [
        ("program", s["program"]),
        ("mechanism", s["mechanism"]),
        ("force", s["force"]),
        ("placement of the program's origin (mm, base frame)", ", ".join(f"{v:.3f}" for v in s["place_mm"])),
        ("feed moves / moves", f"{s['feed_moves']} / {s['moves']}"),
        ("output points", s["points_out"]),
        (
            "worst / RMS deflection uncompensated (µm)",
            f"{s['deflection_before_um']['worst']:.2f} / {s['deflection_before_um']['rms']:.2f}",
        ),
        (
            "worst predicted residual after (µm)",
            f"{s['residual_after_um']['worst']:.3f} (tolerance {s['tolerance_um']:g})",
        ),
    ]
    if s.get("residual_band_95_um") is not None:
        rows.append(
            ("95 % band of the residual from the model's uncertainty (µm)", f"{s['residual_band_95_um']:.3f}")
        )
    if "spin" in s:
        rows.append(
            (
                "worst deflection at the knots, fixed / chosen spin (µm)",
                " / ".join(
                    "unreachable" if v is None else f"{v:.2f}"
                    for v in (s["spin"]["worst_fixed_um"], s["spin"]["worst_chosen_um"])
                ),
            )
        )
    table = (
        "<table>"
        + "".join(f"<tr><th>{html.escape(str(a))}</th><td>{html.escape(str(b))}</td></tr>" for a, b in rows)
        + "</table>"
    )
    fig = f"<script type='application/json' data-figure='fig-comp'>{figure_json(_figure(res))}</script>"
    return (
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
        "<meta name=viewport content='width=device-width, initial-scale=1'>"
        f"<title>{html.escape(Path(s['output']).name)} — stiffmap compensate</title>"
        f"<style>{CSS}</style></head><body>"
        f"<header><h1>Compensation of {html.escape(Path(s['program']).name)}</h1>"
        "<p>Units: positions mm, deflections µm, forces N; base frame of the robot.</p></header>"
        f"<main><section id=summary><h2>Summary</h2>{table}</section>"
        "<section id=figures><h2>Deflection along the program</h2>"
        "<div class=fig id='fig-comp'></div></section></main>"
        f"<script>{get_plotlyjs()}</script>{fig}<script>{JS}</script></body></html>\n"
    )


def write_compensation_figures(res: CompensationResult, out: str | os.PathLike) -> list[str]:
    """Write ``OUT.deflection.png`` and ``OUT.html`` beside the corrected program ``out``.

    Returns
    -------
    list of str
        The files written (atomically).
    """
    png, page = str(out) + ".deflection.png", str(out) + ".html"
    atomic_write_bytes(png, compensation_png(res))
    atomic_write_text(page, compensation_page(res))
    return [png, page]
