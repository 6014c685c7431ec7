"""File-level entry points of the vision path (the CLI and the campaign runner call these).

The numerical modules take arrays; this module reads files: the transform of
the fixed target on the base (a 4x4 in JSON), the stage-validation manifest (a
CSV), and it runs calibration and pose measurement over lists of image files,
turning each bad file into a recorded error while the others go on.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..geometry import as_transform
from ..io import read_csv_columns, read_json
from .calibrate import CalibrationResult, calibrate_camera
from .detect import Board, BoardDetection, detect_board
from .images import read_image
from .sequence import ImageMeasurement, measure_sequence

__all__ = [
    "IMAGE_SUFFIXES",
    "image_files",
    "read_transform",
    "read_stage_manifest",
    "calibrate_files",
    "measure_files",
]

#: File-name endings taken as images when a folder is given (any case).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".webp")


def _natural_key(path: Path) -> list:
    """Sort key putting ``view2.jpg`` before ``view10.jpg``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def image_files(paths: Sequence[str | os.PathLike]) -> list[Path]:
    """The image files named: files as given, folders replaced by the images they hold.

    A folder gives its files ending in :data:`IMAGE_SUFFIXES` (any case), in natural
    order (``view2`` before ``view10``); sub-folders are not searched.

    Raises
    ------
    InputError
        A folder without image files (naming it and the endings looked for).
    """
    out: list[Path] = []
    for p in map(Path, paths):
        if not p.is_dir():
            out.append(p)
            continue
        found = sorted(
            (q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES and q.is_file()), key=_natural_key
        )
        if not found:
            raise InputError(
                "the folder holds no image files (looked for " + ", ".join(IMAGE_SUFFIXES) + ")",
                source=str(p),
            )
        out.extend(found)
    return out


def read_transform(path: str | os.PathLike, key: str = "fixed2base") -> np.ndarray:
    """Read a rigid transform (4x4, mm) from a JSON file.

    The file holds either the matrix itself (a list of 4 rows of 4 numbers) or
    an object with the matrix under ``key`` (or ``"matrix"``).

    Raises
    ------
    InputError
        Naming the file and what is wrong (missing, not JSON, not 4x4, not rigid).
    """
    src = str(path)
    data = read_json(path, "transform file")
    if isinstance(data, dict):
        for k in (key, "matrix"):
            if k in data:
                data = data[k]
                break
        else:
            raise InputError(f"expected a 4x4 matrix or an object with key {key!r}", source=src)
    try:
        T = np.array(data, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"expected a 4x4 matrix of numbers (mm), got {data!r:.80}", source=src) from None
    if T.shape != (4, 4):
        raise InputError(f"expected a 4x4 matrix (4 rows of 4 numbers, mm), got shape {T.shape}", source=src)
    try:
        return as_transform(T, key, atol=1e-4)
    except ValueError as e:
        raise InputError(f"not a rigid transform: {e}", source=src) from None


def read_stage_manifest(path: str | os.PathLike) -> list[tuple[str, float]]:
    """Read a stage-validation manifest: CSV columns ``image`` and ``nominal_mm``.

    Image paths are relative to the manifest's directory; rows with
    ``nominal_mm = 0`` are the reference (start) position.

    Returns
    -------
    list of (image path, nominal displacement in mm)
    """
    t = read_csv_columns(path, ["image", "nominal_mm"], text_columns=["image"])
    base = Path(path).parent
    out = []
    for name, nom, line in zip(t.text["image"], t.columns["nominal_mm"], t.lines, strict=True):
        if not name:
            raise InputError(f"line {line}, column 'image': empty image name", source=str(path))
        if nom < 0:
            raise InputError(
                f"line {line}, column 'nominal_mm': {nom:g} is negative; give the distance moved "
                "from the start position (>= 0 mm)",
                source=str(path),
            )
        out.append((str(base / name) if not Path(name).is_absolute() else name, float(nom)))
    if not any(n == 0 for _, n in out):
        raise InputError(
            "no reference image: at least one row needs nominal_mm = 0 (the stage's start position)",
            source=str(path),
        )
    return out


def calibrate_files(
    paths: Sequence[str | os.PathLike],
    board: Board,
    *,
    model: str = "k3",
    outlier_factor: float = 3.0,
    scale: int | None = None,
) -> CalibrationResult:
    """Calibrate a camera from image files of a board (a folder stands for its images).

    Every image is read and searched; an unreadable image, one of another size
    or one without the board becomes a view with ``used = False`` and the
    reason, and calibration goes on with the others.

    Raises
    ------
    InputError
        When fewer than 3 views are usable (the message lists why).
    """
    if not paths:
        raise InputError("no calibration images given")
    paths = image_files(paths)
    dets: list[BoardDetection | str] = []
    sizes: list[tuple[int, int] | None] = []
    for p in paths:
        src = str(p)
        try:
            img = read_image(p)
        except InputError as e:
            dets.append(e.detail)
            sizes.append(None)
            continue
        h, w = img.shape
        sizes.append((w, h))
        try:
            dets.append(detect_board(img, board, scale=scale, source=src))
        except InputError as e:
            dets.append(e.detail)
    if all(sz is None for sz in sizes):
        raise InputError(
            f"none of the {len(paths)} images could be read: "
            + "; ".join(f"{p}: {d}" for p, d in zip(paths, dets, strict=True))
        )
    # The camera's size: that of most views where the board was found (a stray image of
    # another camera, wherever it is on the command line, is the one left out).
    found = [sz for sz, d in zip(sizes, dets, strict=True) if sz is not None and not isinstance(d, str)]
    pool = found or [sz for sz in sizes if sz is not None]
    size = max(dict.fromkeys(pool), key=pool.count)
    n_size = pool.count(size)
    for i, sz in enumerate(sizes):
        if sz is not None and sz != size:
            dets[i] = (
                f"image is {sz[0]}x{sz[1]} px, but {n_size} of the views are {size[0]}x{size[1]} px "
                "(an image of another camera?)"
            )
    return calibrate_camera(
        dets, board, size, names=[str(p) for p in paths], model=model, outlier_factor=outlier_factor
    )


def measure_files(
    paths: Sequence[str | os.PathLike],
    camera: CameraModel,
    board: Board,
    fixed_board: Board | None = None,
    fixed2base=None,
    *,
    scale: int | None = None,
    camera_source: str = "camera.json",
    refine: str = "auto",
) -> list[ImageMeasurement]:
    """Poses in each image file (tracking along the list; a folder stands for its images).

    Bad files give ``error`` entries.

    ``refine`` as in :class:`~stiffmap.vision.sequence.PoseTracker`.
    """
    return measure_sequence(
        image_files(paths),
        camera,
        board,
        fixed_board,
        fixed2base,
        scale=scale,
        camera_source=camera_source,
        refine=refine,
    )
