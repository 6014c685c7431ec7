"""Real photographs: boards found by OpenCV's two detectors and by stiffmap, and the calibrations.

For every real set beside the repository (``../shared/data/calib_example``, Bouguet's
13x12 board, and the three cameras of ``../shared/data/real``, 9x6 boards), on the same
decoded images in one run:

- boards found by OpenCV's ``findChessboardCorners`` (default flags) and
  ``findChessboardCornersSB`` (default flags), by either of them, and by stiffmap's
  ``detect_board``; the images where OpenCV finds a board and stiffmap does not (there
  must be none);
- the corners' consistency with a plane (RMS distance to a homography plus polynomial
  model of the board, px) of stiffmap's corners and of OpenCV's classic corners refined
  by ``cornerSubPix`` (11x11 window), on the boards both find;
- stiffmap's calibration (k3 model; fix-k3 for Bouguet's set, the model he published)
  beside the published one where there is one.

Run: .venv/bin/python benchmarks/bench_real_sets.py   (writes results/real_sets.md)
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
from helpers.shared_data import CALIB_DIR, REAL_SETS  # noqa: E402

from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision import calibrate_files, detect_board, read_image  # noqa: E402
from stiffmap.vision.board_plane import fit_residuals  # noqa: E402
from stiffmap.vision.detection import DetectionError  # noqa: E402
from stiffmap.vision.files import image_files  # noqa: E402

#: Bouguet's published calibration of calib_example (after per-image corner windows; +/- ~3 sigma).
BOUGUET = {"fx": 657.4629, "fy": 657.9467, "cx": 303.1366, "cy": 242.5693}


def _plane_rms(board: Chessboard, corners: np.ndarray, ids: np.ndarray) -> float:
    res, _ = fit_residuals(corners.reshape(-1, 2), board.object_points()[ids, :2], None)
    return float(np.sqrt(np.mean(res**2)))


def _classic(grey: np.ndarray, board: Chessboard) -> np.ndarray | None:
    ok, c = cv2.findChessboardCorners(grey, board.pattern_size)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    return cv2.cornerSubPix(grey, c, (11, 11), (-1, -1), crit).reshape(-1, 2)


def run_set(name: str, files: list[Path], board: Chessboard, model: str) -> tuple[list, list]:
    n_c = n_sb = n_either = n_ours = 0
    ours_rms, cv_rms, missed = [], [], []
    t_cv = t_sb = t_ours = 0.0
    for f in files:
        grey = read_image(f)
        t = time.perf_counter()
        cv_corners = _classic(grey, board)
        t_cv += time.perf_counter() - t
        t = time.perf_counter()
        ok_sb, _ = cv2.findChessboardCornersSB(grey, board.pattern_size)
        t_sb += time.perf_counter() - t
        n_c += cv_corners is not None
        n_sb += bool(ok_sb)
        n_either += cv_corners is not None or bool(ok_sb)
        t = time.perf_counter()
        try:
            det = detect_board(grey, board)
        except DetectionError as e:
            t_ours += time.perf_counter() - t
            if cv_corners is not None or ok_sb:
                missed.append(f"{f.name} ({e.reason})")
            continue
        t_ours += time.perf_counter() - t
        n_ours += 1
        if cv_corners is not None:
            d = np.linalg.norm(cv_corners[None] - det.corners[:, None], axis=2)
            ours_rms.append(_plane_rms(board, det.corners, det.ids))
            cv_rms.append(_plane_rms(board, cv_corners[np.argmin(d, axis=1)], det.ids))
    n = len(files)
    det_row = [
        name,
        f"{grey.shape[1]}x{grey.shape[0]}",
        n,
        f"{n_c} ({1000 * t_cv / n:.0f} ms)",
        f"{n_sb} ({1000 * t_sb / n:.0f} ms)",
        n_either,
        f"{n_ours} ({1000 * t_ours / n:.0f} ms)",
        ", ".join(missed) or "none",
        f"{np.median(ours_rms):.3f} / {np.median(cv_rms):.3f}" if ours_rms else "n/a",
    ]
    res = calibrate_files(files, board, model=model)
    cam, sd = res.camera, res.camera.std
    cal = [name, model, f"{res.n_used} of {n}"]
    for k in ("fx", "fy", "cx", "cy"):
        v = getattr(cam, k)
        s = f"{v:.2f} ± {sd.get(k, float('nan')):.2f}"
        if name == "calib_example":
            s += f" (published {BOUGUET[k]:.2f}, {100 * (v - BOUGUET[k]) / BOUGUET[k]:+.3f} %)"
        cal.append(s)
    cal.append(f"{cam.rms_px:.3f}")
    return det_row, cal


def main() -> None:
    sets = [
        (
            "calib_example",
            sorted(CALIB_DIR.glob("Image*.tif"), key=lambda p: int(p.stem[5:])),
            Chessboard(13, 12, 30.0),
            "fix-k3",
        )
    ]
    for name, (folder, *_counts) in sorted(REAL_SETS.items()):
        sets.append((name, image_files([folder]), Chessboard(9, 6, 25.0), "k3"))
    det_rows, cal_rows = [], []
    for name, files, board, model in sets:
        d, c = run_set(name, files, board, model)
        det_rows.append(d)
        cal_rows.append(c)
    notes = (
        "Boards found on the same decoded images in one run (mean time per image). OpenCV: "
        "`findChessboardCorners` and `findChessboardCornersSB` with default flags on the full image. "
        "'missed' lists images where either OpenCV detector finds the board and stiffmap does not, "
        "with stiffmap's reason. Plane RMS: median over the boards both stiffmap and OpenCV classic "
        "find of the RMS distance of the corners to a homography + polynomial board model, px "
        "(stiffmap / OpenCV classic + cornerSubPix 11x11).\n\n"
        "Calibrations (`calibrate_files`, +/- 1 sigma): Bouguet's published values are the "
        "toolbox's 'after per-image corner windows' result (../shared/data/calib_example/README.md); "
        "the other sets have no published calibration."
    )
    headers = [
        "set",
        "size",
        "images",
        "OpenCV classic",
        "OpenCV SB",
        "either",
        "stiffmap",
        "missed",
        "plane RMS px (stiffmap / OpenCV)",
    ]
    text_rows = det_rows + [[""] * len(headers)]
    text_rows += [["**calibration**", "model", "views used", "fx", "fy", "cx", "cy", "RMS px", ""]]
    text_rows += [r + [""] for r in cal_rows]
    save("real_sets", "Real photographs: boards found and calibrations", headers, text_rows, notes)


if __name__ == "__main__":
    main()
