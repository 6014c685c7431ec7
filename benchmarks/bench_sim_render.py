"""Speed of the virtual test-bed's renderer: a 2592x1944 image of two targets on ONE core.

Must-show (issue 4): rendering a 2592x1944 image of two targets takes under 1 s on one core.
The process is pinned to one CPU, and NumPy/OpenCV are limited to one thread. Times are
the median of several runs after one warm-up (the warm-up builds the per-camera ray
cache; its cost is reported separately as "first image").

Run:  .venv/bin/python benchmarks/bench_sim_render.py [--quick]
Saves benchmarks/results/sim_render.md.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from _table import write  # noqa: E402

from stiffmap import camera as C  # noqa: E402
from stiffmap.camera import reference_camera  # noqa: E402
from stiffmap.geometry import transform_from  # noqa: E402
from stiffmap.sim import photometry as P  # noqa: E402
from stiffmap.sim.render import Photometry, Target, encode_image, render  # noqa: E402
from stiffmap.sim.scene import board_pose_at_pixel, default_scene  # noqa: E402
from stiffmap.targets import CharucoBoard, Chessboard  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "sim_render.md"


def _scenes():
    cam = reference_camera()
    sc = default_scene(cam)
    yield "campaign scene, position (0, 0, -310)", sc.targets(transform_from(np.eye(3), [0, 0, -310.0])), {}
    yield (
        "campaign scene, nearest (-200, -200, -200)",
        sc.targets(transform_from(np.eye(3), [-200, -200, -200.0])),
        {},
    )
    big = [
        Target(
            Chessboard(13, 9, 10.0),
            board_pose_at_pixel(cam, (800, 950), 600.0, (60, 40), tilt_deg=30, tilt_axis_deg=80),
            "fixed",
        ),
        Target(
            Chessboard(7, 7, 10.0),
            board_pose_at_pixel(cam, (1900, 1000), 550.0, (30, 30), tilt_deg=40, tilt_axis_deg=10),
            "mobile",
        ),
    ]
    yield "two large boards at 0.55-0.6 m (~6 px/mm)", big, {}
    yield "same, clutter + colour", big, {"clutter": True, "colour": True}
    ch = [
        Target(
            CharucoBoard(12, 9, 10.0, 7.0),
            board_pose_at_pixel(cam, (800, 950), 600.0, (50, 35), tilt_deg=30, tilt_axis_deg=80),
        ),
        Target(
            CharucoBoard(7, 7, 10.0, 7.0, "DICT_4X4_50"),
            board_pose_at_pixel(cam, (1900, 1000), 550.0, (25, 25), tilt_deg=40, tilt_axis_deg=10),
        ),
    ]
    yield "two large ChArUco boards", ch, {}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    args = ap.parse_args()
    n_rep = 2 if args.quick else 7
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)
    cam = reference_camera()

    # Cold start: the per-camera ray spline is built by the first image.
    C._RAY_CACHE.clear()
    P._VIGNETTES.clear()
    first = next(iter(_scenes()))[1]
    t0 = time.perf_counter()
    render(cam, first, seed=0)
    cold = time.perf_counter() - t0

    rows = []
    for name, targets, extra in _scenes():
        ph = Photometry(**extra)
        render(cam, targets, photometry=ph, seed=0)  # warm
        tr, te = [], []
        for k in range(n_rep):
            t0 = time.perf_counter()
            r = render(cam, targets, photometry=ph, seed=k)
            t1 = time.perf_counter()
            data = encode_image(r.image, "png")
            t2 = time.perf_counter()
            tr.append(t1 - t0)
            te.append(t2 - t1)
        tj = []
        for _ in range(n_rep):
            t0 = time.perf_counter()
            encode_image(r.image, "jpeg", jpeg_quality=95)
            tj.append(time.perf_counter() - t0)
        mr, me = statistics.median(tr), statistics.median(te)
        rows.append((name, mr, me, mr + me, statistics.median(tj), len(data) / 1e6))
        print(f"{name:45s} render {mr:.3f} s  png {me:.3f} s  total {mr + me:.3f} s")

    lines = [
        "# Renderer speed (one core)",
        "",
        f"2592x1944 px, reference camera (k1 -0.09, k2 0.11), two targets, default photometry "
        f"(noise, vignetting, 0.8 px optics blur). Median of {n_rep} runs, process pinned to one CPU, "
        "single-threaded NumPy/OpenCV. Must-show: render < 1 s.",
        "",
        f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}, "
        f"NumPy {np.__version__}, OpenCV {cv2.__version__}.",
        "",
        "| scene | render (s) | PNG encode (s) | render + PNG (s) | JPEG q95 encode (s) | PNG size (MB) |",
        "|---|---|---|---|---|---|",
    ]
    for name, mr, me, tot, mj, size in rows:
        lines.append(f"| {name} | {mr:.3f} | {me:.3f} | {tot:.3f} | {mj:.3f} | {size:.2f} |")
    lines += [
        "",
        f"First image of a camera (builds the ray-spline cache, then renders): {cold:.3f} s.",
        "",
        f"Worst render time: {max(r[1] for r in rows):.3f} s "
        f"({'PASS' if max(r[1] for r in rows) < 1.0 else 'FAIL'}: < 1 s); "
        f"worst render + PNG: {max(r[3] for r in rows):.3f} s.",
        "",
    ]
    write(OUT, "\n".join(lines))


if __name__ == "__main__":
    main()
