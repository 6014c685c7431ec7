"""``stiffmap report``: render from the data dump, round trip, one-line errors."""

from __future__ import annotations

import json

from helpers.cli_process import assert_one_line_error, run_here


def test_example_then_rerender_from_its_data_gives_the_same_page(tmp_path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    p = run_here("report", "--example", "sensor", a, "--no-png", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["index"] == str(a / "index.html")
    assert out["files"] == ["data.json", "index.html"]
    # data.json -> ReportData -> page: the JSON dump carries everything the page shows.
    p = run_here("report", a / "data.json", b, "--no-png")
    assert p.returncode == 0, p.stderr
    assert f"report: {b / 'index.html'}" in p.stdout
    assert (b / "data.json").read_bytes() == (a / "data.json").read_bytes()
    assert (b / "index.html").read_bytes() == (a / "index.html").read_bytes()


def test_missing_data_file(tmp_path) -> None:
    p = run_here("report", tmp_path / "nope.json", tmp_path / "out")
    assert_one_line_error(p, "nope.json", "file not found")
    assert not (tmp_path / "out").exists()


def test_bad_key_names_file_and_key(tmp_path) -> None:
    bad = tmp_path / "data.json"
    bad.write_text(
        json.dumps(
            {
                "schema": "stiffmap.report/1",
                "campaign": {"name": "c", "kind": "sensor"},
                "sensor": {
                    "points": [[0, 0]],
                    "direction": ["x"],
                    "error_um": [1.0],
                    "error_std_um": [1.0, 2.0],
                },
            }
        )
    )
    p = run_here("report", bad, tmp_path / "out")
    assert_one_line_error(p, "data.json", "sensor.error_std_um", "expected shape (m,) with m = 1, got (2,)")


def test_unknown_example_and_screenshot_without_check(tmp_path) -> None:
    assert_one_line_error(
        run_here("report", "--example", "lidar", tmp_path / "o"),
        "unknown example 'lidar'",
        "vision, sensor",
    )
    p = run_here(
        "report", "--example", "sensor", tmp_path / "o", "--no-png", "--screenshot", tmp_path / "s.png"
    )
    assert_one_line_error(p, "--screenshot needs --check")
