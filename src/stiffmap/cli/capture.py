"""``stiffmap capture``: take a campaign's images from a live camera, one step at a time."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import typer
from rich.live import Live
from rich.prompt import Confirm, Prompt

from ..campaign.run import campaign_root
from ..campaign.spec import load_spec
from ..capture.cameras import open_camera
from ..capture.session import LOG_NAME, CaptureStopped, ViewState, run_capture
from ..capture.view import render_view
from .common import EXIT_PARTIAL, err, fail, out

#: Without a terminal (no live view), a line on the step's state at most this often (s).
WAITING_LINE_S = 10.0


class _ConsoleOperator:
    """The operator at the terminal: each action confirmed with Enter (or s, r, q)."""

    def __init__(self, live: Live | None) -> None:
        self.live = live

    def _ask(self, ask):
        if self.live is not None:
            self.live.stop()
        try:
            return ask()
        except EOFError:
            return None
        finally:
            if self.live is not None:
                self.live.start()

    def confirm(self, instruction: str) -> str:
        err.print(f"[bold yellow]next:[/] {instruction}", highlight=False)
        a = self._ask(
            lambda: Prompt.ask(
                "Enter when done (s: skip this image, r: redo the last image, q: quit)",
                console=err,
                default="",
                show_default=False,
            )
        )
        if a is None:
            return "quit"
        return {"": "go", "s": "skip", "r": "redo", "q": "quit"}.get(a.strip().lower()[:1], "go")

    def overwrite(self, file: str) -> bool:
        return bool(
            self._ask(lambda: Confirm.ask(f"{file} exists: overwrite it?", console=err, default=False))
        )

    def gave_up(self, message: str) -> str:
        err.print(f"[bold red]{message}[/]", highlight=False)
        a = self._ask(lambda: Confirm.ask("Keep trying?", console=err, default=True))
        return "retry" if a else "quit"


def _viewer(live: Live | None) -> Callable[[ViewState], None]:
    """Show the capture's state: in the live view, else a line per image saved and one every
    :data:`WAITING_LINE_S` while waiting."""
    last_saved: list[str] = []
    last_line = [time.monotonic()]

    def view(state: ViewState) -> None:
        if live is not None:
            live.update(render_view(state), refresh=True)
        elif state.saved and state.saved[-1:] != last_saved[-1:]:
            last_saved[:] = state.saved
            last_line[0] = time.monotonic()
            out.print(f"saved {state.saved[-1]}  ({state.on_disk} on disk)", highlight=False)
        elif time.monotonic() - last_line[0] > WAITING_LINE_S:  # progress without a live view
            last_line[0] = time.monotonic()
            out.print(
                f"step {state.step} of {state.steps}, {state.image}: {state.status or 'waiting'} "
                f"({state.collected} of {state.needed} settled frames kept)",
                highlight=False,
            )

    return view


def capture(
    campaign: Path = typer.Argument(..., help="The campaign directory (its campaign.toml)."),
    camera: str = typer.Option(
        "0",
        "--camera",
        help="The camera: a device number (0), a stream URL, a video file, a folder of images, "
        "genicam:PRODUCER.cti[#SERIAL] (pip install 'stiffmap[genicam]'), or sim (the virtual test-bed; "
        "sim:fps=5,time_constant_s=0.1,... sets its options).",
    ),
    frames: int | None = typer.Option(
        None,
        "--frames",
        min=1,
        max=1000,
        help="Settled frames per image, 1 to 1000 (default [capture] frames): averaged into one "
        "image, or kept as the repeats with [capture] average = false.",
    ),
    yes: bool = typer.Option(
        False,
        "--yes",
        "-y",
        help="No questions: every action is taken as done (the simulated camera, rigs with load "
        "actuators, scripts); an image without a good settled frame in [capture] timeout_s (the "
        "camera's time or the wall clock's, at least 10 s, whichever passes first) stops.",
    ),
) -> None:
    """Take a campaign's images from a live camera, one step at a time, once the platform has settled.

    Walks the campaign's plan (positions, load cases, repeats; unloaded and loaded images in
    the order of its [images] patterns), tells what to do next, and saves an image under the
    campaign's file name only when both boards are found, no board is saturated and the
    platform has stayed still, within the measurement noise, for [capture] settle_seconds.
    Images already on disk are kept: an interrupted capture goes on at the first missing one.
    Everything is recorded in capture_log.jsonl in the campaign directory. See docs/capture.md.
    """
    root = campaign_root(campaign)  # the directory, or its campaign.toml
    spec = load_spec(root)
    source = open_camera(camera, root, spec)
    live = Live(console=err, auto_refresh=False, transient=False) if err.is_terminal else None
    view = _viewer(live)
    operator = None if yes else _ConsoleOperator(live)
    with source:
        if live is not None:
            live.start()
        try:
            summary = run_capture(root, spec, source, operator=operator, frames=frames, view=view)
        except CaptureStopped as e:  # not an input error, but it ends the command as one: exit 2
            raise fail(str(e)) from None
        finally:
            if live is not None:
                live.stop()
    out.print(
        f"{len(summary.saved)} images saved, {summary.present} were on disk, {len(summary.skipped)} "
        f"skipped; {summary.frames} frames; log: {root / LOG_NAME}",
        highlight=False,
    )
    if summary.missing:
        out.print(
            f"{len(summary.missing)} images still missing (first: {summary.missing[0]}); run stiffmap "
            "capture again to take them",
            highlight=False,
        )
        raise typer.Exit(EXIT_PARTIAL)
    out.print(f"every image of the campaign is on disk; next: stiffmap run {root}", highlight=False)


def register(app: typer.Typer) -> None:
    app.command("capture")(capture)
