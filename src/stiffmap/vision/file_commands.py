"""The pose and displacement of a board in image files, with one camera or a rig of several.

:func:`pose_files` and :func:`displacement_files` are what ``stiffmap pose`` and ``stiffmap
displacement`` compute, as functions: the images are named as on the command line (files,
folders, quoted patterns; with a rig, image sets named with ``{camera}`` or one camera's
images as ``NAME=GLOB``) and measured as one tracked sequence, so that a symmetric board
keeps its numbering from the references on.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..rig import Rig, parse_named_pattern
from .board_size import check_board_size
from .detect import Board
from .displacement import ImageDisplacements, displacement_per_image
from .files import (
    StageRow,
    image_files,
    measure_files,
    measure_image_sets,
    read_stage_manifest,
    rig_image_sets,
)
from .sequence import ImageMeasurement
from .validate import StageValidation, validate_stage_series

__all__ = [
    "FixedTarget",
    "ManifestValidation",
    "image_sets",
    "measure_named",
    "pose_files",
    "displacement_files",
    "validate_files",
]


@dataclass(frozen=True)
class FixedTarget:
    """The target fixed to the robot base and its pose there.

    Attributes
    ----------
    board : Board
    fixed2base : ndarray, shape (4, 4)
        The fixed target's frame in the robot base frame, mm.
    """

    board: Board
    fixed2base: np.ndarray


def image_sets(
    images: Sequence[str | os.PathLike],
    per_camera: Sequence[str],
    rig: Rig | None,
    what: str = "image",
) -> list:
    """The images of one camera (paths), or a rig's image sets ``(label, {camera: path})``.

    Parameters
    ----------
    images : sequence of str or path-like
        Files, folders or quoted patterns; with a rig, image sets named with ``{camera}``.
    per_camera : sequence of str
        With a rig only: ``NAME=GLOB``, one camera's images (matched across cameras by the
        number in their names, :func:`~stiffmap.vision.files.rig_image_sets`).
    rig : Rig or None
        None for one camera.
    what : str
        How the images are named in messages.

    Raises
    ------
    InputError
        ``NAME=GLOB`` or a name holding ``{camera}`` without a rig, and every error of
        :func:`~stiffmap.vision.files.rig_image_sets`.
    """
    if rig is not None:
        return rig_image_sets(rig, images, per_camera, what=what)
    if per_camera:
        raise InputError("--images NAME=GLOB goes with --rig (one camera's images in a rig)")
    templated = [i for i in images if "{camera}" in str(i)]
    if templated:
        raise InputError(f"{templated[0]!r}: an image name holding {{camera}} needs --rig rig.json")
    return [Path(i) for i in images]


def measure_named(
    items: list,
    cameras: CameraModel | Rig,
    board: Board,
    fixed: FixedTarget | None = None,
    *,
    refine: str = "auto",
    source: str = "camera.json",
) -> list[ImageMeasurement]:
    """Measure the images of one camera, or a rig's image sets, as one tracked sequence.

    ``items`` as :func:`image_sets` gives them; ``source`` names the camera or rig file in
    messages. An image (set) that fails gives an entry with its error. A board size the images
    do not show is refused first (:func:`~stiffmap.vision.board_size.check_board_size`).
    """
    if not items:
        raise InputError("no images given")
    fb, T = (fixed.board, fixed.fixed2base) if fixed is not None else (None, None)
    _check_sizes(items, board, fb)
    if isinstance(cameras, Rig):
        return measure_image_sets(items, cameras, board, fb, T, rig_source=source, refine=refine)
    return measure_files(items, cameras, board, fb, T, camera_source=source, refine=refine)


def _check_sizes(items: list, board: Board, fixed_board: Board | None) -> None:
    """Refuse a board size (the mobile's, the fixed one's) that a few of the images do not show."""
    if isinstance(items[0], tuple):  # a rig's image sets
        paths = [p for _, views in items for p in views.values() if p is not None]
    else:
        paths = image_files(items)
    check_board_size(paths, board, others=[fixed_board])
    if fixed_board is not None:
        check_board_size(paths, fixed_board, others=[board], what="--fixed-board")


def pose_files(
    images: Sequence[str | os.PathLike],
    cameras: CameraModel | Rig,
    board: Board,
    *,
    per_camera: Sequence[str] = (),
    refine: str = "auto",
    source: str = "camera.json",
) -> list[ImageMeasurement]:
    """The pose of the board in each image (with a rig: each image set, fused in the rig frame).

    Parameters
    ----------
    images : sequence of str or path-like
        As :func:`image_sets`.
    cameras : CameraModel or Rig
    board : Board
    per_camera : sequence of str
        With a rig: ``NAME=GLOB`` per camera.
    refine : {"auto", "photometric", "corners"}
    source : str
        The camera or rig file, named in messages.

    Returns
    -------
    list of ImageMeasurement
        One per image (set); ``mobile`` holds the board's pose (board2cam, or with a rig
        board2rig), ``error`` why there is none.
    """
    rig = cameras if isinstance(cameras, Rig) else None
    items = image_sets(images, per_camera, rig)
    return measure_named(items, cameras, board, refine=refine, source=source)


def _reference_items(reference: Sequence[str], rig: Rig | None) -> tuple[list[str], list[str]]:
    """The references as (image sets, ``NAME=GLOB`` of one camera of the rig)."""
    if rig is None:
        return list(reference), []
    per_camera = []
    for r in reference:
        try:
            name, _ = parse_named_pattern(r)
        except ValueError:
            continue
        if name in rig.names:
            per_camera.append(r)
    return [r for r in reference if r not in per_camera], per_camera


def displacement_files(
    references: Sequence[str],
    images: Sequence[str],
    cameras: CameraModel | Rig,
    board: Board,
    *,
    per_camera: Sequence[str] = (),
    fixed: FixedTarget | None = None,
    point=None,
    refine: str = "auto",
    source: str = "camera.json",
) -> ImageDisplacements:
    """The displacement of the target in each image relative to the mean of the references.

    The references and the images are measured as one tracked sequence (a symmetric board
    keeps its numbering from the references on), then compared with
    :func:`~stiffmap.vision.displacement.displacement_per_image`: in the camera frame (with a
    rig, the rig frame), or the robot base frame with a fixed target.

    Parameters
    ----------
    references : sequence of str
        Reference (unloaded) images, averaged; with a rig, image sets named with
        ``{camera}`` or ``NAME=GLOB`` for one camera (a name of the rig before ``=``).
    images : sequence of str
        Images after the load (or any moved state), as :func:`image_sets`.
    cameras : CameraModel or Rig
    board : Board
        The mobile target.
    per_camera : sequence of str
        With a rig: ``NAME=GLOB`` per camera, the images after the load.
    fixed : FixedTarget, optional
        The target on the base, for displacements in the base frame.
    point : array_like, shape (3,), optional
        Point of the mobile target (its frame, mm) whose displacement this is.
    refine : {"auto", "photometric", "corners"}
    source : str
        The camera or rig file, named in messages.

    Returns
    -------
    ImageDisplacements
        Its ``references`` and ``images`` hold every measurement, failed ones included.

    Raises
    ------
    InputError
        No reference or no image given, none of the references measured, and the errors
        of :func:`image_sets`.
    """
    rig = cameras if isinstance(cameras, Rig) else None
    ref_sets, ref_cams = _reference_items(references, rig)
    refs = image_sets(ref_sets, ref_cams, rig, what="--reference")
    moved = image_sets(images, per_camera, rig)
    if not refs or not moved:
        raise InputError(
            "give the reference (unloaded) images with --reference and the images to compare with "
            "them" + (" (names holding {camera}, or --images NAME=GLOB)" if rig is not None else "")
        )
    ms = measure_named(refs + moved, cameras, board, fixed, refine=refine, source=source)
    q = None if point is None else np.asarray(point, dtype=float)
    try:
        return displacement_per_image(ms[: len(refs)], ms[len(refs) :], q)
    except InputError as e:
        # Say why: the references' own errors (a command prints no warning before it fails).
        why = "; ".join(m.error for m in ms[: len(refs)] if m.error)
        raise InputError(f"{e}: {why}" if why else str(e)) from None


@dataclass(frozen=True)
class ManifestValidation:
    """What :func:`validate_files` gives: the manifest's rows, their measurements, the validation.

    Attributes
    ----------
    rows : tuple of StageRow
        The manifest's rows (image, nominal displacement in mm, line), in its order.
    measurements : tuple of ImageMeasurement
        One per row, failed ones included.
    validation : StageValidation
    """

    rows: tuple[StageRow, ...]
    measurements: tuple[ImageMeasurement, ...]
    validation: StageValidation


def validate_files(
    manifest: str | os.PathLike,
    camera: CameraModel,
    board: Board,
    *,
    refine: str = "auto",
    allow_outside: bool = False,
    source: str = "camera.json",
) -> ManifestValidation:
    """Validate against a stage manifest's known displacements (the reference study's X-table test).

    Parameters
    ----------
    manifest : str or path-like
        CSV with columns ``image`` and ``nominal_mm`` (:func:`~stiffmap.vision.files.read_stage_manifest`).
    camera : CameraModel
    board : Board
    refine : {"auto", "photometric", "corners"}
    allow_outside : bool
        Read images the manifest lists outside its own folder.
    source : str
        The camera file, named in messages.

    Raises
    ------
    InputError
        Naming the manifest: its rows, or too few images measured at a step (then the failed
        images' errors are in the message, with their lines).
    """
    rows = read_stage_manifest(manifest, allow_outside=allow_outside)
    ms = measure_files([r.image for r in rows], camera, board, camera_source=source, refine=refine)
    try:
        res = validate_stage_series(ms, [r.nominal_mm for r in rows])
    except InputError as e:
        why = "; ".join(f"line {r.line}: {m.error}" for m, r in zip(ms, rows, strict=True) if m.error)
        # the images' errors once, each with its line (the library's message lists them without)
        what = str(e).split(": ", 1)[0] + f": {why}" if why else str(e)
        raise InputError(what, source=str(manifest)) from None
    return ManifestValidation(tuple(rows), tuple(ms), res)
