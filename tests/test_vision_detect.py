"""Board detection: canonical order, several boards, tracking, ChArUco, and the failure messages."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.board_images import quick_board_image, warped_board_image
from helpers.board_scenes import (
    close_two_target_poses,
    exact_corners,
    look_at_pose,
    scaled_camera,
    small_camera,
)

from stiffmap.camera import CameraModel, reference_camera
from stiffmap.errors import InputError
from stiffmap.sim.calibration_views import CALIBRATION_BOARD, CALIBRATION_MARGIN_MM, careful_poses
from stiffmap.sim.render import Photometry, Target, render
from stiffmap.targets import CharucoBoard, Chessboard
from stiffmap.vision import DetectionError, detect_board, detect_boards, track_board
from stiffmap.vision.board_plane import trim_to_saddles

CAM = small_camera()
ODD = Chessboard(7, 6, 10.0)  # cols + rows odd: colours fix the origin
SYM = Chessboard(8, 6, 10.0)  # cols + rows even: looks the same turned by 180 degrees


def _img(scene, seed=0, **kw):
    return quick_board_image(CAM, scene, rng=np.random.default_rng(seed), **kw)


@pytest.mark.parametrize("roll", [0, 90, 180, 270, 135])
def test_colours_fix_the_frame_whatever_the_roll(roll):
    T = look_at_pose(250, ODD, tilt_deg=(10, -10, roll))
    d = detect_board(_img([(ODD, T)]), ODD, camera=CAM)
    gt = exact_corners(CAM, ODD, T)
    assert d.orientation == "colour"
    assert d.complete
    np.testing.assert_array_equal(d.ids, np.arange(ODD.n_corners))
    np.testing.assert_allclose(d.corners, gt, atol=0.08)  # px: canonical order, sub-pixel


def test_symmetric_board_follows_continuity_with_a_reference():
    T0 = look_at_pose(250, SYM, tilt_deg=(10, -10, 178))
    T1 = look_at_pose(250, SYM, tilt_deg=(10, -10, 184))
    d0 = detect_board(_img([(SYM, T0)]), SYM, camera=CAM)
    gt0 = exact_corners(CAM, SYM, T0)
    # Without a reference the x axis points to the image's right: here the board's is turned.
    assert d0.orientation == "default"
    np.testing.assert_allclose(d0.corners, gt0[::-1], atol=0.08)
    # With a reference in the true frame, continuity keeps it through the next image.
    ref = type(d0)(**{**d0.__dict__, "corners": gt0.copy()})
    d1 = detect_board(_img([(SYM, T1)], seed=1), SYM, camera=CAM, reference=ref)
    assert d1.orientation == "continuity"
    np.testing.assert_allclose(d1.corners, exact_corners(CAM, SYM, T1), atol=0.08)


def test_two_boards_are_told_apart_by_size():
    big = Chessboard(9, 6, 8.0)
    small = Chessboard(5, 4, 8.0)
    Tb = look_at_pose(330, big, tilt_deg=(5, 10, 2), offset_mm=(-45, 0))
    Ts = look_at_pose(300, small, tilt_deg=(-8, -5, -3), offset_mm=(55, 10))
    img = _img([(big, Tb), (small, Ts)])
    for order in ([small, big], [big, small]):
        dets = detect_boards(img, order, camera=CAM)
        for d, b in zip(dets, order, strict=True):
            T = Tb if b is big else Ts
            assert d.board is b
            np.testing.assert_allclose(d.corners, exact_corners(CAM, b, T)[d.ids], atol=0.08)


def test_boards_of_the_same_size_are_refused():
    with pytest.raises(DetectionError, match="same size") as e:
        detect_boards(np.zeros((100, 100), np.uint8), [SYM, Chessboard(6, 8, 20.0)])
    assert e.value.reason == "ambiguous"


def test_tracking_refines_small_motions_and_hands_over_large_ones():
    T0 = look_at_pose(250, ODD, tilt_deg=(10, -10, 3))
    d0 = detect_board(_img([(ODD, T0)]), ODD, camera=CAM)
    T1 = T0.copy()
    T1[:3, 3] += [0.4, -0.3, 0.5]  # mm: a few px
    img1 = _img([(ODD, T1)], seed=2)
    d1 = track_board(img1, d0, camera=CAM)
    assert d1 is not None and d1.tracked
    np.testing.assert_allclose(d1.corners, exact_corners(CAM, ODD, T1), atol=0.08)
    # Half a square of motion: refinement could lock on a neighbour, so it is refused...
    T2 = T0.copy()
    T2[:3, 3] += [5.0, 0.0, 0.0]
    img2 = _img([(ODD, T2)], seed=3)
    assert track_board(img2, d0, camera=CAM) is None
    # ...and detect_board falls back to the full detection.
    d2 = detect_board(img2, ODD, previous=d0, camera=CAM)
    assert not d2.tracked
    np.testing.assert_allclose(d2.corners, exact_corners(CAM, ODD, T2), atol=0.08)


@pytest.mark.parametrize("shift", [(1, 0), (0, 1), (1, 1)])
def test_a_board_moved_by_a_whole_square_is_not_tracked_one_square_off(shift):
    """Moved by a square (along its rows, columns or both), the previous corners each land on
    the neighbouring corner and the grid fits: tracking must refuse it (found with two cameras,
    where one camera's loaded pose came out a square off), and the full search numbers it."""
    for board in (ODD, SYM):
        T0 = look_at_pose(250, board, tilt_deg=(10, -10, 3))
        d0 = detect_board(_img([(board, T0)]), board, camera=CAM)
        T1 = T0.copy()
        T1[:3, 3] += T0[:3, :3] @ [shift[0] * board.square_mm, shift[1] * board.square_mm, 0.0]
        T1[:3, 3] += [0.05, -0.04, 0.0]  # and a little more
        img1 = _img([(board, T1)], seed=5)
        assert track_board(img1, d0, camera=CAM) is None
        d1 = detect_board(img1, board, previous=d0, camera=CAM)
        assert not d1.tracked
        np.testing.assert_allclose(d1.corners, exact_corners(CAM, board, T1), atol=0.1)


def test_wrong_board_size_is_reported():
    T = look_at_pose(250, SYM, tilt_deg=(10, -10, 5))
    img = _img([(SYM, T)])
    # The size the image shows is named (the rendered board's, the test-bed's truth).
    with pytest.raises(DetectionError, match=r"shows a 8x6 chessboard .*did you mean --board 8x6\?") as e:
        detect_board(img, Chessboard(7, 5, 10.0), source="shot.png")
    assert e.value.reason == "wrong_size"
    assert (e.value.larger.cols, e.value.larger.rows, e.value.larger.whole) == (8, 6, True)
    assert str(e.value).startswith("shot.png:")
    with pytest.raises(DetectionError, match=r"9x6") as e:
        detect_board(img, Chessboard(9, 6, 10.0))
    assert e.value.reason in ("wrong_size", "partial")


def test_a_far_board_seen_whole_only_at_finer_scale_is_named_with_its_size():
    """A 9x6 board 1.5 m away at 50 degrees: the coarse search sees a 5x3 piece only."""
    board = Chessboard(9, 6, 10.0)
    T = look_at_pose(1500, board, tilt_deg=(50, 0, 0), offset_mm=(-150, -250))
    img = render(reference_camera(), [Target(board, T)], seed=1).image
    with pytest.raises(DetectionError, match=r"shows a 9x6 chessboard .*--board 9x6\?") as e:
        detect_board(img, Chessboard(8, 5, 10.0))
    assert e.value.reason == "wrong_size"
    assert (e.value.larger.cols, e.value.larger.rows) == (9, 6)


def test_partly_hidden_and_missing_boards():
    T = look_at_pose(250, SYM, tilt_deg=(10, -10, 5))
    with pytest.raises(DetectionError, match="no complete 8x6") as e:
        detect_board(_img([(SYM, T)], occluder=(330, 0, 640, 480)), SYM, source="hidden.png")
    assert e.value.reason == "partial" and "hidden.png" in str(e.value)
    with pytest.raises(DetectionError, match="no 8x6 chessboard found") as e:
        detect_board(_img([]), SYM, source="empty.png")
    assert e.value.reason == "not_found"
    assert isinstance(e.value, InputError)


def test_a_corner_off_the_board_plane_is_rejected():
    T = look_at_pose(250, ODD, tilt_deg=(10, -10, 5))
    img = _img([(ODD, T)])
    gt = exact_corners(CAM, ODD, T)
    d = detect_board(img, ODD, camera=CAM)
    assert d.rejected.size == 0
    assert d.residual_px.max() < 0.1  # px
    # Paint a fake X-corner 3 px beside corner 17: the refinement follows it, the
    # homography test must drop it.
    img2 = img.copy()
    x, y = np.round(gt[17]).astype(int)
    patch = img[y - 12 : y + 13, x - 12 : x + 13].copy()
    img2[y - 12 : y + 13, x - 9 : x + 16] = patch
    d2 = detect_board(img2, ODD, camera=CAM)
    assert 17 in d2.rejected
    assert 17 not in d2.ids and d2.n_corners >= ODD.n_corners - 3


def _charuco_image(hide_right: bool):
    board = CharucoBoard(7, 5, 20.0, 14.0, "DICT_5X5_100")
    dic = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    ocv = cv2.aruco.CharucoBoard((7, 5), 20.0, 14.0, dic)
    px = 10  # texture px per mm
    tex = ocv.generateImage((7 * 20 * px, 5 * 20 * px), marginSize=0)
    tex = cv2.copyMakeBorder(tex, 200, 200, 200, 200, cv2.BORDER_CONSTANT, value=255)
    # Texture pixel of board point (x, y) mm (our frame: origin at the first inner corner).
    A = np.array([[px, 0, 200 + 20 * px - 0.5], [0, px, 200 + 20 * px - 0.5], [0, 0, 1.0]])
    H = np.array([[3.0, 0.4, 140], [-0.3, 2.8, 110], [5e-4, 2e-4, 1.0]])  # board mm -> image px
    img = cv2.warpPerspective(tex, H @ np.linalg.inv(A), (640, 480), flags=cv2.INTER_AREA, borderValue=90)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    if hide_right:
        img[:, 330:] = 90
    obj = board.object_points()[:, :2]
    gt = np.c_[obj, np.ones(len(obj))] @ H.T
    return img, board, gt[:, :2] / gt[:, 2:]


def test_charuco_corners_get_their_canonical_ids_even_when_partly_hidden():
    img, board, gt = _charuco_image(hide_right=False)
    d = detect_board(img, board)
    assert d.orientation == "markers" and d.complete
    np.testing.assert_allclose(d.corners, gt[d.ids], atol=0.35)  # px (texture resampling)
    img, board, gt = _charuco_image(hide_right=True)
    d = detect_board(img, board)
    assert 6 <= d.n_corners < 24 and not d.complete
    np.testing.assert_allclose(d.corners, gt[d.ids], atol=0.35)
    with pytest.raises(DetectionError, match="no DICT_5X5_100 markers"):
        detect_board(np.full((200, 300), 128, np.uint8), board)


def test_large_image_is_searched_reduced_and_refined_at_full_resolution():
    cam = reference_camera()
    T = look_at_pose(700, SYM, tilt_deg=(8, -12, 4), offset_mm=(15, 10))
    img = quick_board_image(cam, [(SYM, T)], rng=np.random.default_rng(4))
    d = detect_board(img, SYM, camera=cam)
    assert d.scale == 3  # 2592 px -> 864 px for the search
    gt = exact_corners(cam, SYM, T)
    np.testing.assert_allclose(d.corners, gt, atol=0.06)  # px
    assert np.sqrt(np.mean(np.sum((d.corners - gt) ** 2, axis=1))) < 0.03  # px


def test_one_board_tracked_the_other_searched_again():
    # The platform moves by half a square (tracking refused) while the base board stays:
    # the tracked board is hidden from the new search, which must find the platform's.
    fixed = Chessboard(9, 4, 10.0)
    M0, F = close_two_target_poses(ODD, fixed)
    M1 = M0.copy()
    M1[:3, 3] += [6.0, -4.0, 0.0]
    d0 = detect_boards(_img([(fixed, F), (ODD, M0)]), [ODD, fixed], camera=CAM)
    img1 = _img([(fixed, F), (ODD, M1)], seed=4)
    d1 = detect_boards(img1, [ODD, fixed], previous=d0, camera=CAM)
    assert not d1[0].tracked and d1[1].tracked
    np.testing.assert_allclose(d1[0].corners, exact_corners(CAM, ODD, M1), atol=0.08)
    np.testing.assert_allclose(d1[1].corners, exact_corners(CAM, fixed, F), atol=0.08)


def test_a_grid_followed_into_the_printed_margin_is_trimmed_back_to_the_board():
    # OpenCV's "larger" search may follow a board one row into its white margin (the
    # issue's "9x7 for a 9x6 board"): those "corners" sit on an edge, not where four squares
    # meet, and must not make the diagnosis say "a bigger grid". Board drawn by OpenCV alone.
    board = Chessboard(9, 6, 20.0)
    cam = CameraModel((1024, 768), 1300.0, 1300.0, 511.5, 383.5, (0.0, 0.0, 0.0, 0.0, 0.0))
    T = look_at_pose(600.0, board, tilt_deg=(15.0, -10.0, 3.0))
    img = warped_board_image(cam, board, T, margin_sq=2.0, background=20.0)
    grid = exact_corners(cam, board, T).reshape(board.rows, board.cols, 2)
    assert trim_to_saddles(img, grid).shape == grid.shape  # the board itself is kept whole
    for extended in (
        np.concatenate([grid, 2 * grid[-1:] - grid[-2:-1]], axis=0),  # one row into the margin
        np.concatenate([2 * grid[:, :1] - grid[:, 1:2], grid], axis=1),  # one column
    ):
        np.testing.assert_array_equal(trim_to_saddles(img, extended), grid)


def test_a_board_too_blurred_for_the_corner_refinement_is_a_detection_error():
    # A grid found by OpenCV whose corners the sub-pixel refinement nearly all drops (8 px
    # of optics blur on 30 px squares): fewer than 4 corners are left for the board-plane
    # fit, which is a detection error naming the blur, not an OpenCV exception (it was one).
    cam = scaled_camera(reference_camera(), 0.25)
    T = careful_poses(cam, 3, border_px=20.0)[1]
    target = Target(CALIBRATION_BOARD, T, margin_mm=CALIBRATION_MARGIN_MM)
    img = render(cam, [target], photometry=Photometry(blur_px=8.0), seed=1).image
    with pytest.raises(DetectionError, match="sub-pixel precision .blur") as e:
        detect_board(img, CALIBRATION_BOARD, source="blurred.png")
    assert e.value.reason == "partial"
