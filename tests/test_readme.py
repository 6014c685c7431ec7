"""The README's Python tour runs as written (issue 26, item 8: the API a newcomer finds first).

Every ```python block of README.md is executed in order, in one namespace (a block may use
what an earlier one made), from a
fresh folder beside a link to the real data (``../shared/data``, as the README says), with
warnings as errors. Then what the tour claims is checked against independent values:
Bouguet's published focal length, the stiffness the tour's displacements were made from, the
3PRR's joint stiffness the simulated campaign was written with.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

import pytest
from helpers.shared_data import CALIB_DIR, REPO


def _python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(), re.S)


@pytest.mark.slow
def test_the_readme_python_tour_runs_and_says_what_it_claims(tmp_path, monkeypatch):
    blocks = _python_blocks()
    assert blocks, "README.md has no Python block"
    tour = "\n".join(blocks)
    for topic in ("calibrate_files", "measure_files", "identify_stiffness", "DeltaRobot", "run_and_export"):
        assert topic in tour, f"the tour does not show {topic}"
    (tmp_path / "shared").symlink_to(Path(os.fspath(CALIB_DIR)).parents[1], target_is_directory=True)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    printed = io.StringIO()
    ns: dict = {"__name__": "readme_tour"}
    with contextlib.redirect_stdout(printed):
        for k, block in enumerate(blocks):
            exec(compile(block, f"README.md python block {k + 1}", "exec"), ns)
    # Bouguet's published calib_example result: fc = [657.46, 657.95] px (6 of 20 views here).
    assert abs(ns["cam"].fx - 657.46) < 3.0 and abs(ns["cam"].fy - 657.95) < 3.0
    assert (work / "camera.json").is_file()
    # K from displacements made with K = diag(2, 5, 9) N/mm and no noise.
    assert abs(ns["fit"].K[1, 1] - 5.0) < 1e-9 and ns["fit"].flags == ()
    # The point above the Delta's base is refused by name; the two below are evaluated.
    assert list(ns["m"].valid) == [True, True, False] and "above the base" in ns["m"].reasons[2]
    # The campaign's fit gives back the joint stiffness it was simulated with (600 N/mm).
    assert ns["summary"]["model_fits"][0]["params"]["kj"] == pytest.approx(600.0, rel=0.01)
    assert (work / "tour-campaign" / "report" / "index.html").is_file()
    assert "fx 65" in printed.getvalue()
