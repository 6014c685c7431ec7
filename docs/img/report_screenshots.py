"""Screenshots of the report's diagnostics for docs/report.md, from headless Chromium.

A vision campaign of the virtual test-bed (12 of the reference study's 48 positions, the
nine load cases, two repeats, a camera calibrated from 10 rendered views) and a sensor
campaign (the 3PRR's 22 points in x and y), each simulated, run and reported as a user
would; then each section of the page is captured as it renders in Chromium
(:func:`stiffmap.report.browser.check_page` with ``elements``)::

    stiffmap simulate /tmp/shots/delta --select 1,4,13,16,17,20,29,32,33,36,45,48 \\
        --repeats 2 --calibration-views 10 --seed 1 --name "virtual test-bed (12 positions)"
    stiffmap run /tmp/shots/delta --no-report
    stiffmap simulate /tmp/shots/prr --robot 3prr --repeats 1 --seed 1
    stiffmap run /tmp/shots/prr --no-report
    python docs/img/report_screenshots.py /tmp/shots/delta /tmp/shots/prr

Writes docs/img/report_*.png and docs/report-screenshot.png (the top of the vision page,
README's picture). Fails (exit 1) when the page does not render or logs an error.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from stiffmap.report.browser import check_page
from stiffmap.report.campaign import write_campaign_report

HERE = Path(__file__).resolve().parent

#: Page element -> file name (docs/img/report_<name>.png), per campaign kind.
VISION = {
    "#setup": "setup",
    "#image": "board_image",
    "#fig-calibration": "calibration",
    "#principal": "ellipsoids",
    "#fig-linearity": "linearity",
    "#fig-residual-detail": "residuals_per_load",
    "#fig-residuals": "residuals_rms",
    "#fig-truth": "truth",
}
SENSOR = {"#setup": "sensor_setup", "#fig-sensor-linearity": "sensor_linearity"}


def shoot(campaign: Path, elements: dict[str, str], top: Path | None = None) -> None:
    """Report ``campaign`` to a temporary folder and save its elements' screenshots."""
    with tempfile.TemporaryDirectory() as tmp:
        index = write_campaign_report(campaign, out_dir=Path(tmp) / "report", png=False)
        r = check_page(index, elements=list(elements), screenshot=top is not None, timeout=180)
        if not r.ok:
            sys.exit(f"{index}: the page did not render cleanly: {r.summary()}")
        for (sel, name), png in zip(elements.items(), r.shots, strict=True):
            if png is None:
                sys.exit(f"{campaign}: no {sel} in its report")
            (HERE / f"report_{name}.png").write_bytes(png)
            print(f"docs/img/report_{name}.png  {sel}")
        if top is not None:
            top.write_bytes(r.screenshot)
            print(top.relative_to(HERE.parent.parent))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    shoot(Path(sys.argv[1]), VISION, top=HERE.parent / "report-screenshot.png")
    shoot(Path(sys.argv[2]), SENSOR)
