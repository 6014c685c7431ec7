"""``stiffmap report``: render a report directory from a JSON dump of the report data."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import EXIT_PARTIAL, fail, out, print_json, warn

EXAMPLES = ("vision", "sensor")


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
) -> None:
    """Write a self-contained HTML report (works offline) and PNG figures.

    The page shows the stiffness map (markers sized by det K), per-plane
    maps, the load cases of every position with their repeats, measured
    beside modelled maps, recovered vs true stiffness, calibration
    residuals, every K with its flags, and static-error maps for sensor
    campaigns. Units: mm, N, N/mm; static error in um; residuals in px.
    """
    from ..report import load_report_data, write_report

    if screenshot is not None and not check:
        raise fail("--screenshot needs --check (the screenshot is taken by the browser check)")
    if not example and Path(data).is_dir():
        from ..campaign.spec import SPEC_NAME
        from ..report.campaign import write_campaign_report

        if not (Path(data) / SPEC_NAME).is_file():
            raise fail(f"{data}: a directory without {SPEC_NAME}; expected a campaign or a data.json file")
        index = write_campaign_report(data, out_dir=out_dir, png=png)
    else:
        if out_dir is None:
            raise fail("give OUT_DIR, the directory to write the report to")
        if example:
            from ..report import example as ex

            if data not in EXAMPLES:
                raise fail(f"--example: unknown example {data!r}; expected one of {', '.join(EXAMPLES)}")
            rd = ex.example_vision() if data == "vision" else ex.example_sensor()
        else:
            rd = load_report_data(data)
        index = write_report(rd, out_dir, png=png)
    files = sorted(p.name for p in index.parent.iterdir() if p.is_file() and not p.name.startswith("."))
    result: dict = {"index": str(index), "files": files}
    code = 0
    if check:
        from ..report.browser import BrowserError, check_page

        try:
            pc = check_page(index, screenshot=screenshot is not None, width=width, height=height)
        except BrowserError as e:
            raise fail(f"--check: {e}") from None
        if screenshot is not None:
            from ..io import atomic_write_bytes

            atomic_write_bytes(screenshot, pc.screenshot)
        result["check"] = {
            "ready": pc.ready,
            "errors": [{"level": e.level, "source": e.source, "text": e.text} for e in pc.errors],
            "external_requests": list(pc.external_requests),
        }
        if pc.errors or pc.external_requests or not pc.ready:
            code = EXIT_PARTIAL
    if as_json:
        print_json(result)
    else:
        out.print(f"report: {index}")
        out.print(f"files: {', '.join(files)}")
        if check:
            c = result["check"]
            for e in c["errors"]:
                warn(f"browser {e['source']} {e['level']}: {e['text']}")
            for u in c["external_requests"]:
                warn(f"the page requested {u}")
            if not c["ready"]:
                warn("the page did not finish rendering its figures")
            if code == 0:
                out.print("browser check: rendered, no console error, no network request")
        if screenshot is not None:
            out.print(f"screenshot: {screenshot}")
    if code:
        raise typer.Exit(code)


def register(app: typer.Typer) -> None:
    app.command("report")(report)
