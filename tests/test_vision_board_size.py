"""A wrong ``--board`` on real photographs: refused early with the size the images show (issue 26).

Bouguet's calibration example (../shared/data/calib_example/README.md) shows a 13x12 board. Asked
for 9x6, OpenCV's exhaustive search threads 9x6 grids through it (skipping squares, running
diagonally) on several views; those used to calibrate silently to fx 1364, fy 930, k3 64, RMS
10.9 px. Now no such grid is accepted, the larger board is followed to its size, and
calibration stops after a few images with that size named.
"""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest
from helpers.shared_data import CALIB_DIR, REAL_SETS

from stiffmap.camera import CameraModel, plausibility_problems
from stiffmap.errors import InputError
from stiffmap.targets import Chessboard
from stiffmap.vision import detect_board, read_image
from stiffmap.vision.board_plane import grid_edge_fraction
from stiffmap.vision.board_size import AGREE, SAMPLE
from stiffmap.vision.calibrate import calibration_problems, grouped_reasons
from stiffmap.vision.chessboard import MIN_EDGE_FRACTION, grow_grid, seed_grid
from stiffmap.vision.detection import DetectionError
from stiffmap.vision.files import calibrate_files, image_files

REAL = Chessboard(13, 12, 30.0)  # Bouguet's board (its README)
SMALL = Chessboard(9, 6, 30.0)


@pytest.fixture(scope="module")
def image18():
    return read_image(CALIB_DIR / "Image18.tif")


def test_a_grid_threaded_through_a_larger_board_is_not_a_board(image18):
    """Image18: OpenCV's exhaustive 9x6 search returns a grid whose columns skip squares."""
    ok, c = cv2.findChessboardCornersSB(image18, SMALL.pattern_size, flags=cv2.CALIB_CB_EXHAUSTIVE)
    if not ok:
        pytest.skip("this OpenCV build finds no 9x6 grid in Image18 (nothing to refuse)")
    spurious = c.reshape(SMALL.rows, SMALL.cols, 2).astype(float)
    true = detect_board(image18, REAL)
    assert true.complete
    whole = true.corners.reshape(REAL.rows, REAL.cols, 2)
    assert grid_edge_fraction(image18, whole) > 0.95  # every side of the board's grid is an edge
    assert grid_edge_fraction(image18, spurious) < MIN_EDGE_FRACTION
    with pytest.raises(DetectionError) as e:
        detect_board(image18, SMALL, source="Image18.tif")
    assert e.value.reason == "wrong_size"


def _answer(image, board) -> str:
    """What detection says of ``board`` in ``image``: found, the larger size named, or why not."""
    try:
        detect_board(image, board)
        return "found"
    except DetectionError as e:
        return e.larger.size if e.larger is not None else e.reason


def test_the_same_image_gets_the_same_answer_whatever_came_before():
    """OpenCV's SB detector draws from OpenCV's global random generator: before stiffmap reset it
    per call, Bouguet's Image15.tif searched for 9x6 alternated between "13x12" and "partial" on
    repeated calls, and a scan of the folder changed after detecting another set's boards."""
    image = read_image(CALIB_DIR / "Image15.tif")
    first = [_answer(image, SMALL) for _ in range(2)]
    for f in image_files([REAL_SETS["greninja"][0]])[:1]:
        _answer(read_image(f), Chessboard(9, 6, 25.0))
    assert first + [_answer(image, SMALL)] == [first[0]] * 3


def test_a_part_of_the_board_grows_to_the_whole_board(image18):
    """Three corners of the real board's grid seed it; growing finds all 13 x 12 (the README's)."""
    det = detect_board(image18, REAL)
    grid = det.corners.reshape(REAL.rows, REAL.cols, 2)
    seed = seed_grid(image18, grid[5:8, 6:9].reshape(-1, 2))
    assert seed is not None
    grown = grow_grid(image18, seed)
    # Its steps may be taken along either axis: the size, in either orientation.
    assert sorted(grown.grid.shape[:2]) == [REAL.rows, REAL.cols] and not grown.cut
    # Its corners are the detected ones (cornerSubPix against stiffmap's refinement, within a
    # small fraction of the 20-35 px squares).
    flat = grid.reshape(-1, 2)
    d = np.min(np.linalg.norm(grown.grid.reshape(-1, 1, 2) - flat[None], axis=-1), axis=1)
    assert np.median(d) < 0.3 and d.max() < 2.0


def test_calibrating_a_13x12_board_as_9x6_stops_early_naming_13x12():
    """The newcomer's case of issue 26: refused (no camera.json), the right size named, early."""
    paths = image_files([CALIB_DIR])
    with pytest.raises(InputError) as e:
        calibrate_files(paths, SMALL)
    msg = str(e.value)
    assert "did you mean --board 13x12?" in msg and "not 9x6" in msg
    # It stopped after a few images (of the 20; vision.board_size's check), not after searching them all.
    checked = int(msg.split(" of the ")[1].split(" images checked")[0])
    assert AGREE <= checked <= SAMPLE


def test_the_issue_camera_json_is_refused_by_every_rule():
    """camera.json of the 9x6 calibration of issue 26: fx 4410, fy 1433, cx 760 on 640 px, RMS 10.9."""
    bad = CameraModel((640, 480), 4410.0, 1433.0, 760.0, 180.0, (4.4, 32.0, -0.5, 0.4, 63.5), rms_px=10.9)
    keys = {k for k, _ in plausibility_problems(bad)}
    assert {"fy", "cx", "rms_px"} <= keys
    good = CameraModel((640, 480), 657.6, 658.0, 303.0, 242.9, (-0.26, 0.17, 0.0, 0.0, -0.12), rms_px=0.17)
    assert plausibility_problems(good) == []  # Bouguet's published camera passes


def test_views_that_fit_a_board_but_not_the_camera_are_flagged(image18):
    """calibration_problems: view RMS far above what the corners' own fit allows."""
    det = detect_board(image18, REAL)
    cam = CameraModel((640, 480), 657.6, 658.0, 303.0, 242.9, (-0.26, 0.17, 0.0, 0.0, -0.12))
    own = det.rms_residual_px
    assert calibration_problems(cam, [det], [1.5 * own + 0.05]) == ()
    (key, what), *_ = calibration_problems(cam, [det], [10.3])
    assert key == "views" and "10.3 px" in what


def test_a_mixed_folder_is_one_answer(tmp_path):
    """Two cameras' images and a stray file in one folder: the camera with the boards is
    calibrated, the other camera's images are one warning line, the stray file another."""
    for k in (1, 2, 3, 4):
        shutil.copy(CALIB_DIR / f"Image{k}.tif", tmp_path / f"Image{k}.tif")
    udacity = REAL_SETS["udacity"][0]
    for k in (2, 3):
        shutil.copy(udacity / f"calibration{k}.jpg", tmp_path / f"calibration{k}.jpg")
    (tmp_path / "notes.txt").write_text("not an image")
    (tmp_path / "x.png").write_text("not an image either")
    res = calibrate_files([tmp_path], REAL)
    assert res.n_used == 4 and res.camera.image_size == (640, 480)
    unused = [v for v in res.views if not v.used]
    lines = grouped_reasons([v.image for v in unused], [v.reason for v in unused])
    assert len(lines) == 2
    assert "(2 images): image is 1280x720 px, but 4 of the views are 640x480 px" in lines[0]
    assert "x.png: not an image file" in lines[1]


def test_grouped_reasons_keep_one_line_per_reason():
    names = [f"v{k}.png" for k in range(6)]
    reasons = ["a", "b", "a", "", "a", "a"]
    assert grouped_reasons(names, reasons) == ["v0.png, v2.png, v4.png ... v5.png (4 images): a", "v1.png: b"]
