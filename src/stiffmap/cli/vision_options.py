"""Options and printing shared by the vision commands (``calibrate``, ``calibrate-rig``, ``pose``,
``displacement``, ``validate``): a board from ``--board``/``--square-mm``, one camera or a rig,
the fixed target, ``--refine``, the warnings of failed images and the exit status.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from ..camera import CameraModel, RigFileAsCamera, load_camera
from ..errors import InputError
from ..rig import Rig, load_rig
from ..targets import CharucoBoard, Chessboard, parse_board_size
from ..vision.calibrate import grouped_reasons
from ..vision.file_commands import FixedTarget
from ..vision.files import MAX_TRANSLATION_MM, read_transform
from ..vision.sequence import ImageMeasurement, photometric_summary
from .common import EXIT_PARTIAL, fail, out, three_numbers, warn

BOARD_HELP = "Board size COLSxROWS in inner corners, e.g. 13x12."
CHARUCO_HELP = (
    "The board is a ChArUco board with this ArUco dictionary (e.g. DICT_5X5_100); "
    "--board still counts inner corners (squares - 1)."
)


def board_option(
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


def point_option(text: str | None) -> tuple[float, float, float] | None:
    """``--point x,y,z`` (mm, target frame), None when not given."""
    if text is None:
        return None
    v = three_numbers(text)
    if v is None or max(abs(x) for x in v) > MAX_TRANSLATION_MM:
        raise InputError(
            f"--point must be three numbers x,y,z in mm (target frame, within {MAX_TRANSLATION_MM:g} mm), "
            f"got {text!r}"
        )
    return v


def fixed_target_option(
    board: str | None, square_mm: float | None, fixed2base: Path | None
) -> FixedTarget | None:
    """The fixed target and its pose on the base (None when not given)."""
    if board is None and square_mm is None and fixed2base is None:
        return None
    if board is None or square_mm is None or fixed2base is None:
        raise InputError(
            "--fixed-board, --fixed-square-mm and --fixed2base go together (for the fixed "
            "target's own frame, give a --fixed2base file holding the 4x4 identity)"
        )
    fb = board_option(board, square_mm, what="--fixed-board", square_option="--fixed-square-mm")
    return FixedTarget(fb, read_transform(fixed2base))


REFINE_HELP = (
    "Pose refinement: photometric (a model of the blurred board fitted to its pixels; several "
    "times more precise along the line of sight; the corner pose is kept when it fails its "
    "checks), corners (reprojection of the corners), or auto (photometric for chessboards, "
    "corners for ChArUco boards)."
)


def refine_option(value: str) -> str:
    if value not in ("auto", "photometric", "corners"):
        raise InputError(f"--refine must be auto, photometric or corners, got {value!r}")
    return value


def warn_failures(
    ms: list[ImageMeasurement],
    rig: Rig | None = None,
    refine: str = "photometric",
    as_json: bool = False,
    rig_file: str = "rig file",
) -> None:
    """One warning per image (set) that failed, or whose pose fell back to the corners (with why).

    With a rig, also one per camera whose image of a measured set could not be used, and one
    per fused pose whose cameras disagree (a wrong rig file, a moved camera: the line begins
    with ``rig_file``, the file the rig was read from, as a campaign's does). With the default
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
                warn(f"{rig_file}: {m.image}: {w}")
        for p in (m.mobile, m.fixed):
            if p is not None and p.fallback and refine != "auto":
                warn(f"{m.image}: {p.fallback}")


def camera_failures(ms: list[ImageMeasurement]) -> int:
    """Cameras whose image of a measured set could not be used."""
    return sum(1 for m in ms if m.ok for v in m.views if v.error)


def exit_for(n_ok: int, n_total: int, inputs: str = "", partial: bool = False) -> None:
    """Exit 2 (with an ``error:`` line) when nothing was measured, 1 when some items failed.

    ``inputs`` names what every image was measured with (the camera file, the board), the
    suspects when none could be; ``partial`` says some camera's image of a measured set failed.
    """
    if n_ok == 0:
        raise fail(f"none of the {n_total} image(s) could be measured{inputs} (see the warnings above)")
    if n_ok < n_total or partial:
        raise typer.Exit(EXIT_PARTIAL)


def measured_with(camera: Path | None, board: str, rig: Path | None = None) -> str:
    if rig is not None:
        return f" with --rig {rig} and --board {board}"
    return f" with --camera {camera} and --board {board}"


RIG_HELP = (
    "rig.json (several calibrated cameras, instead of --camera): each image set is then one image "
    "per camera, named with {camera} (e.g. 'shots/{camera}_07.png') or given by --images."
)
IMAGES_HELP = (
    "With --rig: NAME=GLOB, one camera's images (a quoted file pattern, a folder or a file); repeat "
    "for every camera. Views are matched by the number in their file names (left07.png with "
    "right07.png), else in order."
)


def camera_or_rig(camera: Path | None, rig: Path | None) -> tuple[CameraModel | Rig, str]:
    """The camera model (``--camera``) or the rig (``--rig``), exactly one, and its file's name."""
    if camera is not None and rig is not None:
        raise InputError("--camera and --rig: give one (a rig.json holds every camera of the rig)")
    if camera is None and rig is None:
        raise InputError("give --camera camera.json (one camera) or --rig rig.json (several)")
    if rig is not None:
        return load_rig(rig), str(rig)
    return load_camera_option(camera), str(camera)


def load_camera_option(camera: Path, rig_option: bool = True) -> CameraModel:
    """``--camera``'s camera.json; a rig file there is answered with the option that takes it."""
    try:
        return load_camera(camera)
    except RigFileAsCamera as e:
        what = f"--camera {camera}: this is a rig file ({e.cameras})"
        if rig_option:
            raise InputError(f"{what}: use --rig {camera}") from None
        raise InputError(f"{what}: this command takes one camera's camera.json") from None


def print_cameras(ms: list[ImageMeasurement], rig: Rig) -> None:
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


def rig_calibration_note(rig: Rig, source: str) -> str:
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


def calibration_note(cam, source: str) -> str:
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
