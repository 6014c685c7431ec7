"""Calibration commands: ``calibrate`` (one camera) and ``calibrate-rig`` (several, together)
(see docs/vision.md). ``pose``, ``displacement`` and ``validate`` have their own modules; the
options they share are in :mod:`stiffmap.cli.vision_options`.

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

from ..camera import invertible_field, plausibility_problems, save_camera
from ..errors import InputError
from ..geometry import rotvec_from_matrix
from ..rig import parse_named_pattern, save_rig
from ..vision.calibrate import DIST_MODELS, CalibrationResult, grouped_reasons
from ..vision.files import calibrate_files, calibrate_rig_files
from ..vision.rig_calibration import NO_IMAGE, RigCalibrationResult
from .common import EXIT_WARNINGS, err, fail, fmt, images_progress, note, out, print_json, warn
from .vision_options import BOARD_HELP, CHARUCO_HELP, board_option


# ----------------------------------------------------------------------------- calibrate
def calibrate(
    images: list[Path] = typer.Argument(
        ..., help="Images of the board (at least 3 views), or folders of them."
    ),
    board: str = typer.Option(..., "--board", help=BOARD_HELP),
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
    charuco: str = typer.Option(None, "--charuco", help=CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    as_json: bool = typer.Option(False, "--json", help="Print the camera.json object instead of tables."),
) -> None:
    """Calibrate a camera from images of a board (Zhang's method): intrinsics, distortion, 1-sigma.

    Views where the board is not found, or whose RMS is an outlier, are left out with the
    reason (a note each). Also printed the way the Camera Calibration Toolbox for Matlab does
    (+/- 3 sigma). Exit status 0 for a good calibration (also when some views were left out),
    1 when it comes with warnings (it fails camera.json's plausibility checks: a warning per
    key, the other commands will refuse it), 2 when no calibration was possible.
    """
    try:
        b = board_option(board, square_mm, charuco, marker_mm)
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
        note(f"{out_path} replaced; the previous calibration is kept as {backup}")
    unused = [v for v in res.views if not v.used]
    for line in grouped_reasons([v.image for v in unused], [v.reason for v in unused]):
        note(f"not used: {line}")  # a good calibration leaves some views out: said, not a warning
    implausible = _warn_calibrated(res.camera, out_path, field_warning=False)
    for key, what in res.problems:
        warn(f"{out_path}: {key}: {what}")
    if res.lens_advice:  # advice on a good calibration (its model serves where the corners are)
        note(f"{out_path}: {res.lens_advice}")
    if as_json:
        print_json(res.to_dict())
    else:
        _print_calibration(res, out_path)
    if implausible or res.problems:
        raise typer.Exit(EXIT_WARNINGS)


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
    try:
        return parse_named_pattern(text)
    except ValueError as e:
        raise InputError(f"--camera {text!r}: {e} (e.g. --camera 'left=img/left*.png')") from None


def calibrate_rig(
    camera: list[str] = typer.Option(..., "--camera", help=_CAMERA_HELP),
    board: str = typer.Option(..., "--board", help=BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    model: str = typer.Option("k3", "--model", help=_MODEL_HELP),
    out_path: Path = typer.Option(Path("rig.json"), "--out", help="Where to write rig.json."),
    outlier_factor: float = typer.Option(
        3.0, "--outlier-factor", min=1.0, help="Leave out views whose RMS exceeds this times the median."
    ),
    charuco: str = typer.Option(None, "--charuco", help=CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    as_json: bool = typer.Option(False, "--json", help="Print the rig.json object instead of tables."),
) -> None:
    """Calibrate a rig of cameras from views of a board seen at once: intrinsics, poses, covariance.

    Views are matched across cameras by the number in their file names (left07.png with
    right07.png), else by sorted order; a view some cameras miss still helps the others'
    intrinsics. Each camera's intrinsics and distortion and its pose in the rig frame (the
    first camera's) are refined together (bundle adjustment) with their joint covariance,
    and printed also the way the Camera Calibration Toolbox for Matlab prints a stereo
    calibration (om, T +/- 3 sigma). Exit status 0 for a good calibration (also when some
    views were left out: a note each), 1 when a camera fails camera.json's plausibility
    checks (a warning each), 2 when no calibration was possible.
    """
    try:
        b = board_option(board, square_mm, charuco, marker_mm)
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
        note(f"{out_path} replaced; the previous calibration is kept as {backup}")
    for c, views in zip(res.rig.cameras, res.views, strict=True):
        for v in views:
            if not v.used and v.reason != NO_IMAGE:
                note(f"{v.image}: not used by camera {c.name}: {v.reason}")
    for line in res.dispersion_notes():
        note(line)
    implausible = [_warn_calibrated(c.camera, out_path, f"camera {c.name}: ") for c in res.rig.cameras]
    if as_json:
        print_json(res.to_dict())
    else:
        _print_rig_calibration(res, out_path)
    if any(implausible):
        raise typer.Exit(EXIT_WARNINGS)


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


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate)
    app.command("calibrate-rig")(calibrate_rig)
