"""``stiffmap displacement``: the target's displacement in each image relative to reference images,
with one camera or a rig (docs/vision.md).

Parses the options, calls :func:`stiffmap.vision.file_commands.displacement_files` and prints.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from ..errors import InputError
from ..rig import Rig
from ..vision.displacement import ImageDisplacements
from ..vision.file_commands import displacement_files
from ..vision.records import displacement_records
from .common import fail, fmt, out, print_json, warn
from .vision_options import (
    CHARUCO_HELP,
    IMAGES_HELP,
    REFINE_HELP,
    RIG_HELP,
    board_option,
    calibration_note,
    camera_failures,
    camera_or_rig,
    exit_for,
    fixed_target_option,
    measured_with,
    point_option,
    print_cameras,
    refine_option,
    rig_calibration_note,
    warn_failures,
)


def displacement(
    images: list[str] = typer.Argument(
        None, help="Images after the load (or any moved state); with --rig, image sets named with {camera}."
    ),
    camera: Path = typer.Option(None, "--camera", help="camera.json from `stiffmap calibrate`."),
    rig: Path = typer.Option(None, "--rig", help=RIG_HELP),
    per_camera: list[str] = typer.Option(None, "--images", help=IMAGES_HELP),
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
    charuco: str = typer.Option(None, "--charuco", help=CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    refine: str = typer.Option("auto", "--refine", help=REFINE_HELP),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON list instead of tables."),
) -> None:
    """Displacement of the target in each image relative to the reference image(s).

    d = [dx, dy, dz] (mm) and r = rotation vector (rad), in the camera frame (with --rig, the rig
    frame: the first camera's), or in the robot base frame with
    --fixed-board/--fixed-square-mm/--fixed2base. The mean, standard deviation and n over the
    images are printed at the end. Exit status 1 when some images (or cameras) failed.
    """
    try:
        b = board_option(board, square_mm, charuco, marker_mm)
        cameras, source = camera_or_rig(camera, rig)
        res = displacement_files(
            reference,
            images or [],
            cameras,
            b,
            per_camera=per_camera or [],
            fixed=fixed_target_option(fixed_board, fixed_square_mm, fixed2base),
            point=point_option(point),
            refine=refine_option(refine),
            source=source,
        )
    except InputError as e:
        raise fail(str(e)) from None
    the_rig = cameras if isinstance(cameras, Rig) else None
    ms = [*res.references, *res.images]
    warn_failures(ms, the_rig, refine, as_json, rig_file=source)
    for f in res.summary.flags if res.summary is not None else ():
        warn(_named(f, res))
    frame_names = {"cam": "rig"} if the_rig is not None else {}
    if as_json:
        print_json(displacement_records(res, frame_names, the_rig is not None))
    else:
        _print_displacements(res, frame_names)
        if the_rig is None:
            out.print(calibration_note(cameras, source))
        else:
            print_cameras(ms, the_rig)
            out.print(rig_calibration_note(the_rig, source))
    exit_for(res.n_ok, res.n_images, measured_with(camera, board, rig), camera_failures(ms) > 0)


def _files(ms) -> str:
    names = [m.image for m in ms]
    return ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")


def _named(flag: str, res: ImageDisplacements) -> str:
    """A flag of the images as a whole, with the files it is about (the fixed target's move)."""
    if "fixed target moved" not in flag:
        return flag
    return f"reference {_files(res.references)} -> {_files(res.images)}: {flag}"


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


def register(app: typer.Typer) -> None:
    app.command("displacement")(displacement)
