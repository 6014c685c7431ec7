"""Sub-pixel corner refinement against rendered boards with exact corner positions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.board_images import QuickPhotometry, quick_board_image
from helpers.board_scenes import exact_corners, look_at_pose, small_camera

from stiffmap.camera import CameraModel
from stiffmap.targets import Chessboard
from stiffmap.vision import refine_corners

BOARD = Chessboard(9, 7, 10.0)


def _scene(roll_deg: float, noise: bool, seed: int = 3):
    # 1200 px focal length at 280 mm: 43 px squares, like the reference camera at 870 mm.
    cam = CameraModel((800, 600), 1200.0, 1200.0, 401.3, 298.6, (-0.1, 0.05, 0.0, 0.0, 0.0))
    T = look_at_pose(280, BOARD, tilt_deg=(8, -12, roll_deg), offset_mm=(3, -2))
    img = quick_board_image(cam, [(BOARD, T)], rng=np.random.default_rng(seed) if noise else None)
    return img, exact_corners(cam, BOARD, T)


@pytest.mark.parametrize("roll", [0.0, 4.0, 30.0])
def test_bias_on_noise_free_rendering_is_about_0p01_px(roll):
    # What is left without noise is the estimator's bias: perspective and lens curvature
    # inside the window (about 0.004-0.013 px RMS here, from 0.022 px for cornerSubPix).
    img, gt = _scene(roll, noise=False)
    start = gt + np.random.default_rng(1).uniform(-1.5, 1.5, gt.shape)
    c, ok = refine_corners(img, start, 10)
    assert ok.all()
    err = np.linalg.norm(c - gt, axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.015  # px
    assert err.max() < 0.03  # px


def test_more_accurate_than_cornersubpix_on_axis_aligned_edges():
    # Edges nearly parallel to the pixel grid are where resampling locks to pixels.
    img, gt = _scene(0.0, noise=True)
    start = gt + 0.4
    ours, ok = refine_corners(img, start, 10)
    cv, _ = (
        cv2.cornerSubPix(
            img,
            start.astype(np.float32).reshape(-1, 1, 2),
            (10, 10),
            (-1, -1),
            (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4),
        ).reshape(-1, 2),
        None,
    )
    rms_ours = np.sqrt(np.mean(np.sum((ours - gt) ** 2, axis=1)))
    rms_cv = np.sqrt(np.mean(np.sum((cv - gt) ** 2, axis=1)))
    assert ok.all()
    assert rms_ours < 0.02  # px, with read + shot noise
    assert rms_ours < 0.75 * rms_cv


def test_noise_level_scales_the_scatter():
    # Same corners, 4x the noise: the error grows (the estimator is noise-limited, not stuck).
    cam = small_camera()
    T = look_at_pose(230, BOARD, tilt_deg=(5, 5, 12))
    gt = exact_corners(cam, BOARD, T)
    errs = []
    for read in (0.5, 6.0):
        img = quick_board_image(
            cam, [(BOARD, T)], photometry=QuickPhotometry(read_noise=read), rng=np.random.default_rng(9)
        )
        c, ok = refine_corners(img, gt + 0.3, 8)
        errs.append(np.sqrt(np.mean(np.sum((c - gt) ** 2, axis=1))))
    assert errs[1] > 1.5 * errs[0]
    assert errs[1] < 0.2  # px: still sub-pixel at 6 grey levels of noise


def test_flat_area_and_border_are_flagged():
    img = np.full((100, 120), 128, np.uint8)
    img[:, 60:] = 200  # one straight edge, no corner
    pts = np.array([[30.0, 50.0], [60.0, 50.0], [2.0, 2.0]])
    c, ok = refine_corners(img, pts, 6)
    assert not ok[0]  # flat: singular gradient matrix
    assert not ok[1]  # a single edge: singular too
    assert not ok[2]  # window leaves the image


def test_input_checks():
    img = np.zeros((50, 50), np.uint8)
    with pytest.raises(ValueError, match="window"):
        refine_corners(img, [[10.0, 10.0]], 0)
    with pytest.raises(ValueError, match="NaN"):
        refine_corners(img, [[np.nan, 10.0]], 3)
    with pytest.raises(ValueError, match="2-D"):
        refine_corners(np.zeros((5, 5, 3), np.uint8), [[2.0, 2.0]], 1)
