"""Time and size of a report: writing the page and the PNGs, and opening it in headless Chromium.

Data: the example vision campaign (48 positions x 9 load cases x 10 repeats, with
model, dense model map, truth and calibration) and the example sensor campaign
(22 points x 2 directions with a dense model map). Times are the median of
``--repeats`` runs on one core (each write is single-threaded).

Run: .venv/bin/python benchmarks/bench_report.py [--repeats 3] [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from _table import save
from plotly.offline import get_plotlyjs

from stiffmap.report import write_report
from stiffmap.report.browser import BrowserError, check_page, find_chromium
from stiffmap.report.example import example_sensor, example_vision


def _median_time(fn, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one repeat, no browser")
    args = ap.parse_args()
    reps = 1 if args.quick else args.repeats
    bundle = len(get_plotlyjs().encode())
    chromium = None if args.quick else find_chromium()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, make in (("vision 48 x 9 x 10", example_vision), ("sensor 22 points x 2", example_sensor)):
            data = make()
            d_html = Path(tmp) / f"{name[:6]}-html"
            d_png = Path(tmp) / f"{name[:6]}-png"
            t_html = _median_time(lambda data=data, d=d_html: write_report(data, d, png=False), reps)
            t_all = _median_time(lambda data=data, d=d_png: write_report(data, d, png=True), reps)
            page = (d_png / "index.html").stat().st_size
            pngs = sorted(d_png.glob("*.png"))
            png_bytes = sum(p.stat().st_size for p in pngs)
            t_browser, errors = "n/a", "n/a"
            if chromium:
                try:
                    t0 = time.perf_counter()
                    r = check_page(d_png / "index.html", chromium=chromium, timeout=120, settle=0.0)
                    t_browser = f"{time.perf_counter() - t0:.1f}"
                    errors = f"{len(r.errors)} / {len(r.external_requests)}"
                except BrowserError as e:
                    t_browser = f"failed: {e}"
            rows.append(
                [
                    name,
                    f"{t_html:.2f}",
                    f"{t_all:.2f}",
                    f"{page / 1e6:.2f}",
                    f"{(page - bundle) / 1e3:.0f}",
                    f"{len(pngs)} ({png_bytes / 1e6:.2f} MB)",
                    t_browser,
                    errors,
                ]
            )
    save(
        "report",
        "Report: write time, size, and headless-Chromium load",
        [
            "data",
            "page only (s)",
            "page + PNGs (s)",
            "page (MB)",
            "page less plotly.js (kB)",
            "PNGs",
            "open in Chromium (s)",
            "console errors / external requests",
        ],
        rows,
        notes=(
            f"Median of {reps} run(s). The page embeds plotly.js once ({bundle / 1e6:.2f} MB); "
            "the rest is the "
            "figures as JSON (numeric arrays base64-encoded by plotly), tables and the page's own script. "
            "'open in Chromium' is the whole check: start the browser, load the page from file://, wait "
            "for every figure to render, close."
        ),
    )


if __name__ == "__main__":
    main()
