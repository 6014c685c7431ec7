"""The live terminal view of a capture (rich): what to do next, and what the camera sees.

:func:`render_view` turns a :class:`~stiffmap.capture.session.ViewState` into a rich panel:
the step and the image being taken, the operator's instruction, both boards found or not,
their exposure (saturated and dark fractions) and sharpness (edge blur), the platform's pose
change since the previous frame and its noise, how long it has been at rest, and the status.
"""

from __future__ import annotations

import math

import numpy as np
from rich.console import Group
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from .session import ViewState

__all__ = ["render_view"]


def _pct(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{100 * v:.2f} %"


def _num(v: float, fmt: str) -> str:
    return "-" if not math.isfinite(v) else format(v, fmt)


def render_view(state: ViewState) -> Panel:
    """The live view of one moment of a capture (a rich renderable)."""
    head = Text()
    head.append(f"image {state.step} of {state.steps}", style="bold")
    head.append(f"   {state.image}\n", style="cyan")
    head.append(f"on disk: {state.on_disk} images\n")
    head.append("next: ", style="bold")
    head.append(state.instruction or "-", style="bold yellow")
    t = Table(show_header=True, header_style="bold", box=None, pad_edge=False)
    t.add_column("board")
    t.add_column("found")
    t.add_column("saturated", justify="right")
    t.add_column("dark", justify="right")
    t.add_column("edge blur", justify="right")
    c = state.check
    boards = c.boards if c is not None else ()
    for name in ("mobile", "fixed"):
        b = next((x for x in boards if x.name == name), None)
        if b is None:
            t.add_row(name, "-", "-", "-", "-")
            continue
        found = Text("yes", style="green") if b.found else Text("NO", style="bold red")
        sat = Text(_pct(b.saturated_fraction), style="bold red" if b.saturated_fraction > 0.001 else "")
        t.add_row(name, found, sat, _pct(b.dark_fraction), _num(b.blur_px, ".2f") + " px")
    pose = Text()
    if c is not None and np.all(np.isfinite(c.step_mm)):
        step_um = 1e3 * np.asarray(c.step_mm)
        sig_um = 1e3 * np.asarray(c.sigma_mm)
        pose.append("pose change (x, y, z): ")
        pose.append(f"({', '.join(f'{v:+.1f}' for v in step_um)}) um", style="bold")
        pose.append(f"   noise 1 sigma ({', '.join(f'{v:.1f}' for v in sig_um)}) um\n")
    else:
        pose.append("pose change: -\n")
    if c is not None:
        rest_style = "green" if c.settled else "yellow"
        pose.append(f"chi2 {_num(c.chi2, '.1f')} (limit {c.chi2_limit:.1f})   ")
        pose.append(f"at rest {c.at_rest_s:.1f} s of {state.settle_seconds:g} s", style=rest_style)
        pose.append(f"   frames kept {state.collected}/{state.needed}")
    status_style = "bold red" if c is not None and c.problem else "bold"
    status = Text(state.status or "", style=status_style)
    saved = Text("last saved: " + (", ".join(state.saved) if state.saved else "-"), style="dim")
    return Panel(
        Group(head, Text(""), t, Text(""), pose, Text(""), status, saved),
        title=f"stiffmap capture: {state.campaign}",
        border_style="blue",
    )
