"""A small simulated campaign from Python: the virtual test-bed renders it, stiffmap measures it.

``stiffmap simulate`` then ``stiffmap run`` as functions: the Delta-type robot of the
reference study at a few of its positions (``--select``), loaded by the study's nine load
cases (or the loads of a CSV file), seen by the reference camera; then K is identified at
each position from the rendered images and set beside the true K the test-bed kept.

    python examples/simulated_campaign.py OUT_DIR
    python examples/simulated_campaign.py OUT_DIR --select 1,22,48 --repeats 2 --report
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from stiffmap.campaign.run import run_and_export
from stiffmap.campaign.simulate import CameraSimOptions, SimulationRequest, simulate_campaign
from stiffmap.campaign.store import Store
from stiffmap.campaign.truth import load_truth
from stiffmap.report.campaign import write_campaign_report


def main(argv: list[str] | None = None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out", type=Path, help="a new (or empty) folder for the campaign")
    p.add_argument("--select", default="1,22", help="positions of the 48 (1-based), default 1,22")
    p.add_argument("--loads", default="paper9", help="paper9, or a CSV file of fx, fy, fz (N)")
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--report", action="store_true", help="also write OUT/report/ (HTML, PNG)")
    a = p.parse_args(argv)
    request = SimulationRequest(robot="delta", select=a.select, repeats=a.repeats, seed=1)
    camera = CameraSimOptions(loads=a.loads, calibration_views=0, workers=1)  # the true camera
    sim = simulate_campaign(a.out, request, camera=camera)
    print(f"simulated {sim.n_images} images in {sim.out_dir}")
    done = run_and_export(a.out, workers=1)
    truth = load_truth(a.out)
    with Store(done.db) as store:
        rows = store.stiffness_rows()
    for r in rows:
        Kt = np.asarray(truth.K[r.position - 1])
        err = np.linalg.norm(r.K - Kt) / np.linalg.norm(Kt) if r.status == "ok" else np.nan
        where = f"({r.x:g}, {r.y:g}, {r.z:g}) mm"
        print(f"position {r.position} {where}: {r.status}; |K - K_true| / |K_true| = {err:.2%}")
    if a.report:
        print("report:", write_campaign_report(done.root, done.failures))
    return done, rows, truth


if __name__ == "__main__":
    main()
