"""Drawing of a stage validation (:func:`stiffmap.vision.validate.validate_stage`) as an SVG.

Measured against nominal displacement and the error per step (mean +/- one standard
deviation), self-contained SVG text, no plotting library: ``stiffmap validate --plot``
writes it.
"""

from __future__ import annotations

from html import escape

import numpy as np

from ..vision.validate import StageValidation

__all__ = ["stage_plot_svg"]


def stage_plot_svg(result: StageValidation, title: str = "Stage validation") -> str:
    """SVG of measured vs nominal displacement and of the error per step (mean +/- 1 std)."""
    W, H = 760, 340
    pw, ph = 300, 230
    panels = [(70, 50), (440, 50)]
    steps = result.steps
    noms = np.array([s.nominal_mm for s in steps])
    means = np.array([s.mean_mm for s in steps])
    stds = np.nan_to_num(np.array([s.std_mm for s in steps]))
    errs = means - noms
    xmax = max(float(noms.max()), 1e-6) * 1.08
    ymax = max(float((means + stds).max()), xmax) * 1.02
    emax = max(float(np.max(np.abs(errs) + stds)), 1e-6) * 1.3
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" '
        'font-size="12">',
        f'<text x="{W / 2}" y="22" text-anchor="middle" font-size="15">{escape(title)}</text>',
    ]

    def panel(x0, y0, ylo, yhi, ylabel, pts, line):
        sx = lambda v: x0 + pw * v / xmax  # noqa: E731
        sy = lambda v: y0 + ph * (1 - (v - ylo) / (yhi - ylo))  # noqa: E731
        out.append(f'<rect x="{x0}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>')
        for k in range(5):
            xv = xmax * k / 4
            yv = ylo + (yhi - ylo) * k / 4
            out.append(
                f'<text x="{sx(xv):.1f}" y="{y0 + ph + 16}" text-anchor="middle">{xv:.3g}</text>'
                f'<text x="{x0 - 6}" y="{sy(yv) + 4:.1f}" text-anchor="end">{yv:.3g}</text>'
            )
        out.append(
            f'<text x="{x0 + pw / 2}" y="{y0 + ph + 34}" text-anchor="middle">'
            "nominal displacement (mm)</text>"
            f'<text x="{x0 - 52}" y="{y0 + ph / 2}" text-anchor="middle" '
            f'transform="rotate(-90 {x0 - 52} {y0 + ph / 2})">{escape(ylabel)}</text>'
        )
        a, b = line
        out.append(
            f'<line x1="{sx(0):.1f}" y1="{sy(a):.1f}" x2="{sx(xmax):.1f}" y2="{sy(b):.1f}" '
            'stroke="#999" stroke-dasharray="4 3"/>'
        )
        for xv, yv, sv in pts:
            out.append(
                f'<line x1="{sx(xv):.1f}" y1="{sy(yv - sv):.1f}" x2="{sx(xv):.1f}" y2="{sy(yv + sv):.1f}" '
                'stroke="#1f5fbf"/>'
                f'<circle cx="{sx(xv):.1f}" cy="{sy(yv):.1f}" r="3.5" fill="#1f5fbf"/>'
            )

    panel(*panels[0], 0.0, ymax, "measured (mm)", list(zip(noms, means, stds, strict=True)), (0.0, xmax))
    panel(
        *panels[1], -emax, emax, "measured - nominal (mm)", list(zip(noms, errs, stds, strict=True)), (0, 0)
    )
    out.append("</svg>")
    return "\n".join(out) + "\n"
