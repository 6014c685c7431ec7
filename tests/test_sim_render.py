"""Renderer of the virtual test-bed: exact coverage, textures, photometry, determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.board_images import brute_force_reflectance

from stiffmap.camera import CameraModel, reference_camera
from stiffmap.geometry import transform_from
from stiffmap.sim.render import (
    Photometry,
    Target,
    apply_photometry,
    encode_image,
    half_plane_area,
    render,
    render_reflectance,
    true_corners,
)
from stiffmap.sim.scene import board_pose_at_pixel
from stiffmap.sim.texture import texture_from_board
from stiffmap.targets import CharucoBoard, Chessboard

#: A small camera with the reference study's distortion, for fast tests.
SMALL = CameraModel((320, 240), 400.0, 398.0, 161.3, 118.7, (-0.09, 0.11, 0.0, 0.0, 0.0))


def test_half_plane_area_against_sampling(rng):
    n = 400
    g = (np.arange(n) + 0.5) / n - 0.5
    S, T = np.meshgrid(g, g)
    for _ in range(40):
        a, b = rng.normal(size=2)
        c = rng.uniform(-1.0, 1.0)
        ref = np.mean(a * S + b * T >= c)
        assert half_plane_area(a, b, c) == pytest.approx(ref, abs=3.0 / n)


def test_half_plane_area_exact_cases():
    # Axis-aligned line s >= c: area 1/2 - c; a line through the centre halves the square.
    for c in (-0.7, -0.5, -0.2, 0.0, 0.3, 0.5, 0.9):
        assert half_plane_area(1.0, 0.0, c) == pytest.approx(min(max(0.5 - c, 0.0), 1.0), abs=1e-15)
        assert half_plane_area(0.0, -2.0, c) == pytest.approx(min(max(0.5 - c / 2, 0.0), 1.0), abs=1e-15)
    assert half_plane_area(0.3, 0.8, 0.0) == pytest.approx(0.5, abs=1e-15)
    # Diagonal s + t >= 1/2: a right triangle of legs 1/2 -> 1/8.
    assert half_plane_area(1.0, 1.0, 0.5) == pytest.approx(0.125, abs=1e-15)


def test_edges_land_exactly_without_distortion():
    # Fronto-parallel board, no distortion, 4 px per mm: every edge pixel's value is
    # the exact fraction of the pixel it covers.
    cam = CameraModel((200, 160), 400.0, 400.0, 99.0, 79.0)
    board = Chessboard(4, 3, 10.0)
    # Corner (0, 0) at pixel (60.3, 49.85).
    T = transform_from(np.eye(3), [(60.3 - 99.0) / 4.0, (49.85 - 79.0) / 4.0, 100.0])
    tg = Target(board, T, margin_mm=5.0)
    img = render_reflectance(cam, [tg], background=0.0)
    w, k = tg.white, tg.black
    np.testing.assert_allclose(true_corners(cam, board, T)[0], [60.3, 49.85], atol=1e-9)
    # Column 60 covers u in [59.5, 60.5]: x < 0 on 0.8 of it (square (-1, j)), x >= 0 on 0.2.
    row = 60  # y in board frame: (60 - 49.85) / 4 = 2.54 mm -> squares j = 0
    sq_left, sq_right = (w, k)  # square (-1, 0) is white (odd), (0, 0) black (even)
    assert img[row, 60] == pytest.approx(0.8 * sq_left + 0.2 * sq_right, abs=1e-9)
    assert img[row, 59] == pytest.approx(sq_left, abs=1e-12)
    assert img[row, 61] == pytest.approx(sq_right, abs=1e-12)
    # Row 50 covers v in [49.5, 50.5]: y < 0 (squares j = -1) on 0.35, y >= 0 on 0.65.
    col = 70  # x = 2.425 mm -> i = 0
    assert img[50, col] == pytest.approx(0.35 * w + 0.65 * k, abs=1e-9)
    # The corner pixel (60, 50): four squares with areas 0.8*0.35, 0.2*0.35, 0.8*0.65, 0.2*0.65.
    ref = 0.8 * 0.35 * k + 0.2 * 0.35 * w + 0.8 * 0.65 * w + 0.2 * 0.65 * k
    assert img[50, 60] == pytest.approx(ref, abs=1e-9)
    # The board's outer boundary against the background (0): margin 5 mm = 20 px.
    x_out = 60.3 - 4 * (10.0 + 5.0)  # u of the left edge of the margin: 0.3 -> pixel 0 at 0.2 coverage
    assert x_out == pytest.approx(0.3)
    assert img[row, 0] == pytest.approx(0.2 * w, abs=1e-9)


@pytest.mark.parametrize(
    "board,tilt,spin",
    [
        (Chessboard(5, 4, 10.0), 0.0, 0.0),
        (Chessboard(5, 4, 10.0), 45.0, 20.0),
        (Chessboard(5, 4, 10.0), 60.0, -35.0),
        (CharucoBoard(5, 4, 10.0, 7.0), 40.0, 10.0),
    ],
)
def test_matches_brute_force_supersampling(board, tilt, spin):
    # Near the image corner (strongest distortion) and with strong perspective.
    cam = SMALL
    T = board_pose_at_pixel(
        cam, (250, 180), 300.0, (15.0, 10.0), tilt_deg=tilt, tilt_axis_deg=30, spin_deg=spin
    )
    tg = Target(board, T)
    c = np.round(true_corners(cam, board, T)[7]).astype(int)
    roi = (c[0] - 8, c[1] - 8, c[0] + 8, c[1] + 8)
    ours = render_reflectance(cam, [tg], roi=roi)
    ref = brute_force_reflectance(cam, tg, roi, n=64)
    # 64 x 64 point samples resolve coverage to about 1/64 of the contrast (0.86) at worst
    # and much better on average
    # (measured: max 0.0045, mean |.| < 1e-5, RMS < 1e-3; all shrink as n grows: the
    # reference's own error). An edge moved by 0.01 px would change its pixels by 0.009.
    assert np.abs(ours - ref).max() < 0.006
    assert abs(np.mean(ours - ref)) < 1e-4
    assert np.sqrt(np.mean((ours - ref) ** 2)) < 1.5e-3


def test_coverage_total_is_conserved():
    # Sum of the rendered image of a uniform white board on black = its projected area.
    cam = CameraModel((300, 300), 500.0, 500.0, 149.5, 149.5)
    board = Chessboard(3, 3, 10.0)
    T = board_pose_at_pixel(
        cam, (150, 150), 400.0, (10.0, 10.0), tilt_deg=35.0, tilt_axis_deg=60.0, spin_deg=12
    )
    tg = Target(board, T, margin_mm=2.0, white=1.0, black=1.0)
    img = render_reflectance(cam, [tg], background=0.0)
    # Exact projected area (no distortion): the board outline is a quadrilateral.
    x0, y0, x1, y1 = tg.texture().extent
    quad = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
    uv = cam.project(quad @ T[:3, :3].T + T[:3, 3])
    area = 0.5 * abs(np.dot(uv[:, 0], np.roll(uv[:, 1], -1)) - np.dot(uv[:, 1], np.roll(uv[:, 0], -1)))
    assert img.sum() == pytest.approx(area, rel=1e-6)


def test_colour_convention_and_charuco_match_opencv():
    # Fronto-parallel, no distortion, 10 px per mm with the board's outer corner on a
    # pixel boundary: every cell boundary falls on pixel boundaries, so our render
    # must equal OpenCV's own board image pixel for pixel.
    board = CharucoBoard(5, 4, 10.0, 7.0, "DICT_5X5_100")
    W, H = 50 * 10, 40 * 10
    cam = CameraModel((W, H), 1000.0, 1000.0, 0.0, 0.0)
    # Board point (-10, -10) (OpenCV's origin) at pixel boundary (-0.5, -0.5).
    T = transform_from(np.eye(3), [10.0 - 0.05, 10.0 - 0.05, 100.0])
    tg = Target(board, T, margin_mm=0.0, white=1.0, black=0.0)
    ours = render_reflectance(cam, [tg], background=0.5)
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    cvb = cv2.aruco.CharucoBoard((5, 4), 10.0, 7.0, d)
    ref = cvb.generateImage((W, H), marginSize=0, borderBits=1).astype(np.float64) / 255.0
    assert np.array_equal(np.round(ours, 9), ref)
    # Square (-1, -1) (top-left) is black: docs/conventions.md.
    assert ours[5, 5] == 0.0


def test_charuco_detected_with_right_ids_and_corners():
    cam = CameraModel((640, 480), 800.0, 800.0, 319.5, 239.5, (-0.09, 0.11, 0.0, 0.0, 0.0))
    board = CharucoBoard(6, 5, 10.0, 7.0, "DICT_5X5_100")
    T = board_pose_at_pixel(cam, (320, 240), 260.0, (20.0, 15.0), tilt_deg=25.0, tilt_axis_deg=70, spin_deg=8)
    r = render(cam, [Target(board, T)], photometry=Photometry.noise_free())
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    det = cv2.aruco.CharucoDetector(cv2.aruco.CharucoBoard((6, 5), 10.0, 7.0, d))
    corners, ids, _, _ = det.detectBoard(r.image)
    assert ids is not None and len(ids) == board.chessboard.n_corners
    truth = r.targets[0].corners_px
    err = corners.reshape(-1, 2) - truth[ids.ravel()]
    assert np.abs(err).max() < 0.15  # px; OpenCV's ChArUco refinement, not sub-0.01 px


def test_chessboard_colours_follow_the_convention_under_distortion():
    # Square (i, j) black when i + j is even (docs/conventions.md), checked at the
    # projected centre of every square, and OpenCV finds every corner.
    cam = CameraModel((640, 480), 800.0, 800.0, 319.5, 239.5, (-0.09, 0.11, 0.0, 0.0, 0.0))
    board = Chessboard(6, 5, 10.0)
    T = board_pose_at_pixel(cam, (330, 230), 300.0, (25.0, 20.0), tilt_deg=20.0, tilt_axis_deg=10, spin_deg=5)
    r = render(cam, [Target(board, T)], photometry=Photometry.noise_free())
    i, j = np.meshgrid(np.arange(-1, 6), np.arange(-1, 5))
    centres = np.stack([(i + 0.5) * 10.0, (j + 0.5) * 10.0, np.zeros_like(i, dtype=float)], -1).reshape(-1, 3)
    uv = np.rint(cam.project(centres @ T[:3, :3].T + T[:3, 3])).astype(int)
    vals = r.image[uv[:, 1], uv[:, 0]]
    black = ((i + j) % 2 == 0).ravel()
    assert vals[black].max() < 40 and vals[~black].min() > 150  # DN
    ok, c = cv2.findChessboardCornersSB(r.image, (6, 5), flags=cv2.CALIB_CB_ACCURACY)
    assert ok
    d = np.linalg.norm(c.reshape(-1, 1, 2) - r.targets[0].corners_px[None], axis=2)
    assert sorted(d.argmin(axis=1)) == list(range(30))
    assert d.min(axis=1).max() < 0.15  # px


def test_same_seed_gives_identical_png():
    cam = reference_camera()
    A = Target(Chessboard(9, 6, 10.0), board_pose_at_pixel(cam, (900, 900), 700.0, (40.0, 25.0), tilt_deg=20))
    B = Target(
        Chessboard(5, 4, 10.0), board_pose_at_pixel(cam, (1900, 1100), 650.0, (20.0, 15.0), tilt_deg=30)
    )
    ph = Photometry(clutter=True)
    png1 = encode_image(render(cam, [A, B], photometry=ph, seed=42).image)
    png2 = encode_image(render(cam, [A, B], photometry=ph, seed=42).image)
    png3 = encode_image(render(cam, [A, B], photometry=ph, seed=43).image)
    assert png1 == png2
    assert png1 != png3
    back = cv2.imdecode(np.frombuffer(png1, np.uint8), cv2.IMREAD_UNCHANGED)
    assert back.shape == (1944, 2592) and back.dtype == np.uint8


def test_photometry_levels_noise_and_vignetting(rng):
    cam = CameraModel((400, 300), 300.0, 300.0, 199.5, 149.5)
    flat = np.full((300, 400), 0.5)
    ph = Photometry(gain=0.8, offset_dn=10.0, read_noise_dn=1.5, shot_dn_per_e=0.05, blur_px=0, vignetting=0)
    img = apply_photometry(flat, cam, ph, rng).astype(np.float64)
    signal = 255 * 0.8 * 0.5
    assert img.mean() == pytest.approx(10.0 + signal, abs=0.05)  # DN
    assert img.std() == pytest.approx(np.sqrt(1.5**2 + 0.05 * signal + 1 / 12), rel=0.03)
    # cos^4 vignetting: at the corner the ray angle has tan^2 = (199.5^2 + 149.5^2) / 300^2.
    ph = Photometry.noise_free(gain=1.0, offset_dn=0.0, vignetting=1.0, blur_px=0.0)
    img = apply_photometry(np.full((300, 400), 0.8), cam, ph)
    tan2 = (199.5**2 + 149.5**2) / 300.0**2
    assert img[0, 0] == pytest.approx(255 * 0.8 / (1 + tan2) ** 2, abs=0.5)
    assert img[150, 200] == 204
    # Colour: a Bayer sensor demosaiced; a flat field keeps the white-balance ratios exactly.
    ph = Photometry.noise_free(
        colour=True, white_balance=(0.5, 1.0, 0.75), gain=1.0, offset_dn=0, vignetting=0
    )
    img = apply_photometry(np.full((300, 400), 0.8), cam, ph)
    assert img.shape == (300, 400, 3)
    np.testing.assert_array_equal(img[10, 10], np.rint(255 * 0.8 * np.array([0.5, 1.0, 0.75])))
    with pytest.raises(ValueError, match="rng"):
        apply_photometry(flat, cam, Photometry())


def test_sub_pixel_squares_average_to_grey():
    # A board so far and oblique that a pixel's footprint holds many squares: the
    # fallback (16 x 16 affine sub-samples) must still give the right mean level.
    cam = CameraModel((120, 90), 400.0, 400.0, 59.5, 44.5)
    board = Chessboard(30, 20, 1.0)
    T = board_pose_at_pixel(cam, (60, 45), 2000.0, (15.0, 10.0), tilt_deg=70.0, tilt_axis_deg=0.0)
    tg = Target(board, T, margin_mm=0.0)
    ours = render_reflectance(cam, [tg], background=0.0)
    roi = (55, 43, 65, 47)
    ref = brute_force_reflectance(cam, tg, roi, n=64, background=0.0)
    sub = ours[43:47, 55:65]
    assert sub.mean() == pytest.approx(ref.mean(), abs=0.01)
    assert np.abs(sub - ref).max() < 0.06


def test_jpeg_round_trip_is_close():
    cam = SMALL
    T = board_pose_at_pixel(cam, (160, 120), 300.0, (20.0, 15.0), tilt_deg=10)
    r = render(cam, [Target(Chessboard(5, 4, 10.0), T)], photometry=Photometry.noise_free(colour=True))
    data = encode_image(r.image, "jpeg", jpeg_quality=95)
    back = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert back.shape == r.image.shape
    assert np.mean(np.abs(back.astype(float) - r.image)) < 2.0  # DN
    with pytest.raises(ValueError, match="png or jpeg"):
        encode_image(r.image, "tiff")


def test_bad_inputs_are_refused():
    cam = SMALL
    board = Chessboard(5, 4, 10.0)
    a = np.radians(80.0)
    rot_y = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    with pytest.raises(ValueError, match="behind the camera"):
        render_reflectance(cam, [Target(board, transform_from(rot_y, [0.0, 0.0, 20.0]))])
    # z axis towards the camera: the back of the board.
    flip = np.diag([1.0, -1.0, -1.0])
    with pytest.raises(ValueError, match="seen from behind"):
        render_reflectance(cam, [Target(board, transform_from(flip, [0.0, 0.0, 300.0]))])
    with pytest.raises(ValueError, match="roi"):
        render_reflectance(cam, [], roi=(0, 0, 400, 10))
    with pytest.raises(ValueError, match="rotation"):
        Target(board, np.diag([1.0, 1.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="margin_mm"):
        texture_from_board(board, margin_mm=-1.0)
    with pytest.raises(ValueError, match="vignetting"):
        Photometry(vignetting=1.5)
    with pytest.raises(ValueError, match="dictionary"):
        texture_from_board(CharucoBoard(5, 4, 10.0, 7.0, "DICT_NOPE"))


def test_target_outside_the_image_leaves_background():
    cam = SMALL
    T = board_pose_at_pixel(cam, (160, 120), 300.0, (20.0, 15.0))
    T[0, 3] += 500.0  # far to the right, out of view
    img = render_reflectance(cam, [Target(Chessboard(5, 4, 10.0), T)], background=0.25)
    assert np.all(img == 0.25)
