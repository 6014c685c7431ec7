"""``stiffmap validate``: measured against known stage displacements, after the reference study's
X-table test (docs/vision.md).

Parses the options, calls :func:`stiffmap.vision.file_commands.validate_files` and prints.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from ..errors import InputError
from ..io import atomic_write_text
from ..report.validation import stage_plot_svg
from ..vision.file_commands import validate_files
from ..vision.records import validation_record
from ..vision.validate import REFERENCE_TABLE_I, StageValidation
from .common import fail, fmt, out, print_json, warn
from .vision_options import (
    BOARD_HELP,
    CHARUCO_HELP,
    REFINE_HELP,
    board_option,
    exit_for,
    load_camera_option,
    measured_with,
    refine_option,
)


def validate(
    manifest: Path = typer.Argument(
        ..., help="CSV with columns image,nominal_mm (stage displacement; 0 = start position)."
    ),
    camera: Path = typer.Option(..., "--camera", help="camera.json from `stiffmap calibrate`."),
    board: str = typer.Option(..., "--board", help=BOARD_HELP),
    square_mm: float = typer.Option(..., "--square-mm", help="Side of a square, mm."),
    plot: Path = typer.Option(
        None, "--plot", help="Write an SVG plot (measured vs nominal, error per step)."
    ),
    charuco: str = typer.Option(None, "--charuco", help=CHARUCO_HELP),
    marker_mm: float = typer.Option(None, "--marker-mm", help="ChArUco marker side, mm."),
    refine: str = typer.Option("auto", "--refine", help=REFINE_HELP),
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
        b = board_option(board, square_mm, charuco, marker_mm)
        run = validate_files(
            manifest,
            load_camera_option(camera, rig_option=False),
            b,
            refine=refine_option(refine),
            allow_outside=allow_outside,
            source=str(camera),
        )
    except InputError as e:
        raise fail(str(e)) from None
    for m, r in zip(run.measurements, run.rows, strict=True):
        if not m.ok:
            warn(f"{manifest}, line {r.line}: {m.error}")
    res = run.validation
    if plot is not None:
        atomic_write_text(plot, stage_plot_svg(res, title=f"Stage validation: {manifest.name}"))
    if as_json:
        print_json(validation_record(res))
    else:
        _print_validation(res, plot)
    exit_for(len(run.measurements) - len(res.failed), len(run.measurements), measured_with(camera, board))


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
    app.command("validate")(validate)
