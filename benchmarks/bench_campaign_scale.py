"""``stiffmap run`` at scale: 1 and 2 processes, a local Dask cluster, the decode floor, a projection.

Renders a campaign of the reference set-up on the virtual test-bed (2592x1944 PNG images
of two boards; by default 10 positions of ``paper48``, the nine ``paper9`` load cases and
10 repeats: 1000 images, plus 20 calibration views from which the camera is calibrated),
then, in one run on the same files:

- the decode floor: ``cv2.imread`` of every image, grey, in one process and in two;
- ``run_vision_campaign`` with 1 process, 2 processes, and on a ``distributed.LocalCluster``
  of 2 single-threaded workers (``stiffmap run --dask local --workers 2``), each from
  an empty database: detection, tracking, photometric poses, displacements, K, model fit;
- that the three databases hold the same rows (``dump_content``);
- the projected time of the reference study's campaign (48 positions x 9 loads x 10
  repeats x 2 images = 8 640 images) at the best measured rate.

Run: .venv/bin/python benchmarks/bench_campaign_scale.py [--positions 10] [--repeats 10]
     [--campaign DIR]  (measure an already rendered campaign instead of rendering one)
Saves benchmarks/results/campaign_scale.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import platform
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
from _table import RESULTS, markdown, write

from stiffmap.camera import load_camera
from stiffmap.campaign.demo import demo_config
from stiffmap.campaign.runner import run_vision_campaign
from stiffmap.campaign.simulated import write_campaign
from stiffmap.campaign.spec import load_spec
from stiffmap.campaign.store import DB_NAME, dump_content

#: The reference study's campaign: positions x load cases x repeats x (unloaded, loaded).
REFERENCE_IMAGES = 48 * 9 * 10 * 2
TARGET_S = 300.0


def _decode(paths: list[str]) -> int:
    for p in paths:
        if cv2.imread(p, cv2.IMREAD_GRAYSCALE) is None:
            raise RuntimeError(f"cannot decode {p}")
    return len(paths)


def _decode_rate(images: list[str], processes: int) -> float:
    t = time.perf_counter()
    if processes == 1:
        _decode(images)
    else:
        with ProcessPoolExecutor(processes) as ex:
            sum(ex.map(_decode, [images[k::processes] for k in range(processes)]))
    return len(images) / (time.perf_counter() - t)


def _render(out: Path, positions: int, repeats: int) -> float:
    cfg = demo_config(repeats=repeats)
    step = max(1, len(cfg.positions) // positions)
    cfg = dataclasses.replace(cfg, positions=cfg.positions[::step][:positions])
    t = time.perf_counter()
    write_campaign(out, cfg, workers=2, command="benchmarks/bench_campaign_scale.py")
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--positions", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--campaign", type=Path, default=None, help="an already rendered campaign")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.campaign or Path(tmp) / "campaign"
        t_render = None if args.campaign else _render(out, args.positions, args.repeats)
        images = sorted(str(p) for p in (out / "images").rglob("*.png"))
        n = len(images)
        rows = []
        floor = {}
        for p in (1, 2):
            floor[p] = _decode_rate(images, p)
            rows.append(
                [
                    "decode only (cv2.imread, grey): the floor",
                    p,
                    n,
                    f"{n / floor[p]:.1f}",
                    f"{floor[p]:.1f}",
                    "",
                ]
            )
        dumps = {}
        rates = {}
        for label, workers, dask in (
            ("stiffmap run", 1, None),
            ("stiffmap run", 2, None),
            ("stiffmap run --dask local (LocalCluster)", 2, "local"),
        ):
            for f in out.glob(DB_NAME + "*"):
                os.unlink(f)
            t = time.perf_counter()
            summary = run_vision_campaign(out, workers=workers, dask=dask)
            dt = time.perf_counter() - t
            assert summary.images == n and not summary.failures, summary.failures[:3]
            rates[(label, workers)] = n / dt
            dumps[(label, workers)] = dump_content(out / DB_NAME)
            rows.append([label, workers, n, f"{dt:.1f}", f"{n / dt:.1f}", f"{floor[workers] / (n / dt):.2f}"])
        first = next(iter(dumps.values()))
        same = all(d == first for d in dumps.values())
        best_key = max(rates, key=rates.get)
        best = rates[best_key]
        projected = REFERENCE_IMAGES / best
        summary_rows = [
            ["the three databases hold the same rows", "yes" if same else "NO"],
            [f"best rate ({best_key[0]}, {best_key[1]} processes)", f"{best:.1f} images/s"],
            [
                f"projected time of the reference campaign ({REFERENCE_IMAGES} images)",
                f"{projected:.0f} s ({projected / 60:.1f} min): "
                + ("under" if projected < TARGET_S else "OVER")
                + f" {TARGET_S / 60:.0f} min",
            ],
        ]
        spec = load_spec(out)
        w, h = load_camera(out / spec.camera.file).image_size
        notes = (
            f"{n} rendered {w}x{h} PNG images of two boards (the demo scene: fixed "
            f"{spec.targets.fixed.board} with corner poses, mobile {spec.targets.mobile.board} with "
            f"photometric poses, a campaign's default), {os.cpu_count()} CPUs"
            + (f"; rendering them took {t_render:.0f} s with 2 processes" if t_render else "")
            + ". Each run starts from an empty database. 'x decode' is the run's time per image over "
            "the decode floor's with as many processes."
        )
        title = "stiffmap run at scale: 1 and 2 processes, a local Dask cluster, the decode floor"
        headers = ["what", "processes", "images", "seconds", "images/s", "x decode"]
        stamp = (
            f"{datetime.date.today().isoformat()}, Python {platform.python_version()}, {platform.machine()}"
        )
        text = (
            f"# {title}\n\n{notes}\n\n{markdown(headers, rows)}\n\n"
            f"{markdown(['result', 'value'], summary_rows)}\n\n_{stamp}_\n"
        )
        print(text)
        write(RESULTS / "campaign_scale.md", text)


if __name__ == "__main__":
    main()
