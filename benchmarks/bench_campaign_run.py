"""``stiffmap run`` throughput on a rendered 5-Mpixel campaign: 1 worker, 2 workers, decode floor.

Renders the quick demo campaign (2592x1944 PNG images of two boards: 6 positions,
nine load cases, two repeats), then measures the same images three ways, in one run:

- the decode floor: ``cv2.imread`` of every image, grey, in one process (and in
  two, split in halves), i.e. what reading the files alone costs;
- ``run_campaign`` with one worker, then with two (a fresh database each time):
  detection + tracking + poses of both boards, displacements, identification.

Run: .venv/bin/python benchmarks/bench_campaign_run.py [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from _table import save


def _decode(paths: list[str]) -> int:
    import cv2

    for p in paths:
        img = cv2.imread(p, cv2.IMREAD_GRAYSCALE)
        assert img is not None
    return len(paths)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    from stiffmap.campaign.demo import demo_config
    from stiffmap.campaign.runner import run_campaign
    from stiffmap.campaign.simulated import write_campaign
    from stiffmap.campaign.store import DB_NAME

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "campaign"
        t = time.perf_counter()
        s = write_campaign(out, demo_config(quick=True, repeats=args.repeats), workers=2)
        t_sim = time.perf_counter() - t
        images = sorted(str(p) for p in (out / "images").rglob("*.png"))
        n = len(images)
        rows = []
        t = time.perf_counter()
        _decode(images)
        dt = time.perf_counter() - t
        rows.append(["decode only (cv2.imread, grey)", 1, n, f"{dt:.1f}", f"{n / dt:.1f}"])
        t = time.perf_counter()
        with ProcessPoolExecutor(2) as ex:
            sum(ex.map(_decode, [images[::2], images[1::2]]))
        dt = time.perf_counter() - t
        rows.append(["decode only (cv2.imread, grey)", 2, n, f"{dt:.1f}", f"{n / dt:.1f}"])
        for workers in (1, 2):
            for f in out.glob(DB_NAME + "*"):
                os.unlink(f)
            t = time.perf_counter()
            summary = run_campaign(out, workers=workers)
            dt = time.perf_counter() - t
            assert summary.images == n and not summary.failures, summary.failures
            rows.append(["stiffmap run (measure + identify + fit)", workers, n, f"{dt:.1f}", f"{n / dt:.1f}"])
        mpx = 2592 * 1944 / 1e6
        save(
            "campaign_run",
            "stiffmap run: images per second with 1 and 2 workers, beside the decode floor",
            ["what", "processes", "images", "seconds", "images/s"],
            rows,
            notes=(
                f"{n} rendered PNG images of {mpx:.1f} Mpixel ({s.bytes_written / n / 1e6:.1f} MB each), "
                f"two boards per image (9x6 fixed, 15x14 mobile), {os.cpu_count()} CPUs; rendering them took "
                f"{t_sim:.0f} s with 2 processes. Each run starts from an empty database."
            ),
        )


if __name__ == "__main__":
    main()
