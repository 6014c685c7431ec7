"""The live camera's renderer: the static part once, the moving board's part per frame, the
same image as a full render (bit for bit, with the same noise draws)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.board_scenes import scaled_camera

from stiffmap.camera import CameraModel, pixel_rays, reference_camera
from stiffmap.campaign.demo import QUICK_POSITIONS
from stiffmap.geometry import matrix_from_rotvec, transform_from
from stiffmap.models.presets import paper48
from stiffmap.sim import coverage
from stiffmap.sim.coverage import render_block, render_block_tiled
from stiffmap.sim.live_camera import SimulatedCamera
from stiffmap.sim.live_render import FrameRenderer, RayWindow
from stiffmap.sim.render import Photometry, Target, render
from stiffmap.sim.robot import delta_robot
from stiffmap.sim.scene import demo_scene, spread_poses
from stiffmap.sim.testbed import seeded_generator
from stiffmap.targets import CharucoBoard, Chessboard

#: A small camera with strong barrel distortion (the spline's rays bend most at its corners).
DISTORTED = CameraModel((360, 280), 300.0, 300.0, 181.0, 139.0, (-0.32, 0.12, 0.0, 0.0, 0.0))


def _rays(camera, r0, r1, c0, c1):
    return pixel_rays(camera).block(
        np.arange(r0 - 1, r1 + 1, dtype=np.float64), np.arange(c0 - 1, c1 + 1, dtype=np.float64)
    )


@pytest.mark.parametrize(
    ("board", "max_tilt"),
    [
        (Chessboard(9, 6, 10.0), 60.0),
        (Chessboard(15, 14, 3.0), 75.0),  # squares of a few pixels: few tiles see one cell
        (CharucoBoard(7, 5, 20.0, 15.0), 45.0),  # markers: cells of every size
    ],
    ids=["chessboard", "small squares, 75 deg", "charuco"],
)
def test_tiles_give_every_pixel_render_block_gives(board, max_tilt, monkeypatch):
    """render_block_tiled fills a tile that sees one cell without working out its pixels: on
    boards seen up to 75 degrees, through a strongly distorted lens, in and out of the image,
    every value is render_block's, bit for bit."""
    w, h = DISTORTED.image_size
    poses = spread_poses(DISTORTED, board, grid=(3, 2), distance_mm=420.0, max_tilt_deg=max_tilt)
    rx, ry = _rays(DISTORTED, 0, h, 0, w)
    worked_out = []
    shade = coverage._shade

    def counted(x, *args):
        worked_out.append(x.size)
        return shade(x, *args)

    for T in poses:
        tg = Target(board, T, margin_mm=8.0)
        tex = tg.texture()
        ref = render_block(rx, ry, tex, T)
        for tile in (2, 5, 8):
            with monkeypatch.context() as m:
                m.setattr(coverage, "_shade", counted)
                col, cov = render_block_tiled(rx, ry, tex, T, tile)
            assert np.array_equal(col, ref[0]) and np.array_equal(cov, ref[1]), (tile, T)
    # The shortcut was taken: most pixels (background, inside squares) were not worked out.
    assert sum(worked_out) < 0.5 * len(worked_out) * w * h


def test_a_grazing_board_is_worked_out_pixel_by_pixel():
    """A board seen nearly edge-on (89.5 degrees: a pixel's footprint spans many cells, some rays
    nearly parallel to its plane) gives render_block's values."""
    cam = CameraModel((240, 200), 300.0, 300.0, 119.5, 99.5)
    board = Chessboard(9, 6, 10.0)
    R = matrix_from_rotvec([np.radians(89.5), 0.0, 0.0])
    T = transform_from(R, [-40.0, -10.0, 300.0])
    tg = Target(board, T, margin_mm=10.0)
    rx, ry = _rays(cam, 0, 200, 0, 240)
    ref = render_block(rx, ry, tg.texture(), T)
    assert np.any(ref[1] > 0)
    col, cov = render_block_tiled(rx, ry, tg.texture(), T, 8)
    assert np.array_equal(col, ref[0]) and np.array_equal(cov, ref[1])


def test_ray_window_gives_the_ray_cache_values():
    rays = pixel_rays(DISTORTED)
    win = RayWindow(DISTORTED, margin_px=4)
    for r0, c0, n, m in ((-1, -1, 30, 40), (5, 7, 10, 12), (3, 3, 5, 5), (200, 300, 81, 61)):
        rows = np.arange(r0, r0 + n, dtype=np.float64)
        cols = np.arange(c0, c0 + m, dtype=np.float64)
        a, b = win.block(rows, cols), rays.block(rows, cols)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    # (5, 7) and (3, 3) fell inside the first window; (200, 300) moved it.
    assert win.moves == 2
    # Not a run of whole pixels: evaluated as asked.
    rows = np.array([1.5, 2.5, 7.0])
    a, b = win.block(rows, rows), rays.block(rows, rows)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def _demo_targets(scene, p, dt=(0.0, 0.0, 0.0), dr=(0.0, 0.0, 0.0)):
    T = transform_from(matrix_from_rotvec(dr), np.asarray(p) + np.asarray(dt))
    return scene.targets(T)


@pytest.mark.parametrize(
    "photometry",
    [Photometry(), Photometry.noise_free(), Photometry(colour=True)],
    ids=["default", "noise-free", "colour"],
)
def test_frame_renderer_gives_the_full_render(photometry):
    """At quick-demo positions of the demo's scene (half-size camera), with the mobile board
    moved by a swing's worth between frames: FrameRenderer's frame is render()'s image, bit for
    bit, with the same seed (noise, vignetting, Bayer filter at odd and even patch origins)."""
    scene = demo_scene(scaled_camera(reference_camera(), 0.5))
    P = paper48()[np.asarray(QUICK_POSITIONS) - 1]
    fr = FrameRenderer(scene.camera, _demo_targets(scene, P[0])[:1], photometry)
    k = 0
    for p in P[[0, 3, 5]]:
        for dt, dr in (
            ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
            ((0.31, -0.07, 0.12), (2e-4, -1e-4, 3e-4)),
            ((0.55, 0.25, -0.4), (0.0, 5e-4, 0.0)),  # the patch starts one pixel further
        ):
            k += 1
            fixed, mobile = _demo_targets(scene, p, dt, dr)
            ref = render(scene.camera, [fixed, mobile], photometry=photometry, seed=seeded_generator(5, k))
            img = fr.frame([mobile], seeded_generator(5, k))
            assert img.shape == ref.image.shape and img.dtype == np.uint8
            assert np.array_equal(img, ref.image), (p, dt, dr)
    assert fr.full_frames == 0


def test_frame_renderer_falls_back_where_the_shortcut_does_not_hold():
    """A mobile board inside the fixed board's rendered area (the static patch would show it) and
    a cluttered background (drawn anew for every frame): rendered in full, the same image."""
    scene = demo_scene(scaled_camera(reference_camera(), 0.5))
    fixed, _ = scene.targets(np.eye(4))
    # The mobile board just below the fixed one: its outline within the fixed board's blur reach.
    T = fixed.board2cam @ transform_from(np.eye(3), [0.0, 80.0, -5.0])
    mobile = Target(scene.mobile_board, T, name="mobile", margin_mm=10.0)
    for ph in (Photometry(), Photometry(clutter=True)):
        fr = FrameRenderer(scene.camera, [fixed], ph)
        ref = render(scene.camera, [fixed, mobile], photometry=ph, seed=seeded_generator(9, 1)).image
        assert np.array_equal(fr.frame([mobile], seeded_generator(9, 1)), ref)
        assert fr.full_frames == 1


def test_simulated_camera_frames_are_the_full_renders():
    """The simulated camera with the static part rendered once shows, frame for frame, what it
    showed rendering every frame in full: through a move, a load's swing and a second position."""
    scene = demo_scene(scaled_camera(reference_camera(), 0.5))
    kw = dict(fps=5.0, time_constant_s=0.1, frequency_hz=1.7, seed=4)
    fast = SimulatedCamera(scene, delta_robot(), **kw)
    full = SimulatedCamera(scene, delta_robot(), static_once=False, **kw)
    P = paper48()[[0, 21]]
    with fast, full:
        for p in P:
            for cam in (fast, full):
                cam.move_to(p)
            for i in range(4):
                if i == 1:
                    for cam in (fast, full):
                        cam.set_load([0.0, 4.9, 0.0])
                a, b = fast.grab(), full.grab()
                assert np.array_equal(a.tcp2base, b.tcp2base)
                assert np.array_equal(a.image, b.image)
    assert fast._renderer is not None and fast._renderer.full_frames == 0
