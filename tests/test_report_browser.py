"""The report opens in a real browser (Debian's headless Chromium) with no console error.

Skipped, with a message, when no Chromium is installed (``apt-get install chromium``;
``.ci/run`` installs it when apt is available).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.report_cases import all_positions_failed

from stiffmap.report import write_report
from stiffmap.report.browser import ConsoleEntry, PageCheck, check_page, find_chromium
from stiffmap.report.example import example_sensor, example_vision

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def chromium() -> str:
    exe = find_chromium()
    if exe is None:
        pytest.skip("headless Chromium not found: apt-get install chromium (or set STIFFMAP_CHROMIUM)")
    return exe


#: Run in the page once it signalled that every figure is drawn: count the rendered
#: figures, drive the position selector and the table filter, and report what changed.
_DRIVE = r"""
(async () => {
  const figs = [...document.querySelectorAll("div.fig")];
  const rendered = figs.filter(
    (d) => d.classList.contains("js-plotly-plot") && d.querySelector(".main-svg")).length;
  const sel = document.getElementById("pos-select");
  sel.value = "44";
  sel.dispatchEvent(new Event("change"));
  const detail = document.getElementById("fig-load-detail");
  const lin = document.getElementById("fig-linearity");
  const res = document.getElementById("fig-residual-detail");
  const drawn = (d) => String(d.layout.title.text).startsWith("P45");
  for (let k = 0; k < 100 && !(drawn(detail) && drawn(lin) && drawn(res)); k++)
    await new Promise((r) => setTimeout(r, 50));
  const cb = document.getElementById("only-flagged");
  cb.checked = true;
  cb.dispatchEvent(new Event("change"));
  const shown = [...document.querySelectorAll("table.k tbody tr")].filter(
    (tr) => tr.style.display !== "none");
  return {
    figs: figs.length,
    rendered,
    options: sel.options.length,
    title: String(detail.layout.title.text),
    bars: detail.data[0].y.length,
    repeats: detail.data[2].y.length,
    webgl: document.querySelectorAll("#fig-map3d canvas").length,
    linearity: [String(lin.layout.title.text), lin.data.length],
    residuals: [String(res.layout.title.text), res.data.map((t) => t.y.length)],
    shown: shown.map((tr) => tr.className),
  };
})()
"""


def test_vision_report_renders_without_console_error(chromium, tmp_path) -> None:
    index = write_report(example_vision(), tmp_path, png=False)
    shots = ("#setup", "#principal", "#fig-linearity", "#fig-residuals", "#fig-truth", "#fig-calibration")
    r = check_page(index, script=_DRIVE, chromium=chromium, timeout=90, elements=(*shots, "#nothing"))
    assert r.ready, "the page did not signal that its figures were drawn"
    assert r.errors == (), r.errors
    assert r.external_requests == (), r.external_requests
    # Nothing but the page itself was loaded (plotly.js draws some icons from data: URIs).
    assert [u for u in r.requests if not u.startswith("data:")] == [index.resolve().as_uri()]
    res = r.result
    assert res["figs"] == res["rendered"] == 12  # 8, and the ellipsoids, linearity and two of residuals
    assert res["options"] == 48
    assert res["title"].startswith("P45 (-200, 200, -400)")
    assert res["bars"] == 9 and res["repeats"] == 10
    assert res["webgl"] >= 1  # the 3D stiffness map drew on a WebGL canvas
    # The chosen position's linearity (3 directions x 3 components, dots and line) and residuals
    # (its 9 load cases x 10 repeats per component) were redrawn for it.
    assert res["linearity"][0].startswith("P45 (-200, 200, -400)") and res["linearity"][1] == 18
    assert res["residuals"][0].startswith("P45") and res["residuals"][1] == [90, 90, 90]
    assert sorted(res["shown"]) == ["failed", "failed", "flagged"]
    # What docs/img/report_screenshots.py saves: each diagnostic as drawn, whole (the ellipsoids'
    # section is taller than nothing), not a blank; None for a selector that matches nothing.
    assert r.shots[-1] is None
    for sel, png in zip(shots, r.shots, strict=False):
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
        assert img.shape[1] > 1000 and img.shape[0] > 150, (sel, img.shape)  # 1280 px window
        assert (img < 128).mean() > 0.002, sel  # some ink: text, axes, markers


def test_sensor_report_renders_without_console_error(chromium, tmp_path) -> None:
    index = write_report(example_sensor(), tmp_path, png=False)
    script = (
        "[...document.querySelectorAll('div.fig')].map((d) => d.classList.contains('js-plotly-plot')"
        " && d.querySelectorAll('.main-svg').length > 0)"
    )
    r = check_page(index, script=script, chromium=chromium, timeout=90)
    assert r.ready
    assert r.errors == (), r.errors
    assert r.external_requests == ()
    assert r.result == [True, True, True]  # maps, middle line, linearity


def test_the_check_catches_console_errors_exceptions_and_failed_loads(chromium, tmp_path) -> None:
    page = tmp_path / "bad.html"
    page.write_text(
        "<!DOCTYPE html><html><body><img src='missing.png'>"
        "<script>console.error('boom'); console.log('fine'); undefinedFunction();</script></body></html>"
    )
    r = check_page(page, chromium=chromium, timeout=60)
    texts = [(e.source, e.text) for e in r.errors]
    assert ("console", "boom") in texts
    assert any(s == "exception" and "undefinedFunction is not defined" in t for s, t in texts)
    assert any(s == "network" and "ERR_FILE_NOT_FOUND" in t for s, t in texts)
    assert all(e.text != "fine" for e in r.errors)
    assert (tmp_path / "missing.png").as_uri() in r.requests
    assert r.external_requests == ()


def test_external_request_classification() -> None:
    r = PageCheck(
        "file:///a.html",
        True,
        (ConsoleEntry("warning", "w", "console"), ConsoleEntry("error", "e", "exception")),
        (
            "file:///a.html",
            "data:image/png;base64,AA",
            "blob:file:///x",
            "https://cdn.example/x.js",
            "http://h/",
        ),
    )
    assert r.external_requests == ("https://cdn.example/x.js", "http://h/")
    assert [e.text for e in r.errors] == ["e"]
    # What `stiffmap report --check` prints and decides from (its JSON "check" object).
    assert not r.ok
    assert r.summary() == {
        "ready": True,
        "errors": [{"level": "error", "source": "exception", "text": "e"}],
        "external_requests": ["https://cdn.example/x.js", "http://h/"],
    }
    clean = PageCheck("file:///a.html", True, (ConsoleEntry("warning", "w", "console"),), ("file:///a.html",))
    assert clean.ok and clean.summary() == {"ready": True, "errors": [], "external_requests": []}
    assert not PageCheck("file:///a.html", False, (), ()).ok


def test_page_with_every_position_failed_renders(chromium, tmp_path) -> None:
    index = write_report(all_positions_failed(), tmp_path, png=False)
    r = check_page(index, script="document.getElementById('pos-select').options.length", chromium=chromium)
    assert r.ready
    assert r.errors == (), r.errors
    assert r.result == 3
