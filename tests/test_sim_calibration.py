"""The test-bed's calibration views: the poses a careful user takes, seeded, and the demo's setting."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_scenes import scaled_camera, small_camera

from stiffmap.camera import reference_camera
from stiffmap.campaign.demo import demo_command, demo_config
from stiffmap.errors import InputError
from stiffmap.loads import paper9
from stiffmap.models.presets import paper48
from stiffmap.sim.calibration_views import (
    CALIBRATION_BOARD,
    CALIBRATION_MARGIN_MM,
    MAX_TILT_DEG,
    careful_poses,
    plan_calibration_views,
)
from stiffmap.sim.plan import vision_config
from stiffmap.sim.render import true_corners
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.testbed import plan_campaign

BORDER_PX = 20.0


def _printed_outline(camera, T) -> np.ndarray:
    """The printed board's outline (margin included) in the image, as a closed ring, px."""
    x0, y0, x1, y1 = CALIBRATION_BOARD.extent_mm()
    m = CALIBRATION_MARGIN_MM
    uv = camera.project_rectangle(T, (x0 - m, y0 - m, x1 + m, y1 + m), samples=17)
    n = len(uv) // 4  # sides: y0 then x1 forwards, y1 and x0 backwards make a ring
    return np.vstack([uv[: 2 * n], uv[2 * n : 3 * n][::-1], uv[3 * n :][::-1]])


def _area(ring: np.ndarray) -> float:
    x, y = ring.T
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))


@pytest.mark.parametrize(
    "camera",
    [reference_camera(), scaled_camera(reference_camera(), 0.25), small_camera()],
    ids=["reference", "quarter", "small"],
)
def test_careful_poses_keep_the_board_inside_and_span_the_image(camera):
    w, h = camera.image_size
    poses = careful_poses(camera, 20, border_px=BORDER_PX, rng=np.random.default_rng(3))
    assert len(poses) == 20
    rings = [_printed_outline(camera, T) for T in poses]
    for k, uv in enumerate(rings):
        # Every printed board wholly inside the image, BORDER_PX from its border.
        assert uv.min(axis=0).min() >= BORDER_PX - 1e-6, k
        assert uv[:, 0].max() <= w - 1 - BORDER_PX + 1e-6 and uv[:, 1].max() <= h - 1 - BORDER_PX + 1e-6, k
        # It covers roughly a quarter to a half of the image (less when tilted away).
        assert 0.18 < _area(uv) / (w * h) < 0.55, k
    # Into every corner of the image: a board touching both borders there (within 0.5 % of
    # the image's size: sliding along one border can stop a few px short of the other)...
    tol = np.maximum(0.005 * np.array([w, h]), 1.0)
    lo, hi = BORDER_PX + tol, np.array([w - 1, h - 1]) - BORDER_PX - tol
    for corner in ((0, 0), (1, 0), (0, 1), (1, 1)):
        touching = [
            all((uv[:, i].max() >= hi[i]) if c else (uv[:, i].min() <= lo[i]) for i, c in enumerate(corner))
            for uv in rings
        ]
        assert any(touching), corner
    # ... so that inner corners (the calibration's data) come within 18 % of the image
    # diagonal of each image corner: the margin and the outer squares, 50 mm, lie between
    # (measured 11-15 % at 2592x1944, 13-17 % at 648x486 where the 20 px border weighs more).
    uv = np.vstack([true_corners(camera, CALIBRATION_BOARD, T) for T in poses])
    for cx, cy in ((0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)):
        assert np.hypot(uv[:, 0] - cx, uv[:, 1] - cy).min() < 0.18 * np.hypot(w, h), (cx, cy)
    # Tilts up to the largest, about axes all round; a few distances.
    normals = np.array([T[:3, 2] for T in poses])
    tilt = np.degrees(np.arccos(np.abs(normals[:, 2])))
    assert MAX_TILT_DEG - 2.0 <= tilt.max() <= MAX_TILT_DEG + 1e-9
    assert (tilt > 35.0).sum() >= 6 and tilt.min() < 20.0
    azimuth = np.degrees(np.arctan2(normals[:, 1], normals[:, 0]))[tilt > 15.0]
    assert np.histogram(azimuth, bins=4, range=(-180, 180))[0].min() >= 2  # every quadrant
    centre = np.array(CALIBRATION_BOARD.extent_mm()).reshape(2, 2).mean(axis=0)
    depth = np.array([(T[:3, :2] @ centre + T[:3, 3])[2] for T in poses])  # mm
    assert depth.max() / depth.min() > 1.25


def test_careful_poses_are_seeded_and_refuse_nonsense():
    cam = small_camera()
    a = careful_poses(cam, 9, rng=np.random.default_rng(1))
    b = careful_poses(cam, 9, rng=np.random.default_rng(1))
    c = careful_poses(cam, 9, rng=np.random.default_rng(2))
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not any(np.allclose(x, y, atol=1e-3) for x, y in zip(a, c, strict=True))
    # Without a generator: the plan alone (no jitter), the same every time.
    assert all(
        np.array_equal(x, y) for x, y in zip(careful_poses(cam, 4), careful_poses(cam, 4), strict=True)
    )
    with pytest.raises(ValueError, match="n_views"):
        careful_poses(cam, 0)
    with pytest.raises(ValueError, match="max_tilt_deg"):
        careful_poses(cam, 3, max_tilt_deg=85.0)


def test_a_campaigns_views_follow_its_seed_format_and_setting():
    cfg = vision_config(delta_robot(), paper48()[[21]], paper9()[:3], repeats=1, seed=5, image_format="jpeg")
    views = plan_calibration_views(cfg)
    assert [v.file for v in views] == [f"calibration/view{k:02d}.jpg" for k in range(1, 21)]
    again = plan_calibration_views(vision_config(delta_robot(), paper48()[[21]], paper9()[:3], seed=5))
    assert all(np.array_equal(v.board2cam, u.board2cam) for v, u in zip(views, again, strict=True))
    other = plan_calibration_views(vision_config(delta_robot(), paper48()[[21]], paper9()[:3], seed=6))
    assert not np.allclose(views[0].board2cam, other[0].board2cam)
    # Illumination varies from view to view as from image to image (gain 3 %).
    gains = np.array([v.gain for v in views]) / cfg.photometry.gain
    assert 0.005 < gains.std() < 0.06
    # Their random draws are not any campaign image's (position 0 is no position).
    assert {v.spawn_key for v in views}.isdisjoint(j.spawn_key for j in plan_campaign(cfg).jobs)
    assert plan_calibration_views(cfg, 0) == ()
    assert (
        plan_calibration_views(vision_config(delta_robot(), paper48()[[21]], paper9(), calibration_views=0))
        == ()
    )
    for n in (1, 2, -1):
        with pytest.raises(InputError, match="calibration_views must be 0 .the true camera. or at least 3"):
            vision_config(delta_robot(), paper48()[[21]], paper9(), calibration_views=n)


def test_the_demo_records_its_calibration_setting():
    # A demo directory simulated with the true camera (or before calibration views) must be
    # simulated again, not reused: the recorded command tells them apart.
    calibrated = demo_command(demo_config(quick=True), quick=True)
    true_cam = demo_command(demo_config(quick=True, calibration_views=0), quick=True)
    assert "calibration_views=20" in calibrated and "calibration_views=0" in true_cam
    assert calibrated != true_cam != "stiffmap demo (quick=True, repeats=2, seed=1)"  # the older form
