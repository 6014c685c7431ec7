"""Fisheye and strong wide-angle lenses: stiffmap's lens models against OpenCV's fisheye calibration.

No public fisheye checkerboard set ships in a PyPI or Debian package (docs/vision.md says what
was searched), so the sets are:

- ``udacity``: 20 real photographs of a 9x6 board through a wide-angle automotive camera
  with strong barrel distortion (``../shared/data/real/udacity``, 1280x720; the two images
  of 1281x721 px are another camera's size and are left out by both pipelines);
- ``rendered 150 deg``: 20 careful views of the test-bed's 11x8 A3 board rendered through a
  150-degree fisheye (640x480 px, f = 300 px, OpenCV fisheye k = 0.03, -0.01, 0.002, -0.0003;
  the image corner 74 degrees off axis) with the renderer's realistic noise, blur and
  vignetting: the true camera is known.

For each set, on the views both detectors find (the same views for every row):

- stiffmap's calibration (its detector, ``calibrate_camera``) with the pinhole polynomial
  (``k3``, the default, and ``rational``) and with OpenCV's fisheye model (``fisheye``);
- OpenCV's documented fisheye pipeline: ``findChessboardCorners`` + ``cornerSubPix``
  (its tutorials' 11x11 half-window, and 5x5, 3x3 for small squares) +
  ``cv2.fisheye.calibrate`` (RECOMPUTE_EXTRINSIC | FIX_SKEW);

with the reprojection RMS, the share of the image where the fitted model is one to one
(``invertible_field``: undistortion defined and single-valued), and on the rendered set the
errors of fx, fy, cx, cy against the true camera and the corners' RMS error against their
true positions.

Run: .venv/bin/python benchmarks/bench_fisheye.py   (writes results/fisheye.md)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _table import save  # noqa: E402
from helpers.shared_data import REAL_SETS  # noqa: E402

from stiffmap.camera import CameraModel, invertible_field  # noqa: E402
from stiffmap.errors import InputError  # noqa: E402
from stiffmap.sim.calibration_views import CALIBRATION_BOARD, CALIBRATION_MARGIN_MM, careful_poses  # noqa: E402
from stiffmap.sim.photometry import Photometry  # noqa: E402
from stiffmap.sim.render import Target, render  # noqa: E402
from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision import detect_board, read_image  # noqa: E402
from stiffmap.vision.calibrate import calibrate_camera  # noqa: E402
from stiffmap.vision.files import image_files  # noqa: E402

TRUE = CameraModel((640, 480), 300.0, 300.5, 322.4, 238.7, (0.03, -0.01, 0.002, -0.0003), model="fisheye")
N_RENDERED = 20


def _flags() -> int:
    names = ("CALIB_RECOMPUTE_EXTRINSIC", "CALIB_FIX_SKEW")
    return sum(int(getattr(cv2.fisheye, n, None) or getattr(cv2, n)) for n in names)


#: cornerSubPix half-windows tried (OpenCV's tutorials use 11: a window wider than the
#: squares, as on the rendered fisheye's small squares near the image edge, pulls the corners).
WINDOWS = (11, 5, 3)


def _opencv_corners(grey: np.ndarray, board: Chessboard) -> np.ndarray | None:
    ok, c = cv2.findChessboardCorners(grey, board.pattern_size)
    return c if ok else None


def _subpix(grey: np.ndarray, c: np.ndarray, win: int) -> np.ndarray:
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    return cv2.cornerSubPix(grey, c.copy(), (win, win), (-1, -1), crit).reshape(-1, 2)


def _images(name: str):
    """(grey images, board, true camera or None, true corners or None) of a set."""
    if name == "udacity":
        folder = REAL_SETS["udacity"][0]
        imgs = [read_image(f) for f in image_files([folder])]
        return [g for g in imgs if g.shape == (720, 1280)], Chessboard(9, 6, 25.0), None, None
    imgs, truth = [], []
    for k, T in enumerate(careful_poses(TRUE, N_RENDERED, rng=np.random.default_rng(7))):
        tg = Target(CALIBRATION_BOARD, T, name="calibration", margin_mm=CALIBRATION_MARGIN_MM)
        r = render(TRUE, [tg], photometry=Photometry(), seed=np.random.default_rng(1000 + k))
        imgs.append(r.image)
        truth.append(r.targets[0].corners_px)
    return imgs, CALIBRATION_BOARD, TRUE, truth


def _row(label, cam: CameraModel, rms: float, n: int, seconds: float, true, corner_err) -> list:
    share = invertible_field(cam).image_share()
    errs = "-" if true is None else ", ".join(f"{e:+.3f}" for e in cam.params[:4] - true.params[:4])
    return [
        label,
        n,
        f"{rms:.4f}",
        f"{100 * share:.1f} %",
        f"{cam.fx:.2f}, {cam.fy:.2f}, {cam.cx:.2f}, {cam.cy:.2f}",
        errs,
        "-" if corner_err is None else f"{corner_err:.4f}",
        f"{seconds:.2f}",
    ]


def run_set(name: str) -> list[list]:
    imgs, board, true, truth = _images(name)
    h, w = imgs[0].shape
    ours, found, keep = [], [], []
    for k, g in enumerate(imgs):
        try:
            d = detect_board(g, board)
        except InputError:
            continue
        c = _opencv_corners(g, board)
        if c is None or d.n_corners != board.n_corners:
            continue
        ours.append(d)
        found.append(c)
        keep.append(k)
    err_ours = None
    if truth is not None:
        e1 = np.concatenate([d.corners - truth[k][d.ids] for d, k in zip(ours, keep, strict=True)])
        err_ours = float(np.sqrt(np.mean(np.sum(e1**2, axis=1))))
    rows = []
    for model in ("k3", "rational", "fisheye"):
        t = time.perf_counter()
        # Every view kept (outlier_factor large): the same views in every row.
        res = calibrate_camera(ours, board, (w, h), model=model, outlier_factor=1e9)
        dt = time.perf_counter() - t
        rows.append(
            _row(f"{name}: stiffmap {model}", res.camera, res.camera.rms_px, res.n_used, dt, true, err_ours)
        )
    for win in WINDOWS:
        theirs = [_subpix(imgs[k], c, win) for c, k in zip(found, keep, strict=True)]
        err_cv = None
        if truth is not None:
            e2 = np.concatenate([c - _match(truth[k], c) for c, k in zip(theirs, keep, strict=True)])
            err_cv = float(np.sqrt(np.mean(np.sum(e2**2, axis=1))))
        obj = [board.object_points().reshape(1, -1, 3).astype(np.float64) for _ in theirs]
        img = [c.reshape(1, -1, 2).astype(np.float64) for c in theirs]
        t = time.perf_counter()
        crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
        rms, K, D, _, _ = cv2.fisheye.calibrate(
            obj, img, (w, h), np.eye(3), np.zeros(4), flags=_flags(), criteria=crit
        )
        dt = time.perf_counter() - t
        cam = CameraModel((w, h), K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(np.ravel(D)), model="fisheye")
        label = f"{name}: OpenCV fisheye pipeline, cornerSubPix {win}x{win}"
        rows.append(_row(label, cam, rms, len(theirs), dt, true, err_cv))
    return rows


def _match(truth: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """The true corners in OpenCV's order (nearest neighbour: OpenCV may number from either end)."""
    d = np.linalg.norm(corners[:, None, :] - truth[None, :, :], axis=2)
    return truth[np.argmin(d, axis=1)]


def main() -> None:
    rows = []
    for name in ("udacity", "rendered 150 deg"):
        rows += run_set(name)
    notes = __doc__.split("Run:")[0].split("\n", 1)[1]
    save(
        "fisheye",
        "Fisheye and wide-angle lenses: stiffmap's lens models and OpenCV's fisheye calibration",
        [
            "set: calibration",
            "views",
            "RMS px",
            "image one to one",
            "fx, fy, cx, cy (px)",
            "minus truth (px)",
            "corner error px",
            "time s",
        ],
        rows,
        notes=notes + "\nThe views are those where both detectors find the whole board; every view is kept "
        "(no outlier rejection), so each row fits the same views. 'corner error': RMS distance "
        "of the detector's corners to the true ones (rendered set only).",
    )


if __name__ == "__main__":
    main()
