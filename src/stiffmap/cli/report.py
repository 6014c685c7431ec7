"""``stiffmap report``: a report directory from a campaign, a JSON dump of the report data or an example."""

from __future__ import annotations

from pathlib import Path

import typer

from ..io import ALLOW_OUTSIDE_OPTION
from ..report.browser import BrowserError, check_report
from ..report.sources import write_report_from
from ..report.writer import report_files
from .common import EXIT_PARTIAL, fail, out, print_json, warn


def report(
    data: str = typer.Argument(
        ...,
        metavar="DATA",
        help="A campaign directory (after 'stiffmap run'), a JSON dump of the report data (the "
        "data.json written beside every report), or with --example the name of a built-in "
        "example: vision or sensor.",
    ),
    out_dir: Path = typer.Argument(
        None,
        metavar="[OUT_DIR]",
        help="Directory for index.html, the PNGs and data.json (default for a campaign: CAMPAIGN/report).",
        show_default=False,
    ),
    example: bool = typer.Option(False, "--example", help="DATA names a built-in example (vision, sensor)."),
    png: bool = typer.Option(True, "--png/--no-png", help="Also write the PNG figures for papers."),
    check: bool = typer.Option(
        False,
        "--check",
        help="Open the page in headless Chromium; fail on a console error or a network request.",
    ),
    screenshot: Path | None = typer.Option(
        None, "--screenshot", help="With --check: save a PNG screenshot of the top of the page here."
    ),
    width: int = typer.Option(1280, "--width", min=320, help="Browser viewport width for --check (CSS px)."),
    height: int = typer.Option(
        1800, "--height", min=240, help="Browser viewport height for --check (CSS px)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of text."),
    allow_outside_paths: bool = typer.Option(
        False,
        ALLOW_OUTSIDE_OPTION,
        help="Let a campaign's campaign.toml name files outside its directory (absolute paths, '..', "
        "symbolic links leading out); without it such a name is refused.",
    ),
) -> None:
    """Write a self-contained HTML report (works offline) and PNG figures.

    The page shows the stiffness map (markers sized by det K), per-plane
    maps, the load cases of every position with their repeats, measured
    beside modelled maps, recovered vs true stiffness, calibration
    residuals, every K with its flags, and static-error maps for sensor
    campaigns. Units: mm, N, N/mm; static error in um; residuals in px.
    """
    if screenshot is not None and not check:
        raise fail("--screenshot needs --check (the screenshot is taken by the browser check)")
    index = write_report_from(data, out_dir, example=example, png=png, allow_outside=allow_outside_paths)
    result: dict = {"index": str(index), "files": report_files(index)}
    pc = None
    if check:
        try:
            pc = check_report(index, screenshot=screenshot, width=width, height=height)
        except BrowserError as e:
            raise fail(f"--check: {e}") from None
        result["check"] = pc.summary()
    if as_json:
        print_json(result)
    else:
        _print_result(result, screenshot)
    if pc is not None and not pc.ok:
        raise typer.Exit(EXIT_PARTIAL)


def _print_result(result: dict, screenshot: Path | None) -> None:
    out.print(f"report: {result['index']}")
    out.print(f"files: {', '.join(result['files'])}")
    c = result.get("check")
    if c is not None:
        for e in c["errors"]:
            warn(f"browser {e['source']} {e['level']}: {e['text']}")
        for u in c["external_requests"]:
            warn(f"the page requested {u}")
        if not c["ready"]:
            warn("the page did not finish rendering its figures")
        if c["ready"] and not c["errors"] and not c["external_requests"]:
            out.print("browser check: rendered, no console error, no network request")
    if screenshot is not None:
        out.print(f"screenshot: {screenshot}")


def register(app: typer.Typer) -> None:
    app.command("report")(report)
