"""Displacement accuracy with two cameras, fused, beside camera 1 alone from the same images.

The issue's setup: two of the reference study's cameras (2592x1944 px, fx = 3733 px,
k1 = -0.09, k2 = 0.11; ``stiffmap.camera.reference_camera``) whose lines of sight meet 650 mm
in front of them, 60 degrees apart (camera 2 turned about the rig's y axis, to the right); an
8x6 board (inner corners) of 10 mm squares near the meeting point, facing the bisector (each
camera sees it tilted by about 30 degrees, plus a random tilt of up to 10 degrees about
each board axis, any roll, and an offset of up to 30 mm); noise as in the single-camera
benchmarks (the virtual test-bed's default photometry); displacements from 0.05 to 20 mm
along random directions with small rotations (up to 1 mrad). Per case an "unloaded" and a
"loaded" image set are rendered (four images, independent noise) and measured by
``PoseTracker(rig, board)``: each camera's photometric pose, fused in the rig frame
(``stiffmap.vision.fuse``). From the same camera-1 images, ``PoseTracker(camera1, board)``
gives the single-camera figures.

The rig is the true one (exact cameras and exact cam2rig), so the calibration's share of
the error is zero here: what is measured is the fusion of the image noise. Errors are those
of the displacement of the target origin in the rig frame (= camera 1's frame: x across, z
along camera 1's line of sight), and also along and across each camera's line of sight;
"error / sigma" divides each error by its predicted 1-sigma (from the two fused poses'
covariances) and takes the RMS (1 = calibrated).

Run:  .venv/bin/python benchmarks/bench_vision_rig.py [--quick] [--repeats N]
Saves benchmarks/results/vision_rig.md.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from _table import write  # noqa: E402
from helpers.board_images import TESTBED_RENDERER, testbed_board_image  # noqa: E402
from helpers.board_scenes import moved_pose, random_displacement  # noqa: E402
from helpers.rig_scenes import board2cams, board_in_rig, stereo_rig  # noqa: E402

from stiffmap.camera import reference_camera  # noqa: E402
from stiffmap.geometry import displacement_from_poses  # noqa: E402
from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision import PoseTracker  # noqa: E402

BOARD = Chessboard(8, 6, 10.0)
DISTANCE_MM = 650.0
ANGLE_DEG = 60.0
MAGNITUDES_MM = (0.05, 0.2, 1.0, 5.0, 20.0)
CLAIM_UM = 1.0
Z_RANGE = (0.8, 1.25)


def _board_symmetry(S_est):
    """The exact board symmetry (identity or the half turn about z) nearest to S_est."""
    flip = np.diag([-1.0, -1.0, 1.0, 1.0])
    flip[:2, 3] = [(BOARD.cols - 1) * BOARD.square_mm, (BOARD.rows - 1) * BOARD.square_mm]
    return flip if S_est[0, 0] < 0 else np.eye(4)


def _error(T0, T1, m0, m1):
    """Error of the measured displacement (rig frame, mm and rad) and its predicted 1-sigma."""
    S = _board_symmetry(np.linalg.inv(T0) @ m0.mobile2cam)
    truth = displacement_from_poses(T0 @ S, T1 @ S)
    meas = displacement_from_poses(m0.mobile2cam, m1.mobile2cam)
    sig = np.sqrt(np.diag(m0.mobile.cov) + np.diag(m1.mobile.cov))
    return meas - truth, sig


def one_case(rng, rig, magnitude):
    tilt = rng.uniform(-10, 10, size=2)
    T0 = board_in_rig(
        BOARD,
        distance_mm=DISTANCE_MM,
        angle_deg=ANGLE_DEG,
        tilt_deg=(tilt[0], tilt[1], rng.uniform(-180, 180)),
        offset_mm=rng.uniform(-30, 30, size=2),
    )
    T1 = moved_pose(T0, random_displacement(rng, magnitude))
    sets = [
        [
            testbed_board_image(c.camera, [(BOARD, Tc)], rng)
            for c, Tc in zip(rig.cameras, board2cams(rig, T), strict=True)
        ]
        for T in (T0, T1)
    ]
    fused = PoseTracker(rig, BOARD)
    m0, m1 = fused.measure(sets[0], "unloaded"), fused.measure(sets[1], "loaded")
    alone = PoseTracker(rig.cameras[0].camera, BOARD)
    a0, a1 = alone.measure(sets[0][0], "unloaded"), alone.measure(sets[1][0], "loaded")
    if not (m0.ok and m1.ok and a0.ok and a1.ok):
        return None
    e, s = _error(T0, T1, m0, m1)
    ea, sa = _error(T0, T1, a0, a1)
    n_photo = sum(v.method == "photometric" for m in (m0, m1) for v in m.mobile.views)
    chi2 = [m.mobile.chi2 for m in (m0, m1)]
    return e, s, ea, sa, n_photo, chi2


def rms(x, axis=0):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 cases per displacement (under a minute)")
    ap.add_argument("--repeats", type=int, default=None, help="cases per displacement (default 20)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "vision_rig.md"))
    args = ap.parse_args()
    n = args.repeats or (3 if args.quick else 20)
    rng = np.random.default_rng(20261212)
    rig = stereo_rig(reference_camera(), distance_mm=DISTANCE_MM, angle_deg=ANGLE_DEG, names=("cam1", "cam2"))
    axes = [c.cam2rig[:3, :3] for c in rig.cameras]  # each camera's axes in the rig frame
    t_start = time.perf_counter()
    lines = [
        "# Vision: displacement accuracy with two cameras (fused) and with camera 1 alone",
        "",
        f"Two reference cameras (2592x1944 px, fx = 3733 px, k1 = -0.09, k2 = 0.11) {ANGLE_DEG:g} degrees "
        f"apart, lines of sight meeting {DISTANCE_MM:g} mm away; 8x6 board, 10 mm squares, facing their "
        f"bisector (random tilt up to 10 degrees, any roll, offset up to 30 mm); {n} random cases per "
        "displacement (direction random, rotation <= 1 mrad); unloaded and loaded image sets with "
        f"independent noise. Renderer: {TESTBED_RENDERER}. The rig is the true one (exact cameras "
        "and cam2rig): the calibration's share is zero, the figures are the image noise's. Errors of "
        "the displacement of the target origin in the rig frame (camera 1's: x, y across its line of "
        "sight, z along it), RMS over the cases (bias included), um; camera 1 alone is measured from "
        "the same camera-1 images. error/sigma: RMS of each error over its predicted 1-sigma.",
        "",
        "| displacement (mm) | n | fused x / y / z (um) | camera 1 alone x / y / z (um) "
        "| fused error/sigma x / y / z | camera 1 alone error/sigma x / y / z |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    print("\n".join(lines), flush=True)
    E, S, EA, SA, failed, n_photo, n_views, chis = [], [], [], [], 0, 0, 0, []
    for mag in MAGNITUDES_MM:
        rows = []
        for _ in range(n):
            r = one_case(rng, rig, mag)
            if r is None:
                failed += 1
                continue
            rows.append(r)
            n_photo += r[4]
            n_views += 4
            chis += r[5]
        e = np.array([r[0] for r in rows])
        s = np.array([r[1] for r in rows])
        ea = np.array([r[2] for r in rows])
        sa = np.array([r[3] for r in rows])
        E.append(e)
        S.append(s)
        EA.append(ea)
        SA.append(sa)

        def three(v, f="{:.2f}"):
            return " / ".join(f.format(x) for x in v)

        row = (
            f"| {mag:g} | {len(e)} | {three(1000 * rms(e[:, :3]))} | {three(1000 * rms(ea[:, :3]))} | "
            f"{three(rms(e[:, :3] / s[:, :3]))} | {three(rms(ea[:, :3] / sa[:, :3]))} |"
        )
        lines.append(row)
        print(row, flush=True)
    E, S, EA, SA = (np.concatenate(x) for x in (E, S, EA, SA))
    fused_um = 1000 * rms(E[:, :3])
    alone_um = 1000 * rms(EA[:, :3])
    z_fused = rms(E[:, :3] / S[:, :3])
    z_alone = rms(EA[:, :3] / SA[:, :3])
    summary = [
        "",
        "## All displacements pooled",
        "",
        "| | n | x (um) | y (um) | z (um) | error/sigma x / y / z | rotation x / y / z (urad) |",
        "|---|---:|---:|---:|---:|---:|---:|",
        f"| two cameras, fused | {len(E)} | {fused_um[0]:.2f} | {fused_um[1]:.2f} | {fused_um[2]:.2f} | "
        f"{' / '.join(f'{x:.2f}' for x in z_fused)} | "
        f"{' / '.join(f'{x:.2f}' for x in 1e6 * rms(E[:, 3:]))} |",
        f"| camera 1 alone | {len(EA)} | {alone_um[0]:.2f} | {alone_um[1]:.2f} | {alone_um[2]:.2f} | "
        f"{' / '.join(f'{x:.2f}' for x in z_alone)} | "
        f"{' / '.join(f'{x:.2f}' for x in 1e6 * rms(EA[:, 3:]))} |",
        "",
        "Along and across each camera's line of sight (RMS per axis, um):",
        "",
        "| | across camera 1 | along camera 1 | across camera 2 | along camera 2 |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, err in (("two cameras, fused", E), ("camera 1 alone", EA)):
        cells = []
        for R in axes:
            local = err[:, :3] @ R  # components on the camera's axes
            cells += [f"{1000 * rms(local[:, :2].ravel()):.2f}", f"{1000 * rms(local[:, 2]):.2f}"]
        summary.append(f"| {name} | " + " | ".join(cells) + " |")
    met_um = bool(np.all(fused_um <= CLAIM_UM))
    met_z = bool(np.all((z_fused >= Z_RANGE[0]) & (z_fused <= Z_RANGE[1])))
    chis = np.array(chis)
    summary += [
        "",
        f"Target: at most {CLAIM_UM:g} um RMS along every axis with two cameras: "
        f"{'met' if met_um else 'NOT met'} (worst axis {fused_um.max():.2f} um; camera 1 alone "
        f"{alone_um.max():.2f} um along its line of sight). error/sigma RMS within "
        f"{Z_RANGE[0]}-{Z_RANGE[1]} on every axis: {'met' if met_z else 'NOT met'} "
        f"({', '.join(f'{x:.2f}' for x in z_fused)}).",
        "",
        f"Views refined photometrically: {n_photo} of {n_views}. Consistency of the two cameras' poses: "
        f"chi2 (6 dof) mean {chis.mean():.1f}, largest {chis.max():.1f} over {len(chis)} fused poses. "
        f"Cases where a target was not measured: {failed}.",
        "",
        f"_{time.strftime('%Y-%m-%d')}, Python {platform.python_version()}, {platform.machine()}, "
        f"run time {time.perf_counter() - t_start:.0f} s_",
    ]
    lines += summary
    print("\n".join(summary))
    write(args.out, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
