"""Where a board's edges sit: the photometric model's ink spread and the edge-by-edge check.

Truth from an exact area-coverage drawing (tests/helpers/board_images.py, nothing shared with
stiffmap.sim), with a known ink spread (black squares printed larger) and known pose errors;
and Bouguet's real photographs (../shared/data/calib_example), where the edges and the
corners of the same board disagree (docs/vision.md, "Real photographs").
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers.board_images import area_board_image
from helpers.board_scenes import look_at_pose
from helpers.shared_data import CALIB_DIR
from scipy.ndimage import convolve1d

from stiffmap.camera import CameraModel
from stiffmap.targets import Chessboard
from stiffmap.vision import detect_board, estimate_pose, read_image
from stiffmap.vision.photometric import refine_pose_photometric
from stiffmap.vision.photometric.diagnostics import edge_agreement

CAM = CameraModel((640, 480), 800.0, 800.0, 319.5, 239.5, (0.0, 0.0, 0.0, 0.0, 0.0))
BOARD = Chessboard(9, 7, 15.0)
DIST = 400.0  # mm
CENTRE = np.array([60.0, 45.0, 0.0])  # the board's centre, mm


def _scene(ink_mm: float = 0.0, seed: int = 5):
    T = look_at_pose(DIST, BOARD, tilt_deg=(15.0, -10.0, 5.0))
    img = area_board_image(CAM, BOARD, T, rng=np.random.default_rng(seed), ink_mm=ink_mm)
    det = detect_board(img, BOARD)
    return T, img, det


def _px_per_mm(T) -> float:
    """Image scale at the board's centre, px per mm of board (mean of the two axes)."""
    c = T[:3, :3] @ CENTRE + T[:3, 3]
    return float(CAM.fx / c[2] * np.sqrt(abs(np.linalg.det(T[:2, :2]))))


def test_an_ink_spread_is_recovered_as_the_dilation_and_leaves_the_pose_true():
    """Black squares printed 0.12 mm larger on each side (0.29 px here): the fit's dilation
    recovers it, and the pose along the line of sight stays within 3 of its sigmas of the
    truth; the same fit with its dilation set to zero sees every edge that much towards its
    white side (edge_agreement, at the true pose)."""
    ink = 0.12
    T, img, det = _scene(ink_mm=ink)
    expected_px = ink * _px_per_mm(T)
    photo = estimate_pose(det, BOARD, CAM, image=img, refine="photometric")
    assert photo.method == "photometric" and photo.fallback is None
    fit = photo.photometric
    assert abs(fit.dilation_px - expected_px) < 0.1 * expected_px, (fit.dilation_px, expected_px)
    centre = T[:3, :3] @ CENTRE + T[:3, 3]
    los = centre / np.linalg.norm(centre)
    along = (photo.board2cam[:3, :3] @ CENTRE + photo.board2cam[:3, 3] - centre) @ los
    assert abs(along) < 3 * np.sqrt(los @ photo.cov[:3, :3] @ los)
    no_ink = replace(fit, dilation_px=0.0, dilation_anisotropy_px=(0.0, 0.0))
    seen = edge_agreement(img, BOARD, CAM, T, no_ink, phase=det.phase)
    assert abs(seen.toward_white_px - expected_px) < 0.1 * expected_px
    assert abs(seen.scale) < 3e-4 and np.hypot(*seen.offset_px) < 0.03


def test_edge_agreement_reads_a_known_pose_error():
    """At the true pose the edges agree with it; with the board moved 0.3 % farther along the
    camera's axis they sit 0.3 % farther from its centre than that pose puts them (scale); moved
    0.05 mm sideways they sit fx * 0.05 / z px the other way (offset)."""
    T, img, det = _scene()
    fit = refine_pose_photometric(img, BOARD, CAM, T, detection=det).photometric
    true = edge_agreement(img, BOARD, CAM, T, fit, phase=det.phase)
    assert abs(true.scale) < 3e-4 and np.hypot(*true.offset_px) < 0.03 and abs(true.toward_white_px) < 0.03
    assert true.rms_px < 0.05 and true.n_edges > 80
    eps = 0.003
    far = T.copy()
    far[:3, 3] *= 1.0 + eps
    seen = edge_agreement(img, BOARD, CAM, far, fit, phase=det.phase)
    assert seen.scale == pytest.approx(eps, rel=0.1)
    side = T.copy()
    side[0, 3] += 0.05
    du = CAM.fx * 0.05 / (T[:3, :3] @ CENTRE + T[:3, 3])[2]
    seen = edge_agreement(img, BOARD, CAM, side, fit, phase=det.phase)
    assert seen.offset_px[0] == pytest.approx(-du, abs=0.02) and abs(seen.offset_px[1]) < 0.02
    assert abs(seen.scale) < 3e-4


@pytest.mark.parametrize("name", ["Image2.tif", "Image11.tif"])
def test_bouguets_edges_sit_outside_his_corners(name, tmp_path):
    """On Bouguet's photographs (his published camera) the edges sit 0.05-0.3 % farther from
    the board's centre than the corner pose puts them (both sides of every edge alike: not an
    ink spread), while the photometric pose itself fits them: the disagreement that keeps the
    corner pose there (docs/vision.md, "Real photographs")."""
    cam = CameraModel((640, 480), 657.46, 657.94, 303.19, 242.05, (-0.25403, 0.12143, -0.00021, 0.00002, 0.0))
    board = Chessboard(13, 12, 30.0)
    img = read_image(CALIB_DIR / name)
    det = detect_board(img, board)
    corner = estimate_pose(det, board, cam, refine="corners")
    photo = refine_pose_photometric(img, board, cam, corner.board2cam, detection=det)
    at_corner = edge_agreement(img, board, cam, corner.board2cam, photo.photometric, phase=det.phase)
    at_photo = edge_agreement(img, board, cam, photo.board2cam, photo.photometric, phase=det.phase)
    assert 5e-4 < at_corner.scale < 3e-3, at_corner.scale
    assert abs(at_corner.toward_white_px) < 0.1
    assert abs(at_photo.scale) < 0.25 * at_corner.scale
    # The photometric pose is closer by about that scale times the distance.
    z_c, z_p = corner.board2cam[2, 3], photo.board2cam[2, 3]
    assert -3 * at_corner.scale < (z_p - z_c) / z_c < -0.3 * at_corner.scale


def _filtered(img: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """An 8-bit image filtered along its rows (a camera's line processing), 8 bits again."""
    out = convolve1d(img.astype(np.float64), kernel, axis=1, mode="nearest")
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


@pytest.mark.parametrize(
    "kernel, moves",
    [
        (np.array([-0.3, 0.0, 1.6, 0.0, -0.3]), False),  # symmetric sharpening along the rows
        (np.array([0.0, 0.0, 1.35, -0.2, -0.15]), True),  # causal: an undershoot after each step
    ],
)
def test_line_processing_moves_the_edges_against_the_corners_but_never_scales_them(kernel, moves):
    """A filter along the rows, as an analogue camera's line processing: a symmetric one leaves
    the edges where the corners are; a causal one (ringing after each step, as Bouguet's images
    show) moves the edges sideways against the corners (one image offset), and neither gives
    the scale seen on Bouguet's board (docs/vision.md, "Real photographs")."""
    T = look_at_pose(DIST, BOARD, tilt_deg=(15.0, -10.0, 5.0))
    img = _filtered(area_board_image(CAM, BOARD, T, rng=np.random.default_rng(5)), kernel)
    det = detect_board(img, BOARD)
    corner = estimate_pose(det, BOARD, CAM, refine="corners")
    fit = refine_pose_photometric(img, BOARD, CAM, corner.board2cam, detection=det).photometric
    seen = edge_agreement(img, BOARD, CAM, corner.board2cam, fit, phase=det.phase)
    assert abs(seen.scale) < 3e-4, seen.scale
    assert abs(seen.offset_px[1]) < 0.03
    assert (abs(seen.offset_px[0]) > 0.04) == moves, seen.offset_px  # measured 0.0004 and 0.073 px
