"""Accuracy of the virtual test-bed's renderer: where do the corners land?

1. Renderer against an independent brute-force reference (n x n exactly mapped point
   samples per pixel): the difference shrinks as n grows, i.e. it is the reference's error.
2. OpenCV's sub-pixel corners (findChessboardCornersSB + cornerSubPix) on renders at the
   reference camera (2592x1944, k1 -0.09, k2 0.11), nine 7x5 boards spread over the image
   and tilted up to 45 degrees, against the exported true corners: mean bias and RMS for
   several optics blurs, cornerSubPix windows and with sensor noise.

Run:  .venv/bin/python benchmarks/bench_sim_truth.py [--quick]
Saves benchmarks/results/sim_truth.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _table import write  # noqa: E402
from helpers.board_images import brute_force_reflectance  # noqa: E402

from stiffmap.camera import CameraModel, reference_camera  # noqa: E402
from stiffmap.sim.render import Photometry, Target, render, render_reflectance, true_corners  # noqa: E402
from stiffmap.sim.scene import board_pose_at_pixel, spread_poses  # noqa: E402
from stiffmap.targets import CharucoBoard, Chessboard  # noqa: E402

OUT = HERE / "results" / "sim_truth.md"


def detect(image, truth, pattern, win):
    lo = np.maximum(np.floor(truth.min(axis=0)).astype(int) - 70, 0)
    hi = np.ceil(truth.max(axis=0)).astype(int) + 70
    crop = np.ascontiguousarray(image[lo[1] : hi[1], lo[0] : hi[0]])
    if crop.ndim == 3:
        crop = cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY)
    ok, c = cv2.findChessboardCornersSB(crop, pattern, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    c = cv2.cornerSubPix(crop, c, (win, win), (-1, -1), crit).reshape(-1, 2).astype(np.float64) + lo
    d = np.linalg.norm(c[:, None] - truth[None], axis=2)
    idx = d.argmin(axis=1)
    if sorted(idx) != list(range(len(truth))):
        return None  # SB returned a wrong grid (locked on the border)
    return c - truth[idx]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    lines = ["# Renderer accuracy", ""]

    # 1. Brute force.
    cam_s = CameraModel((320, 240), 400.0, 398.0, 161.3, 118.7, (-0.09, 0.11, 0.0, 0.0, 0.0))
    cases = [
        ("chessboard, facing", Chessboard(5, 4, 10.0), 0.0, 0.0),
        ("chessboard, 45 deg", Chessboard(5, 4, 10.0), 45.0, 20.0),
        ("chessboard, 60 deg", Chessboard(5, 4, 10.0), 60.0, -35.0),
        ("ChArUco, 40 deg", CharucoBoard(5, 4, 10.0, 7.0), 40.0, 10.0),
    ]
    ns = (32, 64) if args.quick else (32, 64, 128)
    lines += [
        "## Renderer against brute-force supersampling",
        "",
        "16x16 px crop around a corner near the image corner of a 320x240 camera with the reference "
        "distortion; values are reflectances (contrast 0.86). The reference maps every sub-sample "
        "exactly (Newton undistortion, plane intersection) and point-samples the print.",
        "",
        "| case | n x n samples | max abs diff | mean diff | RMS diff |",
        "|---|---|---|---|---|",
    ]
    for name, board, tilt, spin in cases:
        T = board_pose_at_pixel(
            cam_s, (250, 180), 300.0, (15.0, 10.0), tilt_deg=tilt, tilt_axis_deg=30, spin_deg=spin
        )
        tg = Target(board, T)
        c = np.round(true_corners(cam_s, board, T)[7]).astype(int)
        roi = (c[0] - 8, c[1] - 8, c[0] + 8, c[1] + 8)
        ours = render_reflectance(cam_s, [tg], roi=roi)
        for n in ns:
            d = ours - brute_force_reflectance(cam_s, tg, roi, n=n)
            lines.append(
                f"| {name} | {n} | {np.abs(d).max():.2e} | {d.mean():+.1e} | {np.sqrt(np.mean(d**2)):.1e} |"
            )
            print(lines[-1])

    # 2. OpenCV corners against the truth.
    cam = reference_camera()
    board = Chessboard(7, 5, 10.0)
    poses = spread_poses(cam, board, grid=(3, 3), distance_mm=700.0, max_tilt_deg=45.0)
    targets = [Target(board, T) for T in poses]
    settings = [("noise-free", Photometry.noise_free(blur_px=b)) for b in (0.0, 0.5, 0.8, 1.0)]
    settings += [("default noise (seed 1)", Photometry())]
    if not args.quick:
        settings += [("default noise, colour Bayer (seed 1)", Photometry(colour=True))]
    wins = (5, 9) if args.quick else (5, 7, 9, 11)
    lines += [
        "",
        "## OpenCV sub-pixel corners against the exported truth",
        "",
        "Reference camera, nine 7x5 boards (10 mm squares) at 0.7 m spread over the whole image, "
        "tilts 0-45 deg (315 corners). findChessboardCornersSB (EXHAUSTIVE | ACCURACY) on a crop "
        "around each board, then cornerSubPix with the given half window. Bias = norm of the mean "
        "error vector; RMS = sqrt(mean |error|^2). Must-show: bias <= 0.01 px and RMS <= 0.03 px "
        "on noise-free renders (the test uses the default optics blur 0.8 px and half window 9).",
        "",
        "| photometry | optics blur (px) | cornerSubPix half window | boards found "
        "| bias (px) | RMS (px) | max (px) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, ph in settings:
        r = render(cam, targets, photometry=ph, seed=1)
        for win in wins:
            errs = [detect(r.image, t.corners_px, board.pattern_size, win) for t in r.targets]
            found = [e for e in errs if e is not None]
            E = np.concatenate(found)
            bias = np.linalg.norm(E.mean(axis=0))
            rms = np.sqrt(np.mean(np.sum(E**2, axis=1)))
            lines.append(
                f"| {name} | {ph.blur_px:g} | {win} | {len(found)}/9 "
                f"| {bias:.4f} | {rms:.4f} | {np.abs(E).max():.3f} |"
            )
            print(lines[-1])
    lines += [
        "",
        "With perfectly sharp edges (blur 0) the bias stays below 0.002 px but cornerSubPix's "
        "gradient estimate on a step edge aliases (RMS ~0.04 px): that is OpenCV's estimator, not "
        "the render (section 1). A real lens and sensor blur an edge over about a pixel; with the "
        "default 0.8 px the agreement is ~0.02 px RMS. 'boards found' < 9 means SB locked onto the "
        "white-margin border of a 45 deg board (a detection failure, not a sub-pixel error).",
        "",
    ]
    write(OUT, "\n".join(lines))


if __name__ == "__main__":
    main()
