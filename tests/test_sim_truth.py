"""Must-show "renderer truth": OpenCV's sub-pixel corners on noise-free renders at the
reference camera agree with the exported true corners (<= 0.01 px mean bias, <= 0.03 px RMS),
over poses tilted up to 45 degrees across the whole image, distortion included."""

from __future__ import annotations

import numpy as np
from helpers.opencv_corners import opencv_corners_near

from stiffmap.camera import reference_camera
from stiffmap.sim.render import Photometry, Target, render
from stiffmap.sim.scene import spread_poses
from stiffmap.targets import Chessboard


def detect_corners(image: np.ndarray, truth: np.ndarray, pattern: tuple[int, int], win: int = 9):
    """findChessboardCornersSB + cornerSubPix on a crop around the board; errors vs truth (px)."""
    c = opencv_corners_near(image, truth, pattern, margin_px=70, half_window=win)
    if c is None:
        return None
    # OpenCV's numbering may start at either end; match each corner to its true one.
    idx = np.linalg.norm(c[:, None] - truth[None], axis=2).argmin(axis=1)
    assert sorted(idx) == list(range(len(truth)))
    return c - truth[idx]


def test_opencv_corners_agree_with_exported_truth():
    cam = reference_camera()
    board = Chessboard(7, 5, 10.0)
    poses = spread_poses(cam, board, grid=(3, 3), distance_mm=700.0, max_tilt_deg=45.0)
    tilts = [np.degrees(np.arccos(T[2, 2])) for T in poses]
    assert max(tilts) > 44.9
    targets = [Target(board, T, name=f"b{k}") for k, T in enumerate(poses)]
    r = render(cam, targets, photometry=Photometry.noise_free())
    errs = []
    for t in r.targets:
        assert t.in_image.all()
        e = detect_corners(r.image, t.corners_px, board.pattern_size)
        assert e is not None, f"board {t.name} not found"
        errs.append(e)
    E = np.concatenate(errs)
    # The true corners span the image, distortion included.
    allc = np.concatenate([t.corners_px for t in r.targets])
    assert allc[:, 0].min() < 400 and allc[:, 0].max() > 2200 and allc[:, 1].min() < 350
    bias = np.linalg.norm(E.mean(axis=0))
    rms = np.sqrt(np.mean(np.sum(E**2, axis=1)))
    assert bias <= 0.01, f"mean bias {bias:.4f} px"
    assert rms <= 0.03, f"RMS {rms:.4f} px"
