"""Vision commands: ``calibrate``, ``pose``, ``displacement``, ``validate`` (see docs/vision.md).

``pose`` and ``displacement`` measure with one camera (``--camera camera.json``) or with a rig
of several (``--rig rig.json``, one image per camera in each image set: a name holding
``{camera}``, or ``--images NAME=GLOB`` per camera, matched by the number in their names).

Each command reads its options, calls :mod:`stiffmap.vision` (through the file-level
entry points of :mod:`stiffmap.vision.files`) and prints. An input error becomes its
``error:`` line and exit status here (:func:`~stiffmap.cli.common.fail`), also when a
command runs in-process without :func:`stiffmap.cli.main.run` (typer's ``CliRunner``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from ..camera import invertible_field, load_camera, plausibility_problems, save_camera
from ..errors import InputError
from ..geometry import rotvec_from_matrix
from ..io import atomic_write_text
from ..report.validation import stage_plot_svg
from ..rig import Rig, load_rig, save_rig
from ..targets import CharucoBoard, Chessboard, parse_board_size
from ..vision.calibrate import DIST_MODELS, CalibrationResult, grouped_reasons
from ..vision.displacement import ImageDisplacements, displacement_per_image
from ..vision.files import (
    MAX_TRANSLATION_MM,
    calibrate_files,
    calibrate_rig_files,
    measure_files,
    measure_image_sets,
    read_stage_manifest,
    read_transform,
    rig_image_sets,
)
from ..vision.fuse import FusedPose
from ..vision.rig_calibration import NO_IMAGE, RigCalibrationResult
from ..vision.sequence import ImageMeasurement, photometric_summary
from ..vision.validate import REFERENCE_TABLE_I, StageValidation, validate_stage_series
from .common import EXIT_PARTIAL, err, fail, fmt, images_progress, out, print_json, three_numbers, warn

_BOARD_HELP = "Board size COLSxROWS in inner corners, e.g. 13x12."
_CHARUCO_HELP = (
    "The board is a ChArUco board with this ArUco dictionary (e.g. DICT_5X5_100); "
    "--board still counts inner corners (squares - 1)."
)


def _board(
    size: str,
    square_mm: float,
    charuco: str | None = None,
    marker_mm: float | None = None,
    what="--board",
    square_option="--square-mm",
):
    """The board of the options; an InputError naming the option that is wrong."""
    try:
        cols, rows = parse_board_size(size)
    except ValueError as e:
        raise InputError(f"{what}: {e}") from None
    try:
        board = Chessboard(cols, rows, square_mm)
    except ValueError as e:
        raise InputError(f"{square_option}: {e}") from None
    if not charuco:
        return board
    if marker_mm is None:
        raise InputError("--charuco needs --marker-mm (side of the ArUco markers, mm)")
    try:
        return CharucoBoard(cols + 1, rows + 1, square_mm, marker_mm, charuco)
    except ValueError as e:
        raise InputError(f"--charuco {charuco} --marker-mm {marker_mm:g} {what} {size}: {e}") from None


def _point(text: str | None):
    if text is None:
        return None
    v = three_numbers(text)
    if v is None or max(abs(x) for x in v) > MAX_TRANSLATION_MM:
        raise InputError(
            f"--point must be three numbers x,y,z in mm (target frame, within {MAX_TRANSLATION_MM:g} mm), "
            f"got {text!r}"
        )
    return np.array(v)


def _fixed_target(board: str | None, square_mm: float | None, fixed2base: Path | None):
    """The fixed target and its pose on the base (None, None when not given)."""
    if board is None and square_mm is None and fixed2base is None:
        return None, None
    if board is None or square_mm is None or fixed2base is None:
        raise InputError(
            "--fixed-board, --fixed-square-mm and --fixed2base go together (for the fixed "
            "target's own frame, give a --fixed2base file holding the 4x4 identity)"
        )
    return _board(board, square_mm, what="--fixed-board", square_option="--fixed-square-mm"), read_transform(
        fixed2base
    )


_REFINE_HELP = (
    "Pose refinement: photometric (a model of the blurred board fitted to its pixels; several "
    "times more precise along the line of sight; the corner pose is kept when it fails its "
    "checks), corners (reprojection of the corners), or auto (photometric for chessboards, "
    "corners for ChArUco boards)."
)


def _refine(value: str) -> str:
    if value not in ("auto", "photometric", "corners"):
        raise InputError(f"--refine must be auto, photometric or corners, got {value!r}")
    return value


def _pose_json(p) -> dict:
    """JSON fields of a BoardPose beyond board2cam and cov."""
    d = {"rms_px": p.rms_px, "n_corners": p.n_corners, "method": p.method}
    # The calibration's share of cov (None: the camera.json gives no uncertainty).
    d["cov_calibration"] = p.cov_calibration
    d["t_std_calibration_mm"] = None if p.cov_calibration is None else p.t_std_calibration_mm
    if p.photometric is not None:
        f = p.photometric
        d["photometric"] = {
            "rms_dn": f.rms_dn,
            "noise_rms_dn": f.noise_rms_dn,
            "n_pixels": f.n_pixels,
            "blur_px": f.blur_px,
            "outlier_fraction": f.outlier_fraction,
        }
    if p.fallback:
        d["fallback"] = p.fallback
    return d


def _warn_failures(
    ms: list[ImageMeasurement], rig: Rig | None = None, refine: str = "photometric", as_json: bool = False
) -> None:
    """One warning per image (set) that failed, or whose pose fell back to the corners (with why).

    With a rig, also one per camera whose image of a measured set could not be used, and one
    per fused pose whose cameras disagree (a wrong rig file, a moved camera). With the default
    ``--refine auto`` a pose that keeps its corners is no warning: one note after the table sums
    them up (none with ``--json``, whose poses each carry their ``fallback``).
    """
    if refine == "auto" and not as_json:
        note = photometric_summary(ms)
        if note is not None:
            out.print(f"note: {note}", markup=False)
    failed = [m for m in ms if not m.ok]
    # Images that failed for one reason (a wrong --board on every image) are one line.
    reasons = [m.error.removeprefix(f"{m.image}: ") for m in failed]
    for line in grouped_reasons([m.image for m in failed], reasons):
        warn(line)
    for m in ms:
        if not m.ok:
            continue
        if rig is not None:
            for v in m.views:
                if v.error:
                    warn(f"camera {v.camera}: {v.error}")
            for w in m.consistency_warnings:
                warn(f"{m.image}: {w}")
        for p in (m.mobile, m.fixed):
            if p is not None and p.fallback and refine != "auto":
                warn(f"{m.image}: {p.fallback}")


def _camera_failures(ms: list[ImageMeasurement]) -> int:
    """Cameras whose image of a measured set could not be used."""
    return sum(1 for m in ms if m.ok for v in m.views if v.error)


def _exit_for(n_ok: int, n_total: int, inputs: str = "", partial: bool = False) -> None:
    """Exit 2 (with an ``error:`` line) when nothing was measured, 1 when some items failed.

    ``inputs`` names what every image was measured with (the camera file, the board), the
    suspects when none could be; ``partial`` says some camera's image of a measured set failed.
    """
    if n_ok == 0:
        raise fail(f"none of the {n_total} image(s) could be measured{inputs} (see the warnings above)")
    if n_ok < n_total or partial:
        raise typer.Exit(EXIT_PARTIAL)


def _measured_with(camera: Path | None, board: str, rig: Path | None = None) -> str:
    if rig is not None:
        return f" with --rig {rig} and --board {board}"
    return f" with --camera {camera} and --board {board}"


_RIG_HELP = (
    "rig.json (several calibrated cameras, instead of --camera): each image set is then one image "
    "per camera, named with {camera} (e.g. 'shots/{camera}_07.png') or given by --images."
)
_IMAGES_HELP = (
    "With --rig: NAME=GLOB, one camera's images (a quoted file pattern, a folder or a file); repeat "
    "for every camera. Views are matched by the number in their file names (left07.png with "
    "right07.png), else in order."
)


def _camera_or_rig(camera: Path | None, rig: Path | None):
    """The camera model (with --camera) or the rig (with --rig): exactly one of them."""
    if camera is not None and rig is not None:
        raise InputError("--camera and --rig: give one (a rig.json holds every camera of the rig)")
    if camera is None and rig is None:
        raise InputError("give --camera camera.json (one camera) or --rig rig.json (several)")
    if rig is not None:
        return None, load_rig(rig)
    return load_camera(camera), None


def _image_sets(images: list[str], per_camera: list[str], rig: Rig | None, what: str = "image") -> list:
    """The image sets of a rig (label, camera -> path), or the image paths of one camera."""
    if rig is not None:
        return rig_image_sets(rig, images, per_camera, what=what)
    if per_camera:
        raise InputError("--images NAME=GLOB goes with --rig (one camera's images in a rig)")
    templated = [i for i in images if "{camera}" in str(i)]
    if templated:
        raise InputError(f"{templated[0]!r}: an image name holding {{camera}} needs --rig rig.json")
    return [Path(i) for i in images]


def _measure(
    items: list,
    cam,
    rig: Rig | None,
    camera: Path | None,
    rig_path: Path | None,
    board,
    fixed_board=None,
    fixed2base=None,
    *,
    refine: str,
) -> list[ImageMeasurement]:
    """Measure the image sets of a rig, or the images of one camera, as one tracked sequence."""
    if not items:
        raise InputError("no images given")
    if rig is not None:
        return measure_image_sets(
            items, rig, board, fixed_board, fixed2base, rig_source=str(rig_path), refine=refine
        )
    return measure_files(items, cam, board, fixed_board, fixed2base, camera_source=str(camera), refine=refine)


def _cameras_json(m: ImageMeasurement) -> list[dict]:
    """Per camera of a rig: its image, error, and the poses it measured (camera frame)."""

    def one(p):
        if p is None:
            return None
        d = {"board2cam": p.board2cam, "rms_px": p.rms_px, "n_corners": p.n_corners, "method": p.method}
        if p.fallback:
            d["fallback"] = p.fallback
        return d

    return [
        {"name": v.camera, "image": v.image, "error": v.error, "mobile": one(v.mobile), "fixed": one(v.fixed)}
        for v in m.views
    ]


def _consistency_json(p) -> dict | None:
    if not isinstance(p, FusedPose):
        return None
    return {"cameras": list(p.cameras), "chi2": p.chi2, "dof": p.dof, "warning": p.consistency_warning}


def _print_cameras(ms: list[ImageMeasurement], rig: Rig) -> None:
    """Which camera saw which target in each image set, with its RMS."""
    t = Table(title=f"per camera ({', '.join(rig.names)})")
    t.add_column("image set", overflow="fold")
    t.add_column("camera")
    t.add_column("image", overflow="fold")
    t.add_column("mobile target")
    t.add_column("fixed target")
    t.add_column("error", overflow="fold")

    def seen(p) -> str:
        if p is None:
            return "-"
        return f"{p.method}, {p.rms_px:.3f} px RMS, {p.n_corners} corners"

    fixed = any(v.fixed is not None for m in ms for v in m.views)
    for m in ms:
        for v in m.views:
            t.add_row(
                m.image, v.camera, v.image, seen(v.mobile), seen(v.fixed) if fixed else "", v.error or ""
            )
    out.print(t)


def _rig_calibration_note(rig: Rig, source: str) -> str:
    """Where the rig's calibration share of the uncertainties comes from."""
    src = rig.calibration_cov_source
    if src == "cov":
        return f"the 1 sigma include the calibration's ({source}: the rig's joint covariance)"
    have = [c.name for c in rig.cameras if c.camera.calibration_cov is not None]
    if src == "none":
        return (
            f"the calibration's uncertainty is unknown ({source} holds no 'cov', nor do its cameras): "
            "not included"
        )
    return (
        f"the 1 sigma include the calibration's ({source}: the cameras' own covariances ({', '.join(have)}), "
        "the cameras' poses in the rig taken as exact)"
    )


# ----------------------------------------------------------------------------- calibrate
def calibrate(
    images: list[Path] = typer.Argument(
        ..., help="Images of the board (at least 3 views), or folders of them."
    ),
    board: str = typer.Option(..., "--board", help=_BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    out_path: Path = typer.Option(Path("camera.json"), "--out", help="Where to write camera.json."),
    fix_k3: bool = typer.Option(False, "--fix-k3", help="Fix k3 = 0 (the Matlab toolbox's default)."),
    rational: bool = typer.Option(False, "--rational", help="Also estimate k4, k5, k6 (rational model)."),
    thin_prism: bool = typer.Option(False, "--thin-prism", help="Rational model plus thin-prism s1..s4."),
    fisheye: bool = typer.Option(
        False,
        "--fisheye",
        help="OpenCV's fisheye model (k1..k4 of the angle off axis) for a fisheye or strong "
        "wide-angle lens: one to one over the whole image where the polynomial folds over.",
    ),
    outlier_factor: float = typer.Option(
        3.0, "--outlier-factor", min=1.0, help="Leave out views whose RMS exceeds this times the median."
    ),
    charuco: str = typer.Option(None, "--charuco", help=_CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    as_json: bool = typer.Option(False, "--json", help="Print the camera.json object instead of tables."),
) -> None:
    """Calibrate a camera from images of a board (Zhang's method): intrinsics, distortion, 1-sigma.

    Views where the board is not found, or whose RMS is an outlier, are left out with the
    reason. Also printed the way the Camera Calibration Toolbox for Matlab does (+/- 3 sigma).
    Exit status 1 when some images were left out (each named) or the result fails camera.json's
    plausibility checks (a warning per key: the other commands will refuse it), 2 when no
    calibration was possible.
    """
    try:
        b = _board(board, square_mm, charuco, marker_mm)
        if sum([fix_k3, rational, thin_prism, fisheye]) > 1:
            raise InputError("choose at most one of --fix-k3, --rational, --thin-prism, --fisheye")
        model = {"fix-k3": fix_k3, "rational": rational, "thin-prism": thin_prism, "fisheye": fisheye}
        model = next((k for k, on in model.items() if on), "k3")
        # A bar on a terminal only (it would be a blank line in a log), gone once done.
        with images_progress("finding the board", show=err.is_terminal, transient=True) as progress:
            res = calibrate_files(images, b, model=model, outlier_factor=outlier_factor, progress=progress)
        backup = save_camera(res.camera, out_path)
    except InputError as e:
        raise fail(str(e)) from None
    if backup is not None:
        warn(f"{out_path} replaced; the previous calibration is kept as {backup}")
    unused = [v for v in res.views if not v.used]
    for line in grouped_reasons([v.image for v in unused], [v.reason for v in unused]):
        warn(f"not used: {line}")
    implausible = _warn_calibrated(res.camera, out_path, field_warning=False)
    for key, what in res.problems:
        warn(f"{out_path}: {key}: {what}")
    if res.lens_advice:
        warn(f"{out_path}: {res.lens_advice}")
    if as_json:
        print_json(res.to_dict())
    else:
        _print_calibration(res, out_path)
    if res.n_used < len(res.views) or implausible or res.problems:
        raise typer.Exit(EXIT_PARTIAL)


def _warn_calibrated(camera, out_path: Path, label: str = "", field_warning: bool = True) -> bool:
    """Warn about a calibrated camera that fails camera.json's checks (True), or whose lens model
    folds within the image (``field_warning``; ``calibrate`` flags a fold among its views' corners
    instead, and prints the field)."""
    implausible = plausibility_problems(camera)
    for key, what in implausible:
        # The other commands refuse this camera.json: say so now, with the views to blame.
        warn(f"{out_path}: {label}key {key!r}: {what} (the views may not constrain the calibration)")
    field = invertible_field(camera)
    if field_warning and not implausible and field.image_share() < 1.0:
        warn(f"{out_path}: {label}{field.describe()}; pose measurements use no pixel beyond it")
    return bool(implausible)


def _print_calibration(res: CalibrationResult, out_path: Path) -> None:
    """The camera's parameters with their 1 sigma, the views, and the Matlab toolbox's text."""
    c = res.camera
    s = c.std
    t = Table(title=f"camera ({c.image_size[0]}x{c.image_size[1]} px, model {res.model}), +/- 1 sigma")
    t.add_column("parameter")
    t.add_column("value")
    t.add_column("1 sigma")
    for k in ("fx", "fy", "cx", "cy"):
        t.add_row(f"{k} (px)", f"{getattr(c, k):.4f}", f"{s[k]:.4f}")
    for name, v, sd in zip(c.dist_names, c.dist, s["dist"], strict=False):
        t.add_row(name, f"{v:.6f}", f"{sd:.6f}")
    out.print(t)
    out.print(
        f"reprojection RMS {c.rms_px:.4f} px; residual std per axis "
        f"[{c.residual_std_px[0]:.4f}, {c.residual_std_px[1]:.4f}] px; "
        f"{res.n_used} of {len(res.views)} views used"
    )
    out.print(invertible_field(c).describe())
    v = Table(title="views")
    v.add_column("image", overflow="fold")
    for col in ("used", "corners", "RMS (px)"):
        v.add_column(col)
    v.add_column("reason", overflow="fold")
    for vr in res.views:
        v.add_row(vr.image, "yes" if vr.used else "no", str(vr.n_corners), fmt(vr.rms_px, 3), vr.reason)
    out.print(v)
    out.print("\nAs the Camera Calibration Toolbox for Matlab prints it:\n")
    out.print(res.matlab_text(), markup=False)
    out.print(f"\nwrote {out_path}")


# ------------------------------------------------------------------------- calibrate-rig
_CAMERA_HELP = (
    "NAME=GLOB: a camera's name and its images, a quoted file pattern such as 'img/left*.jpg' "
    "or a folder. Repeat for every camera; the first one's frame is the rig frame."
)
_MODEL_HELP = (
    "Distortion model of every camera: k3 (k1, k2, p1, p2, k3), fix-k3 (k3 = 0, the Matlab "
    "toolbox's default), rational (+ k4, k5, k6), thin-prism (rational + s1..s4) or fisheye "
    "(OpenCV's fisheye model, k1..k4 of the angle off axis)."
)


def parse_camera_option(text: str) -> tuple[str, str]:
    """``NAME=GLOB`` -> (name, pattern); an InputError saying what a ``--camera`` looks like."""
    name, sep, pattern = text.partition("=")
    name = name.strip()
    example = "(e.g. --camera 'left=img/left*.png')"
    if not sep:
        raise InputError(f"--camera {text!r}: expected NAME=GLOB, a camera's name and its images {example}")
    if not name:
        raise InputError(f"--camera {text!r}: the camera's name before '=' is missing {example}")
    if not name.isprintable():
        raise InputError(
            f"--camera {text!r}: the camera's name {name!r} holds characters that cannot be printed"
        )
    if not pattern.strip():
        raise InputError(f"--camera {text!r}: the images after '=' are missing {example}")
    return name, pattern


def calibrate_rig(
    camera: list[str] = typer.Option(..., "--camera", help=_CAMERA_HELP),
    board: str = typer.Option(..., "--board", help=_BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    model: str = typer.Option("k3", "--model", help=_MODEL_HELP),
    out_path: Path = typer.Option(Path("rig.json"), "--out", help="Where to write rig.json."),
    outlier_factor: float = typer.Option(
        3.0, "--outlier-factor", min=1.0, help="Leave out views whose RMS exceeds this times the median."
    ),
    charuco: str = typer.Option(None, "--charuco", help=_CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    as_json: bool = typer.Option(False, "--json", help="Print the rig.json object instead of tables."),
) -> None:
    """Calibrate a rig of cameras from views of a board seen at once: intrinsics, poses, covariance.

    Views are matched across cameras by the number in their file names (left07.png with
    right07.png), else by sorted order; a view some cameras miss still helps the others'
    intrinsics. Each camera's intrinsics and distortion and its pose in the rig frame (the
    first camera's) are refined together (bundle adjustment) with their joint covariance,
    and printed also the way the Camera Calibration Toolbox for Matlab prints a stereo
    calibration (om, T +/- 3 sigma). Exit status 1 when some images were left out (each
    named) or a camera fails camera.json's plausibility checks, 2 when no calibration was
    possible.
    """
    try:
        b = _board(board, square_mm, charuco, marker_mm)
        if model not in DIST_MODELS:
            raise InputError(f"--model must be one of {', '.join(DIST_MODELS)}, got {model!r}")
        cameras = [parse_camera_option(c) for c in camera]
        # A bar on a terminal only (it would be a blank line in a log), gone once done.
        with images_progress("finding the board", show=err.is_terminal, transient=True) as progress:
            res = calibrate_rig_files(
                cameras, b, model=model, outlier_factor=outlier_factor, progress=progress
            )
        backup = save_rig(res.rig, out_path)
    except InputError as e:
        raise fail(str(e)) from None
    if backup is not None:
        warn(f"{out_path} replaced; the previous calibration is kept as {backup}")
    left_out = 0
    for c, views in zip(res.rig.cameras, res.views, strict=True):
        for v in views:
            if not v.used and v.reason != NO_IMAGE:
                left_out += 1
                warn(f"{v.image}: not used by camera {c.name}: {v.reason}")
    implausible = [_warn_calibrated(c.camera, out_path, f"camera {c.name}: ") for c in res.rig.cameras]
    if as_json:
        print_json(res.to_dict())
    else:
        _print_rig_calibration(res, out_path)
    if left_out or any(implausible):
        raise typer.Exit(EXIT_PARTIAL)


def _print_rig_calibration(res: RigCalibrationResult, out_path: Path) -> None:
    """Each camera's parameters, the cameras' poses, the views, and the Matlab toolbox's text."""
    rig = res.rig
    names = rig.names
    t = Table(title=f"cameras (model {res.model}), value +/- 1 sigma")
    t.add_column("parameter")
    for c in rig.cameras:
        w, h = c.camera.image_size
        t.add_column(f"{c.name} ({w}x{h} px)")
    cams = [c.camera for c in rig.cameras]
    for i, p in enumerate(cams[0].param_names):
        unit = " (px)" if i < 4 else ""
        digits = 4 if i < 4 else 6
        t.add_row(
            p + unit,
            *(f"{c.params[i]:.{digits}f} ± {fmt(np.sqrt(c.cov[i, i]), 2)}" for c in cams),
        )
    t.add_row("RMS (px)", *(f"{c.rms_px:.4f}" for c in cams))
    t.add_row(
        "residual std x, y (px)", *(f"{c.residual_std_px[0]:.4f}, {c.residual_std_px[1]:.4f}" for c in cams)
    )
    t.add_row(
        "views used",
        *(
            f"{n} of {sum(v.reason != NO_IMAGE for v in vs)}"
            for n, vs in zip(res.n_used, res.views, strict=True)
        ),
    )
    out.print(t)
    if len(rig) > 1:
        p = Table(title=f"camera poses in the rig frame ({names[0]}'s), +/- 1 sigma")
        for col in (
            "camera",
            "position t (mm)",
            "1 sigma t (mm)",
            "rotation vector (deg)",
            "1 sigma r (deg)",
            "distance (mm)",
        ):
            p.add_column(col)
        C = rig.cov
        for k in range(1, len(rig)):
            T = rig.cameras[k].cam2rig
            s = rig.extrinsic_slice(k)
            sd = np.sqrt(np.maximum(np.diag(C[s, s]), 0.0))
            p.add_row(
                names[k],
                ", ".join(f"{x:.3f}" for x in T[:3, 3]),
                ", ".join(fmt(x, 2) for x in sd[:3]),
                ", ".join(f"{x:.4f}" for x in np.degrees(rotvec_from_matrix(T[:3, :3]))),
                ", ".join(fmt(x, 2) for x in np.degrees(sd[3:])),
                f"{np.linalg.norm(T[:3, 3]):.3f}",
            )
        out.print(p)
    v = Table(title="views: RMS (px) per camera")
    v.add_column("view")
    for n in names:
        v.add_column(n, overflow="fold")
    for i, name in enumerate(res.view_names):
        cells = []
        for k in range(len(rig)):
            vr = res.views[k][i]
            if vr.used:
                cells.append(f"{vr.rms_px:.3f}")
            elif vr.reason == NO_IMAGE:
                cells.append("-")
            else:
                cells.append(f"[yellow]not used[/]: {vr.reason}")
        v.add_row(name, *cells)
    out.print(v)
    out.print("\nAs the Camera Calibration Toolbox for Matlab prints it:\n")
    out.print(res.matlab_text(), markup=False)
    out.print(f"\nwrote {out_path}")


# ---------------------------------------------------------------------------------- pose
def pose(
    images: list[str] = typer.Argument(
        None,
        help="Images of the board, or folders of them (in natural order); with --rig, image sets "
        "named with {camera}.",
    ),
    camera: Path = typer.Option(None, "--camera", help="camera.json from `stiffmap calibrate`."),
    rig: Path = typer.Option(None, "--rig", help=_RIG_HELP),
    per_camera: list[str] = typer.Option(None, "--images", help=_IMAGES_HELP),
    board: str = typer.Option(..., "--board", help=_BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    charuco: str = typer.Option(None, "--charuco", help=_CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    refine: str = typer.Option("auto", "--refine", help=_REFINE_HELP),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON list instead of a table."),
) -> None:
    """Pose of the board in each image: board2cam (4x4, mm), its 6x6 covariance and the RMS.

    With --rig, one pose per image set in the rig frame (the first camera's), fused from every
    camera that saw the board, and what each camera saw. An image (set) that fails gives an
    entry with its error; the others go on. Exit status 1 when some images failed, 2 when all did.
    """
    try:
        b = _board(board, square_mm, charuco, marker_mm)
        cam, the_rig = _camera_or_rig(camera, rig)
        refine = _refine(refine)
        items = _image_sets(images or [], per_camera or [], the_rig)
        ms = _measure(items, cam, the_rig, camera, rig, b, refine=refine)
    except InputError as e:
        raise fail(str(e)) from None
    size = b.size if hasattr(b, "size") else board
    if as_json:
        print_json([_pose_row(m, the_rig is not None) for m in ms])
    elif the_rig is None:
        _print_poses(ms, f"board2cam of the {size} board (camera frame)")
        out.print(_calibration_note(cam, str(camera)))
    else:
        _print_poses(ms, f"board2rig of the {size} board (rig frame: camera {the_rig.names[0]}'s), fused")
        _print_cameras(ms, the_rig)
        out.print(_rig_calibration_note(the_rig, str(rig)))
    _warn_failures(ms, the_rig, refine, as_json)
    _exit_for(sum(m.ok for m in ms), len(ms), _measured_with(camera, board, rig), _camera_failures(ms) > 0)


def _pose_row(m: ImageMeasurement, with_cameras: bool = False) -> dict:
    """The JSON object of one image (set): its pose, or its error; with a rig, each camera's."""
    cams = {"cameras": _cameras_json(m)} if with_cameras else {}
    if not m.ok:
        return {"image": m.image, "error": m.error, **cams}
    row = {"image": m.image, "board2cam": m.mobile.board2cam, "cov": m.mobile.cov, **_pose_json(m.mobile)}
    if with_cameras:
        row["frame"] = "rig"
        row["consistency"] = _consistency_json(m.mobile)
    return {**row, **cams}


def _calibration_note(cam, source: str) -> str:
    """Where the calibration's share of the uncertainties comes from."""
    src = cam.calibration_cov_source
    if src == "cov":
        return f"the 1 sigma include the calibration's ({source}: full covariance)"
    if src == "std":
        return (
            f"the 1 sigma include the calibration's ({source}: its 'std' as a diagonal covariance, "
            "correlations unknown; recalibrate to store 'cov')"
        )
    return f"the calibration's uncertainty is unknown ({source} has no 'cov' or 'std'): not included"


def _print_poses(ms: list[ImageMeasurement], title: str) -> None:
    t = Table(title=title)
    t.add_column("image", overflow="fold")
    for col in (
        "t (mm)",
        "1 sigma t (mm)",
        "of which calibration (mm)",
        "rotation vector (rad)",
        "RMS (px)",
        "corners",
        "method",
        "ms",
    ):
        t.add_column(col)
    for m in ms:
        if not m.ok:
            t.add_row(m.image, "[red]failed[/]", "", "", "", "", "", "", "")
            continue
        p = m.mobile
        method = p.method
        if p.photometric is not None:
            method += f" ({p.photometric.rms_dn:.2f} DN RMS)"
        t.add_row(
            m.image,
            ", ".join(f"{x:.4f}" for x in p.board2cam[:3, 3]),
            ", ".join(f"{x:.4f}" for x in p.t_std_mm),
            ", ".join(fmt(x, 4) for x in p.t_std_calibration_mm) if p.cov_calibration is not None else "-",
            ", ".join(f"{x:.6f}" for x in rotvec_from_matrix(p.board2cam[:3, :3])),
            f"{p.rms_px:.3f}",
            str(p.n_corners),
            method,
            f"{1000 * m.timings.get('total', np.nan):.0f}",
        )
    out.print(t)


# -------------------------------------------------------------------------- displacement
def displacement(
    images: list[str] = typer.Argument(
        None, help="Images after the load (or any moved state); with --rig, image sets named with {camera}."
    ),
    camera: Path = typer.Option(None, "--camera", help="camera.json from `stiffmap calibrate`."),
    rig: Path = typer.Option(None, "--rig", help=_RIG_HELP),
    per_camera: list[str] = typer.Option(None, "--images", help=_IMAGES_HELP),
    board: str = typer.Option(..., "--board", help="Mobile target size COLSxROWS (inner corners)."),
    square_mm: float = typer.Option(..., "--square-mm", help="Mobile target square side, mm."),
    reference: list[str] = typer.Option(
        ...,
        "--reference",
        help="Reference (unloaded) image; repeat the option for several (averaged). With --rig, an "
        "image set named with {camera}, or NAME=GLOB for each camera.",
    ),
    fixed_board: str = typer.Option(None, "--fixed-board", help="Fixed target size COLSxROWS (on the base)."),
    fixed_square_mm: float = typer.Option(None, "--fixed-square-mm", help="Fixed target square side, mm."),
    fixed2base: Path = typer.Option(
        None, "--fixed2base", help="JSON file with the fixed target's pose on the robot base (4x4, mm)."
    ),
    point: str = typer.Option(None, "--point", help="x,y,z (mm, target frame): displacement of this point."),
    charuco: str = typer.Option(None, "--charuco", help=_CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    refine: str = typer.Option("auto", "--refine", help=_REFINE_HELP),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON list instead of tables."),
) -> None:
    """Displacement of the target in each image relative to the reference image(s).

    d = [dx, dy, dz] (mm) and r = rotation vector (rad), in the camera frame (with --rig, the rig
    frame: the first camera's), or in the robot base frame with
    --fixed-board/--fixed-square-mm/--fixed2base. The mean, standard deviation and n over the
    images are printed at the end. Exit status 1 when some images (or cameras) failed.
    """
    try:
        b = _board(board, square_mm, charuco, marker_mm)
        cam, the_rig = _camera_or_rig(camera, rig)
        fb, T_fb = _fixed_target(fixed_board, fixed_square_mm, fixed2base)
        q = _point(point)
        refine = _refine(refine)
        ref_items = list(reference)
        ref_cams = []
        if the_rig is not None:
            # --reference NAME=GLOB gives one camera's reference images; other entries are sets.
            names = set(the_rig.names)
            ref_cams = [r for r in reference if "=" in r and r.partition("=")[0].strip() in names]
            ref_items = [r for r in reference if r not in ref_cams]
        refs = _image_sets(ref_items, ref_cams, the_rig, what="--reference")
        moved = _image_sets(images or [], per_camera or [], the_rig)
        if not refs or not moved:
            raise InputError(
                "give the reference (unloaded) images with --reference and the images to compare with "
                "them" + (" (names holding {camera}, or --images NAME=GLOB)" if the_rig is not None else "")
            )
        # One tracked sequence: a symmetric board keeps its numbering from the references on.
        ms = _measure(refs + moved, cam, the_rig, camera, rig, b, fb, T_fb, refine=refine)
        n_ref = len(refs)
    except InputError as e:
        raise fail(str(e)) from None
    _warn_failures(ms, the_rig, refine, as_json)
    try:
        res = displacement_per_image(ms[:n_ref], ms[n_ref:], q)
    except InputError as e:
        raise fail(str(e)) from None
    for f in res.summary.flags if res.summary is not None else ():
        warn(f)
    frame_names = {"cam": "rig"} if the_rig is not None else {}
    if as_json:
        print_json(_displacement_rows(res, frame_names, the_rig is not None))
    else:
        _print_displacements(res, frame_names)
        if the_rig is None:
            out.print(_calibration_note(cam, str(camera)))
        else:
            _print_cameras(list(res.references) + list(res.images), the_rig)
            out.print(_rig_calibration_note(the_rig, str(rig)))
    _exit_for(res.n_ok, res.n_images, _measured_with(camera, board, rig), _camera_failures(ms) > 0)


def _displacement_rows(res: ImageDisplacements, frame_names=None, with_cameras: bool = False) -> list[dict]:
    """The JSON list: one object per image (its displacement or its error), then the mean.

    With a rig, each image set's object also holds ``cameras`` (what each camera saw) and the
    references come first, marked ``"reference": true``.
    """
    frame_names = frame_names or {}
    rows = []
    if with_cameras:
        for m in res.references:
            row = {"image": m.image, "reference": True, "error": m.error, "cameras": _cameras_json(m)}
            rows.append(row)
    for m, dsp in zip(res.images, res.displacements, strict=True):
        cams = {"cameras": _cameras_json(m)} if with_cameras else {}
        if dsp is None:
            rows.append({"image": m.image, "error": m.error, **cams})
            continue
        rows.append(
            {
                "image": m.image,
                "frame": frame_names.get(dsp.frame, dsp.frame),
                "d": dsp.d,
                "r": dsp.r,
                "d_std": dsp.d_sigma,
                "r_std": dsp.r_sigma,
                **_calibration_keys(dsp),
                **cams,
            }
        )
    s = res.summary
    if s is not None:
        rows.append(
            {
                "image": None,
                "summary": "mean over images",
                "frame": frame_names.get(s.frame, s.frame),
                "n": s.n,
                "d": s.d,
                "r": s.r,
                "d_std": s.d_std,
                "r_std": s.r_std,
                "d_sigma": s.d_sigma,
                "r_sigma": s.r_sigma,
                **_calibration_keys(s),
            }
        )
    return rows


def _calibration_keys(d) -> dict:
    """The calibration's part of a displacement's propagated 1 sigma (None: unknown).

    ``calibration_share`` is the share of each component's variance (dx..rz) from the camera's
    calibration, an error common to every displacement measured with the camera.
    """
    if d.cov_calibration is None:
        return {"d_std_calibration": None, "r_std_calibration": None, "calibration_share": None}
    return {
        "d_std_calibration": d.d_sigma_calibration,
        "r_std_calibration": d.r_sigma_calibration,
        "calibration_share": d.calibration_share,
    }


def _print_displacements(res: ImageDisplacements, frame_names=None) -> None:
    summary = res.summary
    frame = summary.frame if summary else "cam"
    frame = (frame_names or {}).get(frame, frame)
    n_ref = len(res.references)
    t = Table(title=f"displacement relative to {n_ref} reference image(s), {frame} frame (+/- 1 sigma)")
    t.add_column("image", overflow="fold")
    for col in (
        "dx, dy, dz (mm)",
        "1 sigma (mm)",
        "of which calibration (mm)",
        "calibration share of variance",
        "rx, ry, rz (rad)",
        "|d| (mm)",
    ):
        t.add_column(col)

    def cal(d) -> tuple[str, str]:
        if d.cov_calibration is None:
            return "-", "-"
        return (
            ", ".join(fmt(x, 3) for x in d.d_sigma_calibration),
            ", ".join(f"{100 * x:.0f} %" for x in d.calibration_share[:3]),
        )

    for m, dsp in zip(res.images, res.displacements, strict=True):
        if dsp is None:
            continue
        t.add_row(
            m.image,
            ", ".join(f"{x:.4f}" for x in dsp.d),
            ", ".join(f"{x:.4f}" for x in dsp.d_sigma),
            *cal(dsp),
            ", ".join(f"{x:.2e}" for x in dsp.r),
            f"{np.linalg.norm(dsp.d):.4f}",
        )
    if summary is not None:
        t.add_row(
            f"mean of {summary.n}",
            ", ".join(f"{x:.4f}" for x in summary.d),
            "std " + ", ".join(fmt(x, 3) for x in summary.d_std),
            *cal(summary),
            ", ".join(f"{x:.2e}" for x in summary.r),
            f"{np.linalg.norm(summary.d):.4f}",
        )
    out.print(t)


# ------------------------------------------------------------------------------ validate
def validate(
    manifest: Path = typer.Argument(
        ..., help="CSV with columns image,nominal_mm (stage displacement; 0 = start position)."
    ),
    camera: Path = typer.Option(..., "--camera", help="camera.json from `stiffmap calibrate`."),
    board: str = typer.Option(..., "--board", help=_BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    plot: Path = typer.Option(
        None, "--plot", help="Write an SVG plot (measured vs nominal, error per step)."
    ),
    charuco: str = typer.Option(None, "--charuco", help=_CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    refine: str = typer.Option("auto", "--refine", help=_REFINE_HELP),
    allow_outside: bool = typer.Option(
        False,
        "--allow-outside-paths",
        help="Read images the manifest lists outside its own folder (absolute paths, '..').",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of tables."),
) -> None:
    """Validate against known stage displacements: measured vs nominal, mean +/- std per step.

    After the reference study's X-table test (its Table I, shown beside when the steps match).
    """
    try:
        b = _board(board, square_mm, charuco, marker_mm)
        cam = load_camera(camera)
        rows = read_stage_manifest(manifest, allow_outside=allow_outside)
        refine = _refine(refine)
    except InputError as e:
        raise fail(str(e)) from None
    ms = measure_files([r.image for r in rows], cam, b, camera_source=str(camera), refine=refine)
    for m, r in zip(ms, rows, strict=True):
        if not m.ok:
            warn(f"{manifest}, line {r.line}: {m.error}")
    try:
        res = validate_stage_series(ms, [r.nominal_mm for r in rows])
    except InputError as e:
        raise fail(f"{manifest}: {e}") from None
    if plot is not None:
        atomic_write_text(plot, stage_plot_svg(res, title=f"Stage validation: {manifest.name}"))
    if as_json:
        print_json(_validation_json(res))
    else:
        _print_validation(res, plot)
    _exit_for(len(ms) - len(res.failed), len(ms), _measured_with(camera, board))


def _validation_json(res: StageValidation) -> dict:
    return {
        "steps": [
            {
                "nominal_mm": s.nominal_mm,
                "mean_mm": s.mean_mm,
                "std_mm": s.std_mm,
                "n": s.n,
                "error_mm": s.error_mm,
                "along_mean_mm": s.along_mean_mm,
                "along_std_mm": s.along_std_mm,
            }
            for s in res.steps
        ],
        "axis": res.axis,
        "n_reference": res.n_reference,
        "rms_error_mm": res.rms_error_mm,
        "failed": [{"image": a, "error": e} for a, e in res.failed],
    }


def _print_validation(res: StageValidation, plot: Path | None) -> None:
    """Each step against the reference study's Table I, the RMS error, and the plot written."""
    t = Table(title=f"stage validation ({res.n_reference} reference image(s)); norm of the displacement")
    for col in (
        "nominal (mm)",
        "measured mean ± std (mm)",
        "n",
        "error (mm)",
        "along axis (mm)",
        "reference study",
    ):
        t.add_column(col)
    for s in res.steps:
        ref = REFERENCE_TABLE_I.get(s.nominal_mm)
        t.add_row(
            f"{s.nominal_mm:g}",
            f"{s.mean_mm:.4f} ± {fmt(s.std_mm, 2)}",
            str(s.n),
            f"{s.error_mm:+.4f}",
            f"{s.along_mean_mm:.4f} ± {fmt(s.along_std_mm, 2)}",
            f"{ref[0]} ± {ref[1]}" if ref else "",
        )
    out.print(t)
    out.print(f"RMS error over all images: {res.rms_error_mm:.4f} mm")
    if plot is not None:
        out.print(f"wrote {plot}")


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate)
    app.command("calibrate-rig")(calibrate_rig)
    app.command("pose")(pose)
    app.command("displacement")(displacement)
    app.command("validate")(validate)
