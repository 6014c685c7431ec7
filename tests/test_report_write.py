"""Writing a report: files, self-containment, what the page and figures show, atomic writes."""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path

import numpy as np
import pytest
from helpers.report_cases import all_positions_failed
from plotly.offline import get_plotlyjs
from scipy.spatial import Delaunay

from stiffmap.report import write_report
from stiffmap.report.data import CampaignInfo, MeasuredStiffness, ReportData, SensorResults
from stiffmap.report.example import REFERENCE_PLANES_Z, example_sensor, example_vision
from stiffmap.report.figure_data import (
    MAX_DIAMETER,
    MIN_DIAMETER,
    as_grid,
    det_diameters,
    interpolate_measured,
    middle_line_order,
    plane_values,
)
from stiffmap.report.interactive_figures import plane_maps, stiffness_map_3d

#: plotly.js is large; the page holds it once plus figure JSON.
MAX_PAGE_BYTES = 6_500_000


@pytest.fixture(scope="module")
def vision():
    return example_vision(seed=3)


@pytest.fixture(scope="module")
def vision_report(vision, tmp_path_factory) -> Path:
    """The reference layout's page (48 x 9 x 10); PNGs are tested on a smaller campaign."""
    return write_report(vision, tmp_path_factory.mktemp("vision") / "report", png=False)


def _png_size(b: bytes) -> tuple[int, int]:
    assert b[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", b[16:24])
    return w, h


def _figures(page: str) -> dict[str, dict]:
    out = {}
    for fid, text in re.findall(
        r"<script type='application/json' data-figure='([^']+)'>(.*?)</script>", page, re.S
    ):
        out[fid] = json.loads(text)
    return out


def test_vision_report_files_and_pngs(tmp_path) -> None:
    # Two planes of 3 x 3 positions: every figure, at a third of the 48-panel drawing cost.
    data = example_vision(seed=4, planes=(-200.0, -400.0), per_side=3, repeats=4)
    index = write_report(data, tmp_path / "report")
    d = index.parent
    names = {p.name for p in d.iterdir()}
    want = {
        "index.html",
        "data.json",
        "stiffness_map_3d.png",
        "planes_min_principal.png",
        "planes_det.png",
        "loads_per_position.png",
        "residuals_per_position.png",
        "model_vs_measured.png",
        "recovered_vs_true.png",
        "calibration.png",
    }
    assert names == want  # no temporary file left behind, no sensor figure
    for n in want - {"index.html", "data.json"}:
        w, h = _png_size((d / n).read_bytes())
        assert w >= 600 and h >= 400, n
    assert data.measured.n == 18 and data.measured.flags[14]  # the swapped position is flagged
    page = index.read_text(encoding="utf-8")
    for n in want - {"index.html"}:
        assert f"<a href='{n}'>" in page


def test_page_is_self_contained(vision_report: Path) -> None:
    page = vision_report.read_text(encoding="utf-8")
    assert len(page.encode()) < MAX_PAGE_BYTES
    bundle = get_plotlyjs()
    assert page.count(bundle) == 1  # plotly.js embedded once
    own = page.replace(bundle, "")
    # Outside the bundle: no external script, style sheet, image, font or frame.
    assert not re.search(r"<script[^>]*\ssrc=", own)
    for needle in ("<link", "<img", "<iframe", "@import", "url(", "http://", "https://"):
        assert needle not in own, needle
    # Every figure block is strict JSON (JSON.parse would reject NaN).
    figs = _figures(page)
    assert set(figs) >= {
        "fig-map3d",
        "fig-planes-minp",
        "fig-planes-det",
        "fig-loads-overview",
        "fig-model",
        "fig-truth",
        "fig-calibration",
    }


def test_header_says_what_and_units(vision_report: Path, vision: ReportData) -> None:
    page = vision_report.read_text(encoding="utf-8")
    assert f"<h1>{vision.campaign.name}</h1>" in page
    assert "vision campaign · stiffmap" in page
    assert "stiffness N/mm" in page and "det K (N/mm)³" in page and "mm" in page


def test_stiffness_map_marker_diameters_proportional_to_det(vision: ReportData) -> None:
    fig = stiffness_map_3d(vision)
    tr = fig.data[0]
    size = np.asarray(tr.marker.size, dtype=float)
    det = np.asarray(tr.marker.color, dtype=float)
    above = size > MIN_DIAMETER
    assert above.sum() >= 10
    # The reference's Fig. 12: diameter proportional to det K (above the visibility floor).
    np.testing.assert_allclose(size[above] / det[above], MAX_DIAMETER / det.max(), rtol=1e-12)
    assert np.all(size[~above] == MIN_DIAMETER)
    names = [t.name for t in fig.data]
    m = vision.measured
    n_bad = int((m.ok & ~(m.det > 0)).sum())
    assert ("det K ≤ 0 (flagged)" in names) == (n_bad > 0)
    failed = next(t for t in fig.data if t.name == "failed")
    assert len(failed.x) == int((~m.ok).sum()) == 2


def test_det_diameters_floor_and_nan() -> None:
    d = det_diameters(np.array([100.0, 50.0, 0.1, -3.0, np.nan]))
    np.testing.assert_allclose(d[:3], [MAX_DIAMETER, MAX_DIAMETER / 2, MIN_DIAMETER], rtol=1e-12)
    assert np.isnan(d[3]) and np.isnan(d[4])


def test_plane_maps_one_panel_per_plane(vision: ReportData) -> None:
    fig = plane_maps(vision, "min_principal")
    titles = [a.text for a in fig.layout.annotations]
    for z in REFERENCE_PLANES_Z:
        for row in ("measured", "model", "measured − model"):
            assert f"{row}, z = {z:g} mm" in titles
    # Measured squares on the upper plane: the 16 positions less the failed one (P14).
    first = fig.data[0]
    assert len(first.x) == 15
    m = vision.measured
    on = np.isclose(m.positions[:, 2], -200.0) & m.ok
    np.testing.assert_allclose(np.asarray(first.marker.color, float), m.min_principal[on], rtol=0, atol=0)
    # Residual panel = measured - model at the same positions (N/mm).
    res = [t for t in fig.data if t.type == "scatter" and t.marker.coloraxis == "coloraxis2"][0]
    np.testing.assert_allclose(
        np.asarray(res.marker.color, float),
        (m.min_principal - vision.model.min_principal)[on],
        rtol=0,
        atol=1e-12,
    )


def test_k_table_shows_flags_failures_and_values(vision_report: Path, vision: ReportData) -> None:
    page = vision_report.read_text(encoding="utf-8")
    table = page[page.index("<table class=k>") : page.index("</table>", page.index("<table class=k>"))]
    rows = re.findall(r"<tr(?: class=(\w+))?>(.*?)</tr>", table, re.S)[1:]
    m = vision.measured
    assert len(rows) == m.n
    for i, (cls, body) in enumerate(rows):
        if m.status[i] == "failed":
            assert cls == "failed" and m.messages[i] in body
        elif m.flags[i]:
            assert cls == "flagged"
            for f in m.flags[i]:
                assert f.replace("<", "&lt;").replace(">", "&gt;") in body
        else:
            assert cls == "" and "—" in body
    # Position 45 had two load cases swapped: its K is not positive definite, flagged and highlighted.
    assert rows[44][0] == "flagged" and "not positive definite" in rows[44][1]
    # det K of P1 as printed (4 significant digits).
    assert f"<td>{m.det[0]:.4g}</td>" in rows[0][1]


def test_loads_payload_for_the_selector(vision_report: Path, vision: ReportData) -> None:
    page = vision_report.read_text(encoding="utf-8")
    text = re.search(r"<script type='application/json' id=loads-data>(.*?)</script>", page, re.S).group(1)
    D = json.loads(text)
    n, L, R = vision.loads.norms.shape
    assert (n, L, R) == (48, 9, 10)
    assert len(D["positions"]) == n and len(D["labels"]) == L
    norms = np.array([[[np.nan if v is None else v for v in rr] for rr in row] for row in D["norms"]])
    np.testing.assert_array_equal(norms, vision.loads.norms)
    mean = np.array([[np.nan if v is None else v for v in row] for row in D["mean"]])
    assert np.isnan(mean[13, 4])  # P14 lost load case 5 entirely: no mean, not 0
    assert D["count"][5][2] == 8  # P6 lost two repeats of load case 3


def test_html_escapes_user_text(tmp_path) -> None:
    d = example_sensor()
    d = ReportData(
        CampaignInfo("<script>alert(1)</script>", "sensor", notes="a <b>bold</b> & 'quoted' note"),
        sensor=d.sensor,
        failures=d.failures,
    )
    page = write_report(d, tmp_path, png=False).read_text(encoding="utf-8")
    assert "<script>alert(1)</script>" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "a &lt;b&gt;bold&lt;/b&gt; &amp; &#x27;quoted&#x27; note" in page


def test_sensor_report(tmp_path) -> None:
    d = example_sensor(seed=1)
    index = write_report(d, tmp_path)
    names = {p.name for p in tmp_path.iterdir()}
    assert names == {"index.html", "data.json", "static_error_maps.png", "static_error_middle_line.png"}
    page = index.read_text(encoding="utf-8")
    figs = _figures(page)
    assert set(figs) == {"fig-sensor-maps", "fig-sensor-line", "fig-sensor-linearity"}
    # Linearity: one menu entry per analysed recording (43 of 44), each drawing its plateaus,
    # its line and what the line leaves.
    lin = figs["fig-sensor-linearity"]
    assert len(lin["layout"]["updatemenus"][0]["buttons"]) == 43 and len(lin["data"]) == 3 * 43
    assert "kj = " in page and "N/mm" in page
    assert "rec_13_x.csv: saturated from 12.1 s to 14.3 s" in page
    # The middle-line comparison: the 8 marked points of each direction, ordered by y.
    for direction in ("x", "y"):
        rows = middle_line_order(d, direction)
        assert len(rows) == 8
        assert np.all(np.diff(d.sensor.points[rows, 1]) > 0)
        assert [d.sensor.labels[i] for i in rows] == ["2", "5", "8", "22", "15", "19", "20", "21"]


def test_rewrite_removes_figures_no_longer_produced(tmp_path, vision: ReportData) -> None:
    write_report(vision, tmp_path, png=False)
    (tmp_path / "recovered_vs_true.png").write_bytes(b"old")
    (tmp_path / "notes.txt").write_text("mine")
    write_report(vision, tmp_path, png=False)
    assert not (tmp_path / "recovered_vs_true.png").exists()
    assert (tmp_path / "notes.txt").read_text() == "mine"  # files the report does not own are kept


def test_interpolation_is_exact_for_a_linear_field_and_never_extrapolates(rng) -> None:
    p = rng.uniform(0, 100, size=(30, 2))
    v = 3.0 * p[:, 0] - 2.0 * p[:, 1] + 7.0  # um
    g = interpolate_measured(p, v, n=25)
    X, Y = np.meshgrid(g.xs, g.ys)
    inside = np.isfinite(g.Z)
    assert inside.sum() > 200
    np.testing.assert_allclose(g.Z[inside], 3.0 * X[inside] - 2.0 * Y[inside] + 7.0, rtol=0, atol=1e-9)
    hull = Delaunay(p)
    outside = hull.find_simplex(np.c_[X.ravel(), Y.ravel()]) < 0
    assert np.all(~inside.ravel()[outside])
    # Collinear or too few points: no map rather than a wrong one.
    assert interpolate_measured(np.c_[np.arange(5.0), np.arange(5.0)], np.arange(5.0)) is None
    assert interpolate_measured(p[:2], v[:2]) is None


def test_grid_detection_and_planes() -> None:
    xs, ys = np.array([0.0, 1.0, 2.0]), np.array([5.0, 6.0])
    pts = np.array([(x, y) for y in ys for x in xs])
    g = as_grid(pts[::-1], np.arange(6.0)[::-1])
    assert g is not None
    np.testing.assert_array_equal(g[2], np.arange(6.0).reshape(2, 3))
    assert as_grid(pts[:5], np.arange(5.0)) is None  # a missing corner
    assert as_grid(np.r_[pts, pts[:1]], np.arange(7.0)) is None  # a duplicate
    np.testing.assert_array_equal(
        plane_values(np.array([-400, -200, -310, -200.0])), [-200.0, -310.0, -400.0]
    )


def _degenerate() -> dict[str, ReportData]:
    pos = np.array([[0.0, 0.0, -200.0], [100.0, 0.0, -200.0], [0.0, 0.0, -300.0]])
    return {
        "all positions failed": all_positions_failed(),
        "one position, nothing else": ReportData(
            CampaignInfo("one", "vision"), measured=MeasuredStiffness.from_K(pos[:1], 5.0 * np.eye(3)[None])
        ),
        "two sensor points, one failed, no model": ReportData(
            CampaignInfo("sensor", "sensor"),
            sensor=SensorResults(
                points=np.array([[0.0, 0.0], [1.0, 1.0]]),
                direction=("y", "y"),
                error_um=[1.0, np.nan],
                error_std_um=[np.nan, np.nan],
            ),
        ),
    }


@pytest.mark.parametrize("case", list(_degenerate()))
def test_degenerate_data_still_render(case: str, tmp_path) -> None:
    """No stiffness at all, a single position, too few points to interpolate: a page, no crash, no warning."""
    data = _degenerate()[case]
    page = write_report(data, tmp_path).read_text(encoding="utf-8")
    figs = _figures(page)
    assert figs  # something is drawn
    if data.measured is not None:
        m = data.measured
        assert f"{int(m.ok.sum())} of {m.n} positions with a stiffness" in page
        for msg in (msg for msg, ok in zip(m.messages, m.ok, strict=True) if not ok):
            assert f"<td class=l colspan=4>{msg}</td>" in page
    else:
        assert "1 of 2 point-direction measurements" in page and "no measurement" in page
