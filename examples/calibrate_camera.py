"""Calibrate a camera from photographs of a chessboard, as ``stiffmap calibrate`` does.

On the shared real photographs (Bouguet's Camera Calibration Toolbox example: 20 views of a
13 x 12 board of 30 mm squares, ../shared/data/calib_example) it prints the focal length,
principal point and distortion with their 1-sigma, to set beside the toolbox's published
fc = [657.46, 657.95] px, cc = [303.1, 242.6] px (its README).

    python examples/calibrate_camera.py ../shared/data/calib_example
    python examples/calibrate_camera.py FOLDER --board 13x12 --square-mm 30 --out camera.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from stiffmap.camera import save_camera
from stiffmap.targets import Chessboard, parse_board_size
from stiffmap.vision.files import calibrate_files, image_files


def main(argv: list[str] | None = None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("images", type=Path, help="a folder of images of the board (or image files)", nargs="+")
    p.add_argument("--board", default="13x12", help="inner corners COLSxROWS (default 13x12)")
    p.add_argument("--square-mm", type=float, default=30.0, help="side of a square, mm (default 30)")
    p.add_argument("--max-images", type=int, default=None, help="use the first N images only")
    p.add_argument("--out", type=Path, default=None, help="write camera.json there")
    a = p.parse_args(argv)
    files = image_files(a.images)[: a.max_images]
    board = Chessboard(*parse_board_size(a.board), a.square_mm)
    res = calibrate_files(files, board, model="fix-k3")  # k3 = 0, the Matlab toolbox's default
    cam, std = res.camera, res.camera.std
    print(f"{res.n_used} of {len(res.views)} views used; reprojection RMS {cam.rms_px:.4f} px")
    print(f"fc = [{cam.fx:.3f}, {cam.fy:.3f}] +/- [{std['fx']:.3f}, {std['fy']:.3f}] px (1 sigma)")
    print(f"cc = [{cam.cx:.3f}, {cam.cy:.3f}] +/- [{std['cx']:.3f}, {std['cy']:.3f}] px")
    print("kc = [" + ", ".join(f"{k:.5f}" for k in cam.dist[:5]) + "]")
    if a.out is not None:
        save_camera(cam, a.out)
        print(f"wrote {a.out}")
    return res


if __name__ == "__main__":
    main()
