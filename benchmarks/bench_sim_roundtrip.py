"""Round trip: how well does a simulated campaign give back the true stiffness?

A campaign of the default scene (reference camera 1.05-1.55 m in front of the robot, 9x6 fixed
and 6x5 mobile boards, 10 mm squares; the Delta model; paper9 loads) is measured and
identified with the campaign runner's own derivation (cam2base from the mean fixed-board
pose of each position, displacement of point_mm in the base frame, compliance estimator),
and each identified K is compared with truth.json (relative Frobenius error).

1. True corners (no images), with Gaussian corner noise of 0 to 0.03 px, 3 and 10 repeats.
2. Rendered images (default photometry: noise, vignetting, 0.8 px optics blur), corners found
   by OpenCV (findChessboardCornersSB + cornerSubPix, half window 5) on a crop around each
   board, poses by solvePnP: a stand-in for stiffmap's vision code, which lands later.

Run:  .venv/bin/python benchmarks/bench_sim_roundtrip.py [--quick]
Saves benchmarks/results/sim_roundtrip.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _table import write  # noqa: E402
from helpers.corner_round_trip import derive_from_true_corners, pnp_image_row, round_trip_from_true_corners  # noqa: E402
from helpers.opencv_corners import opencv_corners_near  # noqa: E402

from stiffmap.campaign.derive import derive_position  # noqa: E402
from stiffmap.campaign.measure import ImageRow  # noqa: E402
from stiffmap.campaign.positions import plan  # noqa: E402
from stiffmap.campaign.records import DisplacementRecord, StiffnessRecord  # noqa: E402
from stiffmap.campaign.simulated import write_campaign  # noqa: E402
from stiffmap.campaign.spec import load_spec  # noqa: E402
from stiffmap.campaign.store import record_of  # noqa: E402
from stiffmap.campaign.truth import load_truth  # noqa: E402
from stiffmap.loads import paper9  # noqa: E402
from stiffmap.sim.robot import delta_robot  # noqa: E402
from stiffmap.sim.scene import default_scene  # noqa: E402
from stiffmap.sim.testbed import SimConfig  # noqa: E402
from stiffmap.targets import Chessboard  # noqa: E402

OUT = HERE / "results" / "sim_roundtrip.md"
POSITIONS = np.array(
    [[-66.67, 66.67, -310.0], [-200.0, -200.0, -200.0], [200.0, 200.0, -400.0], [200.0, -200.0, -200.0]]
)


def rel_errors(res):
    return np.array([np.linalg.norm(K - Kt) / np.linalg.norm(Kt) for K, _, Kt in res])


def detect(image, truth_uv, pattern):
    """SB + cornerSubPix on a crop around the board (the crop only bounds the search)."""
    c = opencv_corners_near(image, truth_uv, pattern, margin_px=40, half_window=5)
    if c is None:
        return None
    # Canonical order (the vision code's job): match to the true corners.
    idx = np.linalg.norm(truth_uv[:, None] - c[None], axis=2).argmin(axis=1)
    if sorted(idx) != list(range(len(truth_uv))):
        return None
    return c[idx]


def image_round_trip(root: Path):
    spec = load_spec(root)
    truth = load_truth(root)
    cam = truth.camera
    fb = Chessboard.parse(spec.targets.fixed.board, spec.targets.fixed.square_mm)
    mb = Chessboard.parse(spec.targets.mobile.board, spec.targets.mobile.square_mm)
    rows, errs, failed = {}, [], 0
    for f, c in truth.corners().items():
        img = cv2.imread(str(root / f), cv2.IMREAD_GRAYSCALE)
        um = detect(img, c["mobile"]["corners_px"], mb.pattern_size)
        uf = detect(img, c["fixed"]["corners_px"], fb.pattern_size)
        if um is None or uf is None:
            failed += 1
            rows[f] = ImageRow(f, False, "not found")
            continue
        errs.append(np.r_[um - c["mobile"]["corners_px"], uf - c["fixed"]["corners_px"]])
        rows[f] = pnp_image_row(f, um, uf, mb, fb, cam)
    loads = spec.loads.resolve(spec.g)
    res = []
    for task in plan(spec, root):
        r = derive_position(task, rows, loads, spec, "compliance", "", "")
        s = record_of(StiffnessRecord, r.stiffness)
        res.append((s.K, s.K_std, truth.K[task.index - 1]))
    E = np.concatenate(errs)
    return res, failed, float(np.sqrt(np.mean(np.sum(E**2, axis=1))))


def disp_noise(root: Path, noise: float) -> np.ndarray:
    """Std of the displacement error per base axis (mm), from true corners + noise (px)."""
    truth, loads, derived = derive_from_true_corners(root, noise, seed=0)
    dev = []
    for task, r in derived:
        Kt = truth.K[task.index - 1]
        for d in r.displacements:
            rec = record_of(DisplacementRecord, d)  # the row as it is stored, decoded
            dev.append(np.asarray(rec.d)[:3] - np.linalg.solve(Kt, loads[rec.load - 1].force))
    return np.asarray(dev).std(axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    lines = [
        "# Round trip: simulated campaign -> measured K vs truth.json",
        "",
        "Default scene (reference camera, 9x6 fixed and 6x5 mobile boards, 10 mm squares), Delta "
        "model, paper9 loads, robot repeatability 0.02 mm (shared by a pair) and 1 um per-image "
        "jitter. Positions: (-66.67, 66.67, -310), (-200, -200, -200), (200, 200, -400), "
        "(200, -200, -200) mm. K error = |K - K_true|_F / |K_true|_F per position. Identification "
        "and displacements by the campaign runner (stiffmap.campaign.derive.derive_position).",
        "",
        "## 1. True corners + Gaussian corner noise (no images)",
        "",
        "| corner noise (px) | repeats | K error per position (%) | worst (%) "
        "| displacement error std x, y, z (mm) |",
        "|---|---|---|---|---|",
    ]
    noises = (0.0, 0.01, 0.03) if args.quick else (0.0, 0.005, 0.01, 0.02, 0.03)
    reps = (3,) if args.quick else (3, 10)
    with tempfile.TemporaryDirectory() as tmp:
        for r in reps:
            root = Path(tmp) / f"truth_r{r}"
            cfg = SimConfig(
                scene=default_scene(),
                robot=delta_robot(),
                positions=POSITIONS,
                loads=tuple(paper9()),
                repeats=r,
            )
            write_campaign(root, cfg, render_images=False)
            for s in noises:
                e = rel_errors(round_trip_from_true_corners(root, noise_px=s, seed=1))
                dn = disp_noise(root, s)
                lines.append(
                    f"| {s:g} | {r} | {', '.join(f'{100 * v:.2f}' for v in e)} | {100 * e.max():.2f} "
                    f"| {', '.join(f'{v:.4f}' for v in dn)} |"
                )
                print(lines[-1])
        # 2. Rendered images, OpenCV corners.
        n_pos = 1 if args.quick else 2
        r = 1 if args.quick else 3
        root = Path(tmp) / "images"
        cfg = SimConfig(
            scene=default_scene(),
            robot=delta_robot(),
            positions=POSITIONS[:n_pos],
            loads=tuple(paper9()),
            repeats=r,
            seed=5,
        )
        t0 = time.perf_counter()
        write_campaign(root, cfg, workers=2)
        t_render = time.perf_counter() - t0
        t0 = time.perf_counter()
        res, failed, rms = image_round_trip(root)
        t_meas = time.perf_counter() - t0
        e = rel_errors(res)
        n_img = 2 * n_pos * 9 * r
        lines += [
            "",
            "## 2. Rendered images, corners by OpenCV (stand-in for the vision code)",
            "",
            f"{n_img} images (default photometry), rendered in {t_render:.0f} s (2 processes); "
            f"corners found in {n_img - failed}/{n_img} images in {t_meas:.0f} s; corner error RMS "
            f"{rms:.3f} px against the truth.",
            "",
            "| repeats | K error per position (%) |",
            "|---|---|",
            f"| {r} | {', '.join(f'{100 * v:.1f}' for v in e)} |",
            "",
            "## Reading",
            "",
            "- The chain (spec, files, frames, point_mm, cam2base, derivation, identification) is exact: "
            "with noise-free corners K comes back to ~0.1-0.3 % (the 1 um per-image jitter).",
            "- With the corner noise OpenCV actually achieves on these renders (~0.02-0.03 px), one "
            "camera 1.05-1.55 m away measures the displacement along its axis (base y) to ~0.1-0.2 mm "
            "and across it to ~0.05 mm per pair -- the reference study's own validation scatter "
            "(Table I: 0.21-0.28 mm). Displacements under 0.1-0.5 kg are 0.1-3.5 mm, so a few "
            "repeats give K to 5-30 %, not 2 %. The 2 % round trip through the vision path needs "
            "about 10x less displacement noise: more repeats (the error falls as 1/sqrt(repeats)), "
            "larger boards or a closer camera (depth noise ~ distance^2 / board size), or joint "
            "estimation across images.",
            "",
        ]
        print("\n".join(lines[-16:]))
    write(OUT, "\n".join(lines))


if __name__ == "__main__":
    main()
