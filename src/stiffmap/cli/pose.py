"""``stiffmap pose``: the board's pose in each image, with one camera or a rig (docs/vision.md).

Parses the options, calls :func:`stiffmap.vision.file_commands.pose_files` and prints.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from ..errors import InputError
from ..geometry import rotvec_from_matrix
from ..rig import Rig
from ..vision.file_commands import pose_files
from ..vision.records import pose_record
from ..vision.sequence import ImageMeasurement
from .common import fail, fmt, out, print_json
from .vision_options import (
    BOARD_HELP,
    CHARUCO_HELP,
    IMAGES_HELP,
    REFINE_HELP,
    RIG_HELP,
    board_option,
    calibration_note,
    camera_failures,
    camera_or_rig,
    exit_for,
    measured_with,
    print_cameras,
    refine_option,
    rig_calibration_note,
    warn_failures,
)


def pose(
    images: list[str] = typer.Argument(
        None,
        help="Images of the board, or folders of them (in natural order); with --rig, image sets "
        "named with {camera}.",
    ),
    camera: Path = typer.Option(None, "--camera", help="camera.json from `stiffmap calibrate`."),
    rig: Path = typer.Option(None, "--rig", help=RIG_HELP),
    per_camera: list[str] = typer.Option(None, "--images", help=IMAGES_HELP),
    board: str = typer.Option(..., "--board", help=BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    charuco: str = typer.Option(None, "--charuco", help=CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    refine: str = typer.Option("auto", "--refine", help=REFINE_HELP),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON list instead of a table."),
) -> None:
    """Pose of the board in each image: board2cam (4x4, mm), its 6x6 covariance and the RMS.

    With --rig, one pose per image set in the rig frame (the first camera's), fused from every
    camera that saw the board, and what each camera saw. An image (set) that fails gives an
    entry with its error; the others go on. Exit status 1 when some images failed, 2 when all did.
    """
    try:
        b = board_option(board, square_mm, charuco, marker_mm)
        cameras, source = camera_or_rig(camera, rig)
        ms = pose_files(
            images or [], cameras, b, per_camera=per_camera or [], refine=refine_option(refine), source=source
        )
    except InputError as e:
        raise fail(str(e)) from None
    the_rig = cameras if isinstance(cameras, Rig) else None
    size = b.size if hasattr(b, "size") else board
    if as_json:
        print_json([pose_record(m, the_rig is not None) for m in ms])
    elif the_rig is None:
        _print_poses(ms, f"board2cam of the {size} board (camera frame)")
        out.print(calibration_note(cameras, source))
    else:
        _print_poses(ms, f"board2rig of the {size} board (rig frame: camera {the_rig.names[0]}'s), fused")
        print_cameras(ms, the_rig)
        out.print(rig_calibration_note(the_rig, source))
    warn_failures(ms, the_rig, refine, as_json, rig_file=source)
    exit_for(sum(m.ok for m in ms), len(ms), measured_with(camera, board, rig), camera_failures(ms) > 0)


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
            ", ".join(f"{x:.4f}" for x in p.board2frame[:3, 3]),
            ", ".join(f"{x:.4f}" for x in p.t_std_mm),
            ", ".join(fmt(x, 4) for x in p.t_std_calibration_mm) if p.cov_calibration is not None else "-",
            ", ".join(f"{x:.6f}" for x in rotvec_from_matrix(p.board2frame[:3, :3])),
            f"{p.rms_px:.3f}",
            str(p.n_corners),
            method,
            f"{1000 * m.timings.get('total', np.nan):.0f}",
        )
    out.print(t)


def register(app: typer.Typer) -> None:
    app.command("pose")(pose)
