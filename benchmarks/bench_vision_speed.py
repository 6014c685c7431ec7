"""Speed of the vision path on 2592x1944 images, side by side with a plain OpenCV script.

One robot position of the reference setup: a 12x7 board (10 mm squares) fixed on the base
and an 8x6 board (10 mm squares) on the platform, seen by the reference camera
(2592x1944 px, fx = 3733 px). A sequence of N images: the first half unloaded, the second
half loaded (the platform moved by 0.3 mm and 0.2 mrad), with small vibrations (5 um)
and independent sensor noise in every image. Images are saved as PNG (and, in a second
run, as uncompressed TIFF) and read back from disk.

Per image, in one run over the same files:

- decode: ``cv2.imread`` alone (the floor: no method can be faster than reading the image);
- plain OpenCV, one target: ``cv2.imread`` + ``findChessboardCornersSB`` (default flags,
  full image) + ``solvePnP``, timed for each board alone (the mobile 8x6, the fixed 12x7);
  the speed-up is against the faster of the two;
- stiffmap, both targets: ``PoseTracker.measure`` (read, size check, detection or
  tracking of both boards, both poses with covariance, mobile2base), with the corner
  poses (``refine="corners"``) and with the default (photometric poses), and the default as it
  was before the speed work of issue 14 (every photometric fit cold): the baseline of the
  precision along the line of sight.

Corner accuracy: RMS distance of the corners to their true positions (the renderer's
exact projections), px.

The default against every fit cold on image formations that are not the test-bed's (the
nine of ``bench_vision_formations.py``: blur after pixel integration, Bayer mosaics, JPEG, a
phone's chain): per formation, ``--cases`` boards, each a sequence of 8 images (4 at one pose,
4 after a displacement of 0.05-2 mm, 3 um vibration in every image), measured by the default
tracker and by one whose every photometric fit is cold; the pose differences in units of the
cold fit's sigma (6 axes), and the ratio of the two predicted sigmas along the line of sight.

Run:  .venv/bin/python benchmarks/bench_vision_speed.py [--quick] [--n N]
Saves benchmarks/results/vision_speed.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from _table import write  # noqa: E402
from helpers.board_images import TESTBED_RENDERER, testbed_board_image  # noqa: E402
from helpers.board_scenes import exact_corners, look_at_pose  # noqa: E402

from stiffmap.camera import reference_camera  # noqa: E402
from stiffmap.geometry import matrix_from_rotvec  # noqa: E402
from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision import PoseTracker  # noqa: E402

MOBILE = Chessboard(8, 6, 10.0)
FIXED = Chessboard(12, 7, 10.0)


def make_sequence(n: int, folder: Path, rng) -> tuple[list[Path], list[np.ndarray], np.ndarray]:
    cam = reference_camera()
    F = look_at_pose(760, FIXED, tilt_deg=(-8, 18, -3), offset_mm=(-150, 100))
    M0 = look_at_pose(700, MOBILE, tilt_deg=(10, -15, 5), offset_mm=(30, -20))
    load = np.array([0.3, -0.1, 0.15])
    poses, paths = [], []
    for k in range(n):
        T = M0.copy()
        if k >= n // 2:
            T[:3, :3] = matrix_from_rotvec([2e-4, 0.0, 0.0]) @ T[:3, :3]
            T[:3, 3] = T[:3, 3] + load
        T[:3, 3] = T[:3, 3] + rng.normal(scale=0.005, size=3)  # vibration, mm
        img = testbed_board_image(cam, [(FIXED, F), (MOBILE, T)], rng)
        p = folder / f"img{k:02d}.png"
        cv2.imwrite(str(p), img)
        poses.append(T)
        paths.append(p)
    return paths, poses, F


def baseline(path: Path, board: Chessboard, cam):
    """The plain OpenCV script: decode + findChessboardCornersSB + solvePnP, one target."""
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    ok, corners = cv2.findChessboardCornersSB(img, board.pattern_size)
    if not ok:
        return None
    obj = board.object_points()
    _, rvec, tvec = cv2.solvePnP(obj, corners, cam.matrix, cam.dist_array)
    return corners.reshape(-1, 2)


def rms_to_truth(corners, truth):
    # The plain script's numbering may be the turned one; compare with the nearer order.
    e1 = np.sqrt(np.mean(np.sum((corners - truth) ** 2, axis=1)))
    e2 = np.sqrt(np.mean(np.sum((corners[::-1] - truth) ** 2, axis=1)))
    return min(e1, e2)


def warm_against_cold(n_cases: int) -> list[str]:
    """Table rows: per formation, warm (default) minus cold poses over their sigma."""
    import bench_vision_formations as bf
    from helpers.board_scenes import moved_pose, random_displacement

    from stiffmap.geometry import displacement_from_poses

    cam = bf.camera()
    cases = bf.draw_cases(n_cases, 5)
    rows = []
    for f_index, (label, draw) in enumerate(bf.FORMATIONS):
        rng = np.random.default_rng([7, f_index])
        z, ratio, n_fits, n_pairs = [], [], 0, 0
        for board, T0, T1 in cases:
            seq = [
                draw(cam, board, moved_pose(T0 if k < 4 else T1, random_displacement(rng, 0.003)), rng)
                for k in range(8)
            ]
            warm = PoseTracker(cam, board)
            cold = PoseTracker(cam, board)
            cold._warm_start = False
            for im in seq:
                mw, mc = warm.measure(im), cold.measure(im)
                n_fits += 1
                if (
                    not (mw.ok and mc.ok)
                    or mw.mobile.method != "photometric"
                    or mc.mobile.method != "photometric"
                ):
                    continue
                n_pairs += 1
                a, b = mw.mobile, mc.mobile
                d = displacement_from_poses(b.board2frame, a.board2frame)
                z.append(d / np.sqrt(np.diag(b.cov_noise)))
                los = b.board2frame[:3, 3] / np.linalg.norm(b.board2frame[:3, 3])
                ratio.append(
                    np.sqrt(los @ a.cov_noise[:3, :3] @ los) / np.sqrt(los @ b.cov_noise[:3, :3] @ los)
                )
        if n_pairs:
            z = np.array(z)
            rows.append(
                f"| {label} | {n_pairs} of {n_fits} | {np.sqrt(np.mean(z**2)):.3f} | {np.abs(z).max():.2f} "
                f"| {np.mean(ratio):.3f} |"
            )
        else:
            rows.append(f"| {label} | 0 of {n_fits} | n/a | n/a | n/a |")
        print(rows[-1], flush=True)
    return rows


def run(paths, poses, F, repeats):
    cam = reference_camera()
    fixed2base = np.eye(4)
    n = len(paths)
    t_dec = np.zeros((repeats, n))
    t_base = np.zeros((repeats, n))
    t_base_m = np.zeros((repeats, n))
    t_ours = np.zeros((repeats, n))
    t_photo = np.zeros((repeats, n))
    t_cold = np.zeros((repeats, n))
    t_pose = np.zeros((repeats, n))
    along_new = np.full(n, np.nan)
    along_old = np.full(n, np.nan)
    sd_new = np.full(n, np.nan)
    sd_old = np.full(n, np.nan)
    warm = np.zeros(n, bool)
    tracked = np.zeros(n, bool)
    base_ok = 0
    base_mobile_ok = 0
    acc_base, acc_base_m, acc_ours_f, acc_ours_m = [], [], [], []
    for r in range(repeats):
        # Each method in a pass of its own over the files (as a user runs one script over a
        # folder; interleaving them per image would leave each with the other's caches).
        for k, p in enumerate(paths):
            t0 = time.perf_counter()
            cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            t_dec[r, k] = time.perf_counter() - t0
        cs = []
        for k, p in enumerate(paths):
            t0 = time.perf_counter()
            cs.append(baseline(p, FIXED, cam))
            t_base[r, k] = time.perf_counter() - t0
        cms = []
        for k, p in enumerate(paths):
            t0 = time.perf_counter()
            cms.append(baseline(p, MOBILE, cam))
            t_base_m[r, k] = time.perf_counter() - t0
        # The fast path (corner poses), the default (photometric refinement) and the path before
        # the speed work (every photometric fit from the start), same files.
        tr = PoseTracker(cam, MOBILE, FIXED, fixed2base, refine="corners")
        tr_photo = PoseTracker(cam, MOBILE, FIXED, fixed2base, refine="auto")
        tr_cold = PoseTracker(cam, MOBILE, FIXED, fixed2base, refine="auto")
        tr_cold._warm_start = False
        out = {}
        for name, tracker, times in (
            ("corners", tr, t_ours),
            ("default", tr_photo, t_photo),
            ("cold", tr_cold, t_cold),
        ):
            out[name] = []
            for k, p in enumerate(paths):
                t0 = time.perf_counter()
                m = tracker.measure(p)
                times[r, k] = time.perf_counter() - t0
                if not m.ok:
                    raise RuntimeError(m.error)
                out[name].append(m)
        t_pose[r] = [m.timings["pose"] for m in out["default"]]
        if r:
            continue
        for k in range(n):
            m, mp, mc, c, cm = out["corners"][k], out["default"][k], out["cold"][k], cs[k], cms[k]
            # The mobile board's position along the line of sight, minus the truth's.
            los = poses[k][:3, 3] / np.linalg.norm(poses[k][:3, 3])
            along_new[k] = (mp.mobile2cam[:3, 3] - poses[k][:3, 3]) @ los
            along_old[k] = (mc.mobile2cam[:3, 3] - poses[k][:3, 3]) @ los
            sd_new[k] = np.sqrt(los @ mp.mobile2cam_cov[:3, :3] @ los)
            sd_old[k] = np.sqrt(los @ mc.mobile2cam_cov[:3, :3] @ los)
            warm[k] = bool(mp.mobile.photometric and mp.mobile.photometric.warm_start)
            tracked[k] = m.tracked
            gt_f = exact_corners(cam, FIXED, F)
            gt_m = exact_corners(cam, MOBILE, poses[k])
            if c is not None:
                base_ok += 1
                acc_base.append(rms_to_truth(c, gt_f))
            if cm is not None:
                base_mobile_ok += 1
                acc_base_m.append(rms_to_truth(cm, gt_m))
            acc_ours_f.append(rms_to_truth(m.fixed_detection.corners, gt_f[m.fixed_detection.ids]))
            acc_ours_m.append(rms_to_truth(m.mobile_detection.corners, gt_m[m.mobile_detection.ids]))
    # The plain script on one thread (stiffmap measures in one): OpenCV's SB spreads its search
    # over every core by default.
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        t_base_1 = np.zeros(n)
        for k, p in enumerate(paths):
            t0 = time.perf_counter()
            baseline(p, MOBILE, cam)
            t_base_1[k] = time.perf_counter() - t0
    finally:
        cv2.setNumThreads(threads)
    med = lambda a: np.median(a, axis=0)  # noqa: E731
    return {
        "decode": med(t_dec),
        "base": med(t_base),
        "base_m": med(t_base_m),
        "base_1": t_base_1,
        "threads": threads,
        "ours": med(t_ours),
        "photo": med(t_photo),
        "cold": med(t_cold),
        "pose": med(t_pose),
        "along_new": along_new,
        "along_old": along_old,
        "sd_new": sd_new,
        "sd_old": sd_old,
        "warm": warm,
        "tracked": tracked,
        "base_ok": base_ok,
        "base_mobile_ok": base_mobile_ok,
        "acc_base": float(np.mean(acc_base)) if acc_base else float("nan"),
        "acc_base_m": float(np.mean(acc_base_m)) if acc_base_m else float("nan"),
        "acc_ours_f": float(np.mean(acc_ours_f)),
        "acc_ours_m": float(np.mean(acc_ours_m)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="6 images, 1 repeat")
    ap.add_argument("--n", type=int, default=None, help="images in the sequence (default 20)")
    ap.add_argument("--cases", type=int, default=None, help="boards per image formation (default 3)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "vision_speed.md"))
    args = ap.parse_args()
    n = args.n or (6 if args.quick else 20)
    repeats = 1 if args.quick else 3
    rng = np.random.default_rng(7)
    t_start = time.perf_counter()
    lines = [
        "# Vision: speed on 2592x1944 images, beside a plain OpenCV script",
        "",
        f"One robot position of the reference setup (fixed 12x7 board, mobile 8x6 board, 10 mm squares, "
        f"reference camera), a sequence of {n} images (half unloaded, half loaded: 0.3 mm, 0.2 mrad; "
        f"5 um vibration). Times are per image, median of {repeats} passes over the same files "
        "(each method in a pass of its own), one process on this machine (2 cores; OpenCV's SB "
        f"uses its threads, stiffmap one). Renderer: {TESTBED_RENDERER}.",
        "",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        paths, poses, F = make_sequence(n, folder, rng)
        for fmt in ("png", "tif"):
            if fmt == "tif":
                new = []
                for p in paths:
                    q = p.with_suffix(".tif")
                    cv2.imwrite(
                        str(q), cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), [cv2.IMWRITE_TIFF_COMPRESSION, 1]
                    )
                    new.append(q)
                paths = new
            r = run(paths, poses, F, repeats)
            dec = r["decode"]
            tr = r["tracked"]
            ours = r["ours"]
            base = r["base"] if r["base"].mean() < r["base_m"].mean() else r["base_m"]
            size_mb = np.mean([p.stat().st_size for p in paths]) / 1e6
            rows = [
                ("decode alone (cv2.imread), mean", 1e3 * dec.mean()),
                ("plain OpenCV, one target (mobile 8x6), mean", 1e3 * r["base_m"].mean()),
                ("plain OpenCV, one target (fixed 12x7), mean", 1e3 * r["base"].mean()),
                (
                    f"plain OpenCV, one target (mobile 8x6), on one thread (default: {r['threads']}), "
                    "one pass, mean",
                    1e3 * r["base_1"].mean(),
                ),
                ("stiffmap, both targets, first image (full detection)", 1e3 * ours[0]),
                (
                    f"stiffmap, both targets, tracked images (mean of {tr.sum()})",
                    1e3 * ours[tr].mean() if tr.any() else float("nan"),
                ),
                (f"stiffmap, both targets, mean over the {n} images", 1e3 * ours.mean()),
                (
                    "stiffmap default (photometric refinement), both targets, tracked images",
                    1e3 * r["photo"][tr].mean() if tr.any() else float("nan"),
                ),
                (
                    f"stiffmap default (photometric refinement), mean over the {n} images",
                    1e3 * r["photo"].mean(),
                ),
                (
                    "stiffmap default, tracked images: of which poses (corner + photometric, both targets)",
                    1e3 * r["pose"][tr].mean() if tr.any() else float("nan"),
                ),
                (
                    "stiffmap default before the speed work (every fit cold), tracked images",
                    1e3 * r["cold"][tr].mean() if tr.any() else float("nan"),
                ),
            ]
            speedup = base.mean() / ours.mean()
            track_ratio = ours[tr].mean() / dec[tr].mean() if tr.any() else float("nan")
            photo_speedup = base.mean() / r["photo"].mean()
            photo_tr = r["photo"][tr].mean() / dec[tr].mean() if tr.any() else float("nan")
            sb_over_default = base.mean() / r["photo"][tr].mean() if tr.any() else float("nan")
            sb_alone = np.mean([r["base"].mean(), r["base_m"].mean()]) - dec.mean()
            sb1_over_default = r["base_1"].mean() / r["photo"][tr].mean() if tr.any() else float("nan")
            # Along the line of sight: the error of each tracked image's mobile pose minus that of
            # the first image (same cold fit in both paths): a displacement's error, um.
            an, ao = r["along_new"], r["along_old"]
            dn, do = an[1:] - an[0], ao[1:] - ao[0]
            rms_n, rms_o = np.sqrt(np.mean(dn**2)), np.sqrt(np.mean(do**2))
            diff = np.sqrt(np.mean((an[1:] - ao[1:]) ** 2))
            sd = np.sqrt(np.mean(r["sd_new"][1:] ** 2))
            sd_old = np.sqrt(np.mean(r["sd_old"][1:] ** 2))
            lines += [
                f"## {fmt.upper()} files ({size_mb:.1f} MB each)",
                "",
                "| per image | ms |",
                "|---|---:|",
                *[f"| {a} | {b:.1f} |" for a, b in rows],
                "",
                "| result | value |",
                "|---|---:|",
                "| speed-up of stiffmap (2 targets) over plain OpenCV (1 target, the faster), sequence mean "
                f"| {speedup:.1f} x |",
                f"| tracked image time / decode time (same images) | {track_ratio:.2f} |",
                "| speed-up of the default (photometric poses, 4-6x more precise along the line of sight) "
                f"over plain OpenCV | {photo_speedup:.1f} x |",
                "| default, tracked image time / decode time (same images): target <= 1.5 "
                f"| {photo_tr:.2f} |",
                f"| plain OpenCV SB (1 target, the faster) / default tracked image: target >= 10 "
                f"| {sb_over_default:.1f} |",
                f"| plain OpenCV SB alone (without its decode) / decode | {sb_alone / dec.mean():.1f} |",
                "| plain OpenCV SB on one thread, as stiffmap measures (1 target) / default tracked image "
                f"| {sb1_over_default:.1f} |",
                f"| default photometric fits started warm (mobile target) | {r['warm'].sum()} of {n} |",
                "| along the line of sight, mobile target, displacement from the first image: RMS error, "
                f"default (um) | {1e3 * rms_n:.2f} |",
                "| the same, the path before the speed work (every fit cold) on the same images "
                f"(um) | {1e3 * rms_o:.2f} |",
                "| RMS difference of the two paths' poses along the line of sight, tracked images (um) "
                f"| {1e3 * diff:.3f} |",
                f"| predicted 1 sigma of one pose along the line of sight, default (um) | {1e3 * sd:.2f} |",
                f"| the same, the path before the speed work (um) | {1e3 * sd_old:.2f} |",
                "| along-axis precision, default / before (predicted sigma): target <= 1.10 "
                f"| {sd / sd_old:.3f} |",
                f"| along-axis precision, default / before (RMS error, {n - 1} displacements) "
                f"| {rms_n / rms_o:.3f} |",
                f"| images tracked (no full detection) | {tr.sum()} of {n} |",
                f"| plain OpenCV found the fixed 12x7 board | {r['base_ok']} of {n} |",
                f"| plain OpenCV found the mobile 8x6 board | {r['base_mobile_ok']} of {n} |",
                f"| corner RMS error, plain OpenCV (SB), mobile board (px) | {r['acc_base_m']:.4f} |",
                f"| corner RMS error, plain OpenCV (SB), fixed board (px) | {r['acc_base']:.4f} |",
                f"| corner RMS error, stiffmap, fixed board (px) | {r['acc_ours_f']:.4f} |",
                f"| corner RMS error, stiffmap, mobile board (px) | {r['acc_ours_m']:.4f} |",
                "",
            ]
            print("\n".join(lines[-(len(rows) + 26) :]), flush=True)
            if fmt == "png":
                # Unchanged: the predicted sigma within 10 % of the cold fits', and the two paths'
                # poses within 0.1 of it of each other along the line of sight (no bias).
                same = sd / sd_old <= 1.10 and diff < 0.1 * sd
                t_def = 1e3 * r["photo"][tr].mean()
                need = sb_alone / dec.mean() / 10 + 0.1
                default_verdict = (
                    f"Default (photometric poses of both targets), tracked images: {t_def:.1f} ms, "
                    f"{photo_tr:.2f} x decode (target <= 1.5: {'yes' if photo_tr <= 1.5 else 'NO'}); "
                    f"{sb_over_default:.1f} x faster than plain OpenCV SB + solvePnP on one target "
                    f"(target >= 10: {'yes' if sb_over_default >= 10 else 'NO'}; on this machine SB alone "
                    f"takes {sb_alone / dec.mean():.1f} x the decode time, so >= 10 x needs the default "
                    f"within {need:.2f} x decode; SB spreads over the {r['threads']} threads OpenCV "
                    f"starts, stiffmap measures in one: against SB on one thread {sb1_over_default:.1f} x). "
                    "Along the line of sight, one pose's predicted sigma is "
                    f"{1e3 * sd:.2f} um against {1e3 * sd_old:.2f} um before the speed work "
                    f"({sd / sd_old:.3f} x; the RMS error of {n - 1} displacements {1e3 * rms_n:.2f} um "
                    f"against {1e3 * rms_o:.2f} um; the two paths' poses {1e3 * diff:.3f} um RMS apart, "
                    f"{diff / sd:.3f} sigma): precision within 10 %: {'yes' if same else 'NO'}."
                )
                better = r["acc_ours_f"] <= r["acc_base"] and r["acc_ours_m"] <= r["acc_base_m"]
                verdict = (
                    "Claim (PNG, corner poses: `--refine corners`, the fast path): "
                    f">= 5x faster: {'yes' if speedup >= 5 else 'NO'} ({speedup:.1f}x); "
                    f"tracked images within 1.5x of decode: {'yes' if track_ratio <= 1.5 else 'NO'} "
                    f"({track_ratio:.2f}); "
                    f"corner accuracy equal or better: "
                    f"{'yes' if better else 'NO'}. The default photometric refinement trades speed "
                    f"for precision: {photo_speedup:.1f}x faster than plain OpenCV (see "
                    "vision_photometric.md for its precision)."
                )
    n_cases = args.cases or (1 if args.quick else 3)
    lines += [
        "## The default against every fit cold, on other image formations",
        "",
        f"{n_cases} board(s) per formation (9x7 and 8x6 of 15 mm, 12x11 of 10 mm, 450-900 mm, "
        "bench_vision_formations.py's cases), 8 images each (4 at one pose, 4 displaced by 0.05-2 mm; "
        "3 um vibration): the default tracker (warm starts, followed boards, chord steps) against "
        "one whose every photometric fit is cold, same images. Pose differences in units of the "
        "cold fit's sigma, over the 6 axes of every image where both gave a photometric pose.",
        "",
        "| formation | both photometric | RMS difference (sigma) | largest (sigma) "
        "| predicted sigma along the line of sight, default / cold |",
        "|---|---:|---:|---:|---:|",
        *warm_against_cold(n_cases),
        "",
        verdict,
        "",
        default_verdict,
        "",
        f"_{time.strftime('%Y-%m-%d')}, Python {platform.python_version()}, OpenCV {cv2.__version__}, "
        f"{platform.machine()}, run time {time.perf_counter() - t_start:.0f} s, load average at the end "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores_",
    ]
    print(verdict)
    print(default_verdict)
    write(args.out, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
