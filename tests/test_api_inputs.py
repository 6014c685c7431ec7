"""The Python API's inputs (issue 26, item 8): boards as text, load cases as columns.

``calibrate_files(paths, "9x6")`` raised a bare IndexError; every function taking a board now
takes ``"COLSxROWS"`` with ``square_mm`` (``stiffmap.targets.as_board``) and says what is
missing otherwise. Forces are columns in the arrays and rows in the CSV files: an array of
rows is refused with the hint to transpose it.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers.board_images import quick_board_image
from helpers.board_scenes import close_two_target_poses, small_camera

from stiffmap.identify import identify_stiffness
from stiffmap.loads import forces_matrix, paper9
from stiffmap.targets import CharucoBoard, Chessboard, as_board
from stiffmap.vision import calibrate_files, detect_board, estimate_pose, measure_files


def test_as_board_takes_text_with_its_square_and_names_what_is_missing():
    assert as_board("9x6", 25.0) == Chessboard(9, 6, 25.0)
    b = Chessboard(13, 12, 30.0)
    assert as_board(b) is b and as_board(b, 30.0) is b
    c = CharucoBoard(6, 5, 20.0, 15.0, "DICT_5X5_100")
    assert as_board(c) is c
    with pytest.raises(
        ValueError, match=r"board '9x6': .* needs its square size, e\.g\. board='9x6', square_mm="
    ):
        as_board("9x6")
    with pytest.raises(ValueError, match=r"fixed_board '9by6': board size must look like COLSxROWS"):
        as_board("9by6", 10.0, "fixed_board")
    with pytest.raises(ValueError, match=r"square_mm=25 but the board's squares are 30 mm"):
        as_board(b, 25.0)
    with pytest.raises(ValueError, match=r"board: expected a Chessboard, a CharucoBoard .* got list"):
        as_board([9, 6])


def test_calibrate_files_with_a_text_board_and_without_its_square(tmp_path):
    # What a newcomer typed (issue 26): a clear error, before any image is read.
    with pytest.raises(
        ValueError, match=r"board '9x6': a board given by its size also needs its square size"
    ):
        calibrate_files([tmp_path / "nothing.png"], "9x6")


def test_text_boards_measure_as_the_board_objects_do(tmp_path):
    """One rendered image: detection, pose and measure_files with "7x6" give what Chessboard gives."""
    cam = small_camera()
    mobile, fixed = Chessboard(7, 6, 10.0), Chessboard(9, 4, 10.0)
    M0, F = close_two_target_poses(mobile, fixed)
    img = quick_board_image(cam, [(fixed, F), (mobile, M0)], rng=np.random.default_rng(1))
    d_text = detect_board(img, "7x6", square_mm=10.0)
    d_obj = detect_board(img, mobile)
    np.testing.assert_array_equal(d_text.corners, d_obj.corners)
    p = estimate_pose(d_text, "7x6", cam, square_mm=10.0, refine="corners")
    np.testing.assert_allclose(p.board2cam[:3, 3], M0[:3, 3], atol=0.5)  # mm
    cv2.imwrite(str(tmp_path / "a.png"), img)
    (m,) = measure_files(
        [tmp_path / "a.png"], cam, "7x6", "9x4", square_mm=10.0, fixed_square_mm=10.0, refine="corners"
    )
    assert m.ok and m.fixed is not None
    np.testing.assert_allclose(m.mobile.board2frame, p.board2cam, atol=1e-3)  # mm; the same corner fit


def test_forces_as_rows_are_refused_with_the_hint_to_transpose():
    F = forces_matrix(paper9())  # (3, 9): one column per load case
    D = np.linalg.solve(np.diag([2.0, 5.0, 9.0]), F)
    with pytest.raises(ValueError, match=r"forces has shape \(9, 3\): one row per load case.*pass forces\.T"):
        identify_stiffness(F.T, D.T)
    np.testing.assert_allclose(identify_stiffness(F, D).K, np.diag([2.0, 5.0, 9.0]), atol=1e-9)
