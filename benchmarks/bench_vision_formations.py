"""Photometric versus corner-based displacements under image formations that are not the test-bed's.

The photometric model (``stiffmap.vision.photometric``) takes an edge as a Gaussian of one
effective sigma (optics blur and pixel box together), shaded and possibly dilated. The
virtual test-bed forms its images the same way (optics blur, then pixel integration), so
``bench_vision_photometric.py`` cannot tell whether the model holds on other optics. Here
the same scenes are drawn by formations that break that assumption:

(a) the test-bed renderer, ``stiffmap.sim.render`` (default Photometry: blur 0.8 px before
    pixel integration, gain 0.8, read noise 0.8 DN, shot 0.04 DN/e, vignetting 0.3): the
    baseline;
(b) a blur applied after pixel integration (sigma 0.8 px, ``cv2.GaussianBlur``), sharp
    optics: ``tests/helpers/board_images.area_board_image`` (exact pixel-area coverage)
    and ``warped_board_image`` (OpenCV's warp of a raster, 2x supersampled), both
    independent of stiffmap's renderer; noise 1 DN;
(c) the test-bed's optics and pixel integration, then an RGGB Bayer sensor (white balance
    0.92 / 1 / 0.88, noise per photosite) demosaiced by OpenCV (bilinear ``BayerBG2BGR``,
    edge-aware ``_EA``, ``_VNG``) and converted to grey (``helpers.board_images.bayer_board_image``);
(d) the test-bed's image (a) through JPEG at quality 95 and 85 (``cv2.imencode``, grey);
(e) a phone's chain: (c) edge-aware, compressed in colour by JPEG 85 (4:2:0), decoded grey.

Camera: a pinhole 1280x960 px, fx = fy = 1600 px (no distortion: (b) draws through a
homography). Each case draws a board (9x7 and 8x6 of 15 mm squares, 12x11 of 10 mm,
in turn), a distance of 450-900 mm (log-uniform), a pose (tilt up to 25 degrees, any roll,
anywhere the board stays in the image), a displacement of 0.05-2 mm along a random
direction and a rotation up to 1 mrad. Every formation draws the SAME cases (its own noise),
the unloaded and the loaded image; each pair is measured by two ``PoseTracker`` s,
``refine="corners"`` and ``refine="photometric"`` (the loaded image tracked from the
unloaded one, as in a campaign). The error of the measured displacement of the board's
centre is split along the line of sight and across it (per axis); "1 sigma" is the RMS over
the cases (bias included). A photometric pose that falls back is the corner pose (what a
user gets): its case counts in the photometric column with the corner pose's error.
error / predicted: RMS over the cases of the along-axis error divided by the 1 sigma
propagated from the two poses' covariances (1 = a calibrated covariance).

A separate script from ``bench_vision_photometric.py``: its scenes need a pinhole camera
(that one uses the distorted reference camera) and its table is one row per formation.

Run:  .venv/bin/python benchmarks/bench_vision_formations.py [--quick] [--cases N]
(40 cases: about 5 minutes on one free core, 7 on a shared one; --quick: 6 cases, about 1).
Saves benchmarks/results/vision_formations.md.
"""

from __future__ import annotations

import argparse
import platform
import re
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _table import write  # noqa: E402
from bench_vision_photometric import board_symmetry, draw_pose, rms  # noqa: E402
from helpers.board_images import (  # noqa: E402
    area_board_image,
    bayer_board_image,
    jpeg_image,
    testbed_board_image,
    warped_board_image,
)
from helpers.board_scenes import moved_pose, random_displacement  # noqa: E402

from stiffmap.camera import CameraModel  # noqa: E402
from stiffmap.geometry import displacement_from_poses  # noqa: E402
from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision import PoseTracker  # noqa: E402

BOARDS = (Chessboard(9, 7, 15.0), Chessboard(8, 6, 15.0), Chessboard(12, 11, 10.0))
DISTANCE_MM = (450.0, 900.0)


def _testbed(cam, board, T, rng):
    return testbed_board_image(cam, [(board, T)], rng)


#: (label, drawing(camera, board, board2cam, rng) -> uint8 grey image)
FORMATIONS = (
    ("(a) test-bed: sim.render (blur before integration)", _testbed),
    ("(b) blur after integration, exact coverage", lambda c, b, T, g: area_board_image(c, b, T, rng=g)),
    ("(b) blur after integration, OpenCV raster warp", lambda c, b, T, g: warped_board_image(c, b, T, rng=g)),
    ("(c) Bayer RGGB, bilinear demosaic", lambda c, b, T, g: bayer_board_image(c, [(b, T)], g)),
    (
        "(c) Bayer RGGB, edge-aware demosaic",
        lambda c, b, T, g: bayer_board_image(c, [(b, T)], g, demosaic="edge-aware"),
    ),
    ("(c) Bayer RGGB, VNG demosaic", lambda c, b, T, g: bayer_board_image(c, [(b, T)], g, demosaic="VNG")),
    ("(d) JPEG 95 of (a)", lambda c, b, T, g: jpeg_image(_testbed(c, b, T, g), 95)),
    ("(d) JPEG 85 of (a)", lambda c, b, T, g: jpeg_image(_testbed(c, b, T, g), 85)),
    (
        "(e) Bayer edge-aware + colour JPEG 85",
        lambda c, b, T, g: jpeg_image(
            bayer_board_image(c, [(b, T)], g, demosaic="edge-aware", colour=True), 85
        ),
    ),
)


def camera() -> CameraModel:
    return CameraModel((1280, 960), 1600.0, 1600.0, 639.5, 479.5, (0.0, 0.0, 0.0, 0.0, 0.0))


def draw_cases(n: int, seed: int):
    """n cases: (board, T0, T1), boards in turn."""
    rng = np.random.default_rng(seed)
    cam = camera()
    cases = []
    for k in range(n):
        board = BOARDS[k % len(BOARDS)]
        dist = float(np.exp(rng.uniform(*np.log(DISTANCE_MM))))
        T0 = draw_pose(rng, cam, board, dist)
        mag = float(np.exp(rng.uniform(np.log(0.05), np.log(2.0))))
        T1 = moved_pose(T0, random_displacement(rng, mag))
        cases.append((board, T0, T1))
    return cases


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def reason_of(fallback: str) -> str:
    """A fallback message without its numbers (to count the reasons)."""
    return re.sub(r"-?\d+(\.\d+)?", "#", fallback.replace("; corner pose kept", ""))


def one_case(cam, board, T0, T1, draw, rng):
    """Errors of both methods on one case: {method: (along, across, pred_along, n_fallbacks, reasons)}."""
    imgs = [draw(cam, board, T, rng) for T in (T0, T1)]
    centre = np.array([(board.cols - 1) * board.square_mm / 2, (board.rows - 1) * board.square_mm / 2, 0.0])
    los = T0[:3, :3] @ centre + T0[:3, 3]
    los /= np.linalg.norm(los)
    P = np.eye(3) - np.outer(los, los)
    out = {}
    for method in ("corners", "photometric"):
        tr = PoseTracker(cam, board, refine=method)
        m0 = tr.measure(imgs[0], "unloaded")
        m1 = tr.measure(imgs[1], "loaded")
        if not (m0.ok and m1.ok):
            out[method] = None
            continue
        S = board_symmetry(board, np.linalg.inv(T0) @ m0.mobile2cam)
        q = S[:3, :3].T @ (centre - S[:3, 3])
        truth = displacement_from_poses(T0 @ S, T1 @ S, q)[:3]
        meas = displacement_from_poses(m0.mobile2cam, m1.mobile2cam, q)[:3]
        C = np.zeros((3, 3))
        for m in (m0, m1):
            J = np.hstack([np.eye(3), -_skew(m.mobile2cam[:3, :3] @ q)])
            C += J @ m.mobile2cam_cov @ J.T
        err = meas - truth
        reasons = [reason_of(p.fallback) for p in (m0.mobile, m1.mobile) if p.fallback]
        out[method] = (
            float(err @ los),
            float(np.sqrt(np.sum((P @ err) ** 2) / 2)),
            float(np.sqrt(los @ C @ los)),
            reasons,
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="6 cases per formation (about a minute)")
    ap.add_argument("--cases", type=int, default=None, help="cases per formation (default 40)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "vision_formations.md"))
    args = ap.parse_args()
    n = args.cases or (6 if args.quick else 40)
    cam = camera()
    cases = draw_cases(n, 20261201)
    t_start = time.perf_counter()
    head = (
        "| image formation | n | along: corners / photometric (um) | gain along | bias along: corners / "
        "photometric (um) | across: corners / photometric (um) | gain across | error / predicted along: "
        "corners / photometric | fallbacks (of 2n) | lost |"
    )
    lines = [
        "# Vision: photometric versus corner-based poses under other image formations",
        "",
        f"Pinhole camera 1280x960 px, fx = fy = 1600 px; {n} cases per formation, the same for every "
        "formation (boards 9x7 and 8x6 of 15 mm squares and 12x11 of 10 mm in turn, 450-900 mm, tilt <= "
        "25 deg, any roll, displacement 0.05-2 mm along a random direction, rotation <= 1 mrad). Unloaded "
        "and loaded images of each formation (see benchmarks/bench_vision_formations.py) measured by "
        "PoseTracker with refine='corners' and refine='photometric'. Error of the displacement of the "
        "board's centre along the line of sight and across it (per axis); 1 sigma = RMS over the cases, "
        "bias included; bias = mean. A photometric fallback keeps the corner pose (and its error). "
        "Gain = corners / photometric. error / predicted: RMS of error over its propagated 1 sigma. "
        "Lost: cases where a tracker measured no pose.",
        "",
        head,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    print("\n".join(lines), flush=True)
    reasons_all: dict[str, Counter] = {}
    summary_rows = []
    for f_index, (label, draw) in enumerate(FORMATIONS):
        rng = np.random.default_rng([20261201, f_index])
        res: dict[str, list] = {"corners": [], "photometric": []}
        reasons: Counter = Counter()
        lost = 0
        for board, T0, T1 in cases:
            r = one_case(cam, board, T0, T1, draw, rng)
            if r["corners"] is None or r["photometric"] is None:
                lost += 1
                continue
            for k in res:
                res[k].append(r[k][:3])
            reasons.update(r["photometric"][3])
        C = np.array(res["corners"], dtype=float).reshape(-1, 3)
        Ph = np.array(res["photometric"], dtype=float).reshape(-1, 3)
        ac, ap_ = rms(C[:, 0]), rms(Ph[:, 0])
        cc, cp = rms(C[:, 1]), rms(Ph[:, 1])
        zc, zp = rms(C[:, 0] / C[:, 2]), rms(Ph[:, 0] / Ph[:, 2])
        nfb = sum(reasons.values())
        reasons_all[label] = reasons
        row = (
            f"| {label} | {len(C)} | {1e3 * ac:.1f} / {1e3 * ap_:.1f} | {ac / ap_:.1f}x | "
            f"{1e3 * np.mean(C[:, 0]):+.1f} / {1e3 * np.mean(Ph[:, 0]):+.1f} | "
            f"{1e3 * cc:.2f} / {1e3 * cp:.2f} | "
            f"{cc / cp:.1f}x | {zc:.2f} / {zp:.2f} | {nfb} | {lost} |"
        )
        summary_rows.append((label, ac / ap_, zp, nfb))
        lines.append(row)
        print(row, flush=True)
    tail = ["", "Fallback reasons (photometric refinement, counted over both images of each case):", ""]
    any_reason = False
    for label, reasons in reasons_all.items():
        for reason, k in reasons.most_common():
            tail.append(f'- {label}: {k} x "{reason}"')
            any_reason = True
    if not any_reason:
        tail.append("- none")
    g_min = min(summary_rows, key=lambda x: x[1])
    tail += [
        "",
        f"Smallest gain along the line of sight: {g_min[1]:.1f}x ({g_min[0]}).",
        "",
        f"_{time.strftime('%Y-%m-%d')}, Python {platform.python_version()}, {platform.machine()}, "
        f"run time {time.perf_counter() - t_start:.0f} s_",
    ]
    lines += tail
    print("\n".join(tail))
    write(args.out, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
