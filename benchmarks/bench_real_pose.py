"""Real photographs with the default settings: warnings, photometric refinements kept and why not.

For every real set beside the repository (``../shared/data/calib_example``, Bouguet's 13x12
board; the three cameras of ``../shared/data/real``, 9x6 boards) and the real stereo set of
``tests/data/stereo_opencv`` (OpenCV's left/right samples, 9x6), the real commands with their
default settings, in subprocesses:

- ``stiffmap calibrate`` and ``stiffmap pose`` (``calibrate-rig`` and ``pose --rig`` for the
  stereo set): their ``warning:`` lines, split into those naming an image that cannot be
  measured (a board partly out of the frame, an image of another size: right to warn) and the
  others (on good images there must be none);
- through the library (the same calls as ``pose``): poses posed, photometric refinements kept,
  and why each other one was not (``photometric_counts``); with the rig, the cameras'
  consistency chi2 (6 dof) over the pairs that calibrated it;
- where each image's edges sit relative to its corner pose (``edge_agreement`` with the
  image's photometric fit: the edges' scale about the board's centre and one image offset; what
  moves a photometric pose away from the corner pose), median and range over the set;
- a wrong board size (9x6 on Bouguet's 13x12 board): the answer, and the command's time
  (wall and CPU of the child process);
- the stereo set's consistency chi2 per pair, with the rig calibrated from all 13 pairs and
  leaving each pair out of the calibration (``calibrate_rig`` on the 12 others), with the rig's
  dispersion and without it (``Rig.dispersion`` set to None: the test as it was before it).

Run: .venv/bin/python benchmarks/bench_real_pose.py   (writes results/real_pose.md)
     .venv/bin/python benchmarks/bench_real_pose.py --stereo   (the stereo set's row and its
     per-pair chi2 only, about 1 min, written into the existing results/real_pose.md)
"""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _table import markdown, save  # noqa: E402
from helpers.shared_data import CALIB_DIR, REAL_SETS  # noqa: E402

from stiffmap.camera import load_camera  # noqa: E402
from stiffmap.rig import load_rig  # noqa: E402
from stiffmap.targets import Chessboard  # noqa: E402
from stiffmap.vision import detect_board, read_image  # noqa: E402
from stiffmap.vision.detection import DetectionError  # noqa: E402
from stiffmap.vision.files import image_files, measure_files, measure_image_sets  # noqa: E402
from stiffmap.vision.photometric import PhotometricError, refine_pose_photometric  # noqa: E402
from stiffmap.vision.photometric.diagnostics import edge_agreement  # noqa: E402
from stiffmap.vision.pose import corner_noise_factor, estimate_pose, pose_shift_sigma  # noqa: E402
from stiffmap.vision.rig_calibration import calibrate_rig  # noqa: E402
from stiffmap.vision.sequence import photometric_counts  # noqa: E402

STEREO = HERE.parent / "tests" / "data" / "stereo_opencv"
#: The stereo set's per-pair chi2 paragraph of results/real_pose.md starts with this line.
CHI2_HEAD = "Rig consistency chi2 per pair (6 dof; law: median 5.35, 99.99 % quantile 27.9), the stereo set:"
STIFFMAP = [sys.executable, "-m", "stiffmap"]
#: Warnings that name an image that cannot be measured (right to warn).
IMAGE_PROBLEMS = ("no complete", "image is ", "partly", "not an image")


def _run(args: list[str]) -> tuple[int, list[str], float, float]:
    """Exit status, warning lines (and the error line, if any), wall and child CPU seconds of one
    command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run(STIFFMAP + args, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    warns = [ln for ln in r.stderr.splitlines() if ln.startswith(("warning:", "error:"))]
    return r.returncode, warns, wall, cpu


def _split(warns: list[str]) -> tuple[int, int]:
    bad_image = sum(any(w in ln for w in IMAGE_PROBLEMS) for ln in warns)
    return bad_image, len(warns) - bad_image


def _why(why: dict) -> str:
    return "; ".join(f"{c}: {n}" for c, n in sorted(why.items(), key=lambda cn: -cn[1])) or "-"


def _shifts(pairs, camera, board) -> str:
    """Photometric minus corner pose in combined sigmas over (pose, detection) pairs: median and
    90 % with the corner pose's independent-noise covariance, then with it times
    ``corner_noise_factor`` (as the acceptance test takes it)."""
    own, wide = [], []
    for p, det in pairs:
        if p is not None and p.method == "photometric" and det is not None:
            c = estimate_pose(det, board, camera, refine="corners")
            own.append(pose_shift_sigma(c, p))
            k = corner_noise_factor(c.residuals_px)
            wide.append(pose_shift_sigma(replace(c, cov=c.cov + (k - 1.0) * c.cov_noise), p))
    if not own:
        return "-"
    q = lambda x: f"{np.median(x):.1f} / {np.quantile(x, 0.9):.1f}"  # noqa: E731
    return f"{q(own)}; {q(wide)}"


def _edges(pairs, camera, board) -> str:
    """Edges against the corner pose over (image file, detection) pairs: the scale (%) and the
    offset's length (px), median [min, max], and how many images' photometric fits failed."""
    scale, off, failed = [], [], 0
    for path, det in pairs:
        if det is None:
            continue
        img = read_image(path)
        corner = estimate_pose(det, board, camera, refine="corners")
        try:
            fit = refine_pose_photometric(img, board, camera, corner.board2cam, detection=det).photometric
        except PhotometricError:
            try:  # as estimate_pose does: the inner squares alone
                fit = refine_pose_photometric(
                    img, board, camera, corner.board2cam, detection=det, inner_only=True
                ).photometric
            except PhotometricError:
                failed += 1
                continue
        a = edge_agreement(img, board, camera, corner.board2cam, fit, phase=det.phase)
        scale.append(100.0 * a.scale)
        off.append(float(np.hypot(*a.offset_px)))
    if not scale:
        return "-"
    q = lambda x, f: f"{np.median(x):{f}} [{np.min(x):{f}}, {np.max(x):{f}}]"  # noqa: E731
    return f"{q(scale, '+.3f')} % / {q(off, '.2f')} px" + (f" ({failed} not fitted)" if failed else "")


def wrong_size(name: str, folder, board: Chessboard) -> list:
    """Each image searched for a smaller board: the sizes named, and CPU per image."""
    named: dict[str, int] = {}
    t = time.process_time()
    files = image_files([folder])
    for f in files:
        try:
            detect_board(read_image(f), board)
            key = "found (a sub-grid accepted)"
        except DetectionError as e:
            key = e.larger.size + ("" if e.larger.whole else " (cut)") if e.larger is not None else e.reason
        named[key] = named.get(key, 0) + 1
    cpu = (time.process_time() - t) / len(files)
    text = "; ".join(f"{k}: {n}" for k, n in sorted(named.items(), key=lambda kn: -kn[1]))
    return [name, board.size, text, f"{cpu:.2f}"]


def one_camera(name: str, folder, board: Chessboard, tmp: Path) -> list:
    cam_json = tmp / f"{name}.json"
    rc_c, w_c, *_ = _run(
        ["calibrate", str(folder), "--board", board.size, "--square-mm", "25", "--out", str(cam_json)]
    )
    rc_p, w_p, *_ = _run(
        ["pose", "--camera", str(cam_json), "--board", board.size, "--square-mm", "25", str(folder)]
    )
    files = image_files([folder])
    camera = load_camera(cam_json)
    ms = measure_files(files, camera, board)
    kept, tried, why = photometric_counts(ms)
    posed = sum(m.ok for m in ms)
    shifts = _shifts([(m.mobile, m.mobile_detection) for m in ms], load_camera(cam_json), board)
    return [
        name,
        f"{posed} / {len(ms)}",
        f"{kept} / {tried}",
        shifts,
        _why(why),
        _edges([(f, m.mobile_detection) for f, m in zip(files, ms, strict=True)], camera, board),
        "{} + {}".format(*_split(w_c)),
        "{} + {}".format(*_split(w_p)),
        "-",
    ]


def stereo(tmp: Path, board: Chessboard) -> list:
    rig_json = tmp / "rig.json"
    rc_c, w_c, *_ = _run(
        [
            "calibrate-rig",
            "--camera",
            f"left={STEREO}/left*.jpg",
            "--camera",
            f"right={STEREO}/right*.jpg",
            "--board",
            board.size,
            "--square-mm",
            "25",
            "--out",
            str(rig_json),
        ]
    )
    rc_p, w_p, *_ = _run(
        [
            "pose",
            "--rig",
            str(rig_json),
            "--board",
            board.size,
            "--square-mm",
            "25",
            f"{STEREO}/{{camera}}*.jpg",
        ]
    )
    numbers = sorted(p.stem[4:] for p in STEREO.glob("left*.jpg"))
    sets = [(n, {"left": STEREO / f"left{n}.jpg", "right": STEREO / f"right{n}.jpg"}) for n in numbers]
    ms = measure_image_sets(sets, load_rig(rig_json), board)
    kept, tried, why = photometric_counts(ms)
    chi2 = np.array([m.mobile.chi2 for m in ms if m.ok])
    flagged = sum(bool(m.mobile.consistency_warning) for m in ms if m.ok)
    rig = load_rig(rig_json)
    per_cam = [
        _shifts(
            [(v.mobile, v.mobile_detection) for m in ms for v in m.views if v.camera == c.name],
            c.camera,
            board,
        )
        for c in rig.cameras
    ]
    edges = [
        _edges(
            [(v.image, v.mobile_detection) for m in ms for v in m.views if v.camera == c.name],
            c.camera,
            board,
        )
        for c in rig.cameras
    ]
    return [
        "stereo (OpenCV samples, rig)",
        f"{len(chi2)} / {len(ms)} pairs",
        f"{kept} / {tried}",
        " and ".join(per_cam),
        _why(why),
        " and ".join(edges),
        "{} + {}".format(*_split(w_c)),
        "{} + {}".format(*_split(w_p)),
        f"median {np.median(chi2):.1f}, max {chi2.max():.0f}; {flagged} of {len(chi2)} above 27.9",
    ]


def _chi2s(ms) -> str:
    c = [m.mobile.chi2 for m in ms]
    return (
        ", ".join(f"{x:.1f}" for x in c)
        + f" (median {np.median(c):.1f}, {sum(x > 27.9 for x in c)} above 27.9)"
    )


def stereo_chi2(rig_json: Path, board: Chessboard) -> str:
    """The stereo set's consistency chi2 per pair (default poses): the rig from all pairs, and
    each pair posed with the rig calibrated from the 12 others; with and without the dispersion."""
    numbers = sorted(p.stem[4:] for p in STEREO.glob("left*.jpg"))
    sets = [(n, {"left": STEREO / f"left{n}.jpg", "right": STEREO / f"right{n}.jpg"}) for n in numbers]
    rig = load_rig(rig_json)
    lines = [f"pairs {', '.join(numbers)}:"]
    for label, r in (("with the dispersion", rig), ("without it", replace(rig, dispersion=None))):
        lines.append(f"- all 13 pairs in the rig, {label}: {_chi2s(measure_image_sets(sets, r, board))}")
    dets = [
        [detect_board(read_image(STEREO / f"{c}{n}.jpg"), board) for n in numbers] for c in ("left", "right")
    ]
    loo = {True: [], False: []}
    for i in range(len(numbers)):
        keep = [j for j in range(len(numbers)) if j != i]
        r = calibrate_rig(
            [[d[j] for j in keep] for d in dets], board, [(640, 480)] * 2, camera_names=["left", "right"]
        ).rig
        for with_d in (True, False):
            rr = r if with_d else replace(r, dispersion=None)
            loo[with_d].append(measure_image_sets([sets[i]], rr, board)[0])
    lines.append(f"- each pair left out of the rig, with the dispersion: {_chi2s(loo[True])}")
    lines.append(f"- each pair left out of the rig, without it: {_chi2s(loo[False])}")
    return "\n".join(lines)


def _stereo_only() -> None:
    """The stereo set's row and per-pair chi2 written into the existing results/real_pose.md."""
    board = Chessboard(9, 6, 25.0)
    path = HERE / "results" / "real_pose.md"
    text = path.read_text(encoding="utf-8")
    with tempfile.TemporaryDirectory() as d:
        row = stereo(Path(d), board)
        chi2 = stereo_chi2(Path(d) / "rig.json", board)
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("| stereo (OpenCV samples, rig)"))
    lines[i] = "| " + " | ".join(str(c) for c in row) + " |"
    text = "\n".join(lines) + "\n"
    head = CHI2_HEAD
    if head in text:
        start = text.index(head)
        end = text.index("\n\n", start)
        text = text[:start] + head + "\n" + chi2 + text[end:]
    else:
        at = text.rindex("\n\n| set ")  # before the main table (the last), as main() writes it
        text = text[:at] + "\n\n" + head + "\n" + chi2 + text[at:]
    print(chi2)
    path.write_text(text, encoding="utf-8")
    print(f"saved {path}")


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows.append(one_camera("calib_example (Bouguet)", CALIB_DIR, Chessboard(13, 12, 30.0), tmp))
        for name, (folder, *_) in REAL_SETS.items():
            rows.append(one_camera(name, folder, Chessboard(9, 6, 25.0), tmp))
        rows.append(stereo(tmp, Chessboard(9, 6, 25.0)))
        chi2 = stereo_chi2(tmp / "rig.json", Chessboard(9, 6, 25.0))
        rc, w, wall, cpu = _run(
            [
                "calibrate",
                str(CALIB_DIR),
                "--board",
                "9x6",
                "--square-mm",
                "30",
                "--out",
                str(tmp / "wrong.json"),
            ]
        )
    headers = [
        "set",
        "posed",
        "photometric kept / tried",
        "kept: photometric - corner pose, combined sigma (median / 90 %; corner cov x factor)",
        "why the others kept their corner pose",
        "edges vs the corner pose: scale / offset (median [range])",
        "calibrate warnings (bad image + other)",
        "pose warnings (bad image + other)",
        "rig consistency chi2 (6 dof)",
    ]
    notes = (
        "Default settings (`--refine auto`). The distance of a kept photometric pose from its corner "
        "pose in combined sigmas (Mahalanobis over 6 parameters, both fits' own covariances) follows "
        "the chi law of 6 degrees of freedom if both covariances hold: median 2.35, 90 % 3.26. "
        "Edges vs the corner pose (`vision.photometric.diagnostics.edge_agreement`, every posed image "
        "with its photometric fit): how much farther from the board's centre the edges sit than the "
        "corner pose puts them (a photometric pose moves closer by about that share of its distance) "
        "and the length of one image offset of every edge (which moves it sideways). "
        "Warnings split into those naming an image that cannot be "
        "measured (board partly out of the frame, another image size) and the others. Wrong board size "
        f"(`calibrate calib_example --board 9x6`): exit {rc}, {wall:.1f} s wall, {cpu:.1f} s CPU "
        f"(this shared machine's load varies): `{w[-1] if w else 'no message'}`"
    )
    wrong = [
        wrong_size("calib_example (Bouguet, 13x12)", CALIB_DIR, Chessboard(9, 6, 30.0)),
        *(wrong_size(f"{n} (9x6)", folder, Chessboard(7, 5, 25.0)) for n, (folder, *_) in REAL_SETS.items()),
        wrong_size("stereo left (9x6)", STEREO, Chessboard(7, 5, 25.0)),
    ]
    table = markdown(
        ["set (board)", "--board asked", "per image: the size named (or why not)", "CPU s / image"], wrong
    )
    notes += (
        "\n\nA board smaller than the printed one asked for, on every image: the size each image's "
        "error names (`DetectionError.larger`; a size is named when the board is followed whole, "
        "`(cut)` when it runs out of the image; `partial`/`not_found` when no piece of it could "
        "be grown):\n\n" + table
    )
    notes += "\n\n" + CHI2_HEAD + "\n" + chi2
    save("real_pose", "Real photographs: default warnings and photometric refinements", headers, rows, notes)


if __name__ == "__main__":
    _stereo_only() if "--stereo" in sys.argv[1:] else main()
