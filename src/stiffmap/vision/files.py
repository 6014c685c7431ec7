"""File-level entry points of the vision path (the CLI and the campaign runner call these).

The numerical modules take arrays; this module reads files: the transform of
the fixed target on the base (a 4x4 in JSON), the stage-validation manifest (a
CSV), and it runs calibration and pose measurement over lists of image files,
turning each bad file into a recorded error while the others go on.
"""

from __future__ import annotations

import csv
import glob
import os
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..camera import CameraModel
from ..errors import InputError
from ..geometry import as_transform
from ..io import read_csv_columns, read_json
from ..rig import Rig, parse_named_pattern
from ..targets import as_board
from .board_size import check_board_size
from .calibrate import CalibrationResult, calibrate_camera
from .detect import Board, BoardDetection, DetectionError, detect_board
from .detection import grid_of
from .images import read_image
from .rig_calibration import RigCalibrationResult, calibrate_rig
from .sequence import ImageMeasurement, measure_sequence

__all__ = [
    "IMAGE_SUFFIXES",
    "image_files",
    "read_transform",
    "read_stage_manifest",
    "StageRow",
    "board_size_hint",
    "calibrate_files",
    "calibrate_rig_files",
    "WRONG_SIZE_AFTER",
    "camera_images",
    "match_views",
    "measure_files",
    "rig_image_sets",
    "measure_image_sets",
]

#: Largest translation of a transform read from a file, mm (a robot cell is metres wide).
MAX_TRANSLATION_MM = 1e6

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
            subs = sorted((q.name for q in p.iterdir() if q.is_dir()), key=str.lower)
            hint = (
                f"; its sub-folders ({', '.join(subs[:5])}{' ...' if len(subs) > 5 else ''}) are not "
                "searched: give the one of the camera to calibrate"
                if subs
                else ""
            )
            raise InputError(
                "the folder holds no image files (looked for " + ", ".join(IMAGE_SUFFIXES) + ")" + hint,
                source=str(p),
            )
        out.extend(found)
    return out


def read_transform(path: str | os.PathLike, key: str = "fixed2base") -> np.ndarray:
    """Read a rigid transform (4x4, mm) from a JSON file.

    The file holds either the matrix itself (a list of 4 rows of 4 numbers) or
    an object with the matrix under ``key`` (or ``"matrix"``). The rotation block may be
    rounded (orthonormal to 1e-4); it is returned re-orthonormalised, exactly rigid. A
    translation beyond :data:`MAX_TRANSLATION_MM` (a kilometre) is refused.

    Raises
    ------
    InputError
        Naming the file and what is wrong (missing, not JSON, not 4x4, not numbers, not
        rigid, a translation of more than a kilometre).
    """
    src = str(path)
    data = read_json(path, "transform file")
    if isinstance(data, dict):
        for k in (key, "matrix"):
            if k in data:
                data = data[k]
                where = f"key {k!r}: "
                break
        else:
            raise InputError(f"expected a 4x4 matrix or an object with key {key!r}", source=src)
    else:
        where = ""
    rows = data if isinstance(data, list) else None
    if rows is None or len(rows) != 4 or not all(isinstance(r, list) and len(r) == 4 for r in rows):
        shape = f"{len(rows)} rows" if rows is not None else type(data).__name__
        raise InputError(f"{where}expected a 4x4 matrix (4 rows of 4 numbers, mm), got {shape}", source=src)
    T = np.empty((4, 4))
    for i, r in enumerate(rows):
        for j, v in enumerate(r):
            x = _finite_number(v)
            if x is None:
                raise InputError(
                    f"{where}row {i + 1}, column {j + 1}: expected a finite number, got {_short(v)}",
                    source=src,
                )
            T[i, j] = x
    big = float(np.abs(T[:3, :3]).max())
    if big > 1 + 1e-4:  # checked first: R^T R of such entries overflows
        raise InputError(
            f"{where}not a rigid transform: the 3x3 rotation block holds {big:.3g}, a rotation's "
            "entries lie within [-1, 1] (a scaled matrix, or the translation in the wrong column?)",
            source=src,
        )
    try:
        as_transform(T, key, atol=1e-4)
    except ValueError as e:
        raise InputError(f"{where}not a rigid transform: {e}", source=src) from None
    t = float(np.abs(T[:3, 3]).max())
    if t > MAX_TRANSLATION_MM:
        raise InputError(
            f"{where}a translation of {t:.3g} mm is not a pose in a robot cell (at most "
            f"{MAX_TRANSLATION_MM:g} mm; the transform is in mm)",
            source=src,
        )
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T[:3, :3] = U @ Vt
    return T


def _finite_number(v) -> float | None:
    """A JSON number as a finite float (not a bool), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        x = float(v)
    except OverflowError:
        return None
    return x if np.isfinite(x) else None


def _short(v, n: int = 40) -> str:
    try:
        text = repr(v)
    except ValueError:  # an integer too long for repr
        return "an integer of thousands of digits"
    return text if len(text) <= n else text[: n - 3] + "..."


class StageRow(NamedTuple):
    """One row of a stage manifest: the image's path, its stage displacement (mm), its line."""

    image: str
    nominal_mm: float
    line: int


def read_stage_manifest(path: str | os.PathLike, *, allow_outside: bool = False) -> list[StageRow]:
    """Read a stage-validation manifest: CSV columns ``image`` and ``nominal_mm``.

    Image paths are relative to the manifest's directory and must stay inside it (no
    absolute path, no ``..`` out of it) unless ``allow_outside`` (``--allow-outside-paths``); rows with
    ``nominal_mm = 0`` are the reference (start) position. A nominal displacement is
    finite, >= 0 and at most :data:`MAX_TRANSLATION_MM`.

    Returns
    -------
    list of StageRow
        (image path, nominal displacement in mm, line in the file), in the file's order.

    Raises
    ------
    InputError
        Naming the file, the line and the column.
    """
    src = str(path)
    try:
        t = read_csv_columns(path, ["image", "nominal_mm"], text_columns=["image"])
    except csv.Error as e:  # a field of hundreds of kB: not a manifest
        raise InputError(f"not a readable CSV table ({e})", source=src) from None
    base = Path(path).parent
    out = []
    for name, nom, line in zip(t.text["image"], t.columns["nominal_mm"], t.lines, strict=True):
        if not name:
            raise InputError(f"line {line}, column 'image': empty image name", source=src)
        if not np.isfinite(nom) or nom < 0 or nom > MAX_TRANSLATION_MM:
            raise InputError(
                f"line {line}, column 'nominal_mm': {nom:g} is not a stage displacement; give the "
                f"distance moved from the start position (0 to {MAX_TRANSLATION_MM:g} mm)",
                source=src,
            )
        image = base / name
        if not allow_outside and not _inside(image, base):
            raise InputError(
                f"line {line}, column 'image': {name!r} is outside the manifest's folder {str(base)!r}; "
                "list images inside it, or pass --allow-outside-paths to read them from elsewhere",
                source=src,
            )
        if image.is_dir():
            raise InputError(
                f"line {line}, column 'image': {name!r} is a folder, expected an image file", source=src
            )
        out.append(StageRow(str(image) if not Path(name).is_absolute() else name, float(nom), int(line)))
    if not any(r.nominal_mm == 0 for r in out):
        raise InputError(
            "no reference image: at least one row needs nominal_mm = 0 (the stage's start position)",
            source=src,
        )
    return out


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` (absolute, or relative to the working directory) lies in ``folder``."""
    try:
        return Path(os.path.abspath(path)).is_relative_to(os.path.abspath(folder))
    except (OSError, ValueError):
        return False


def calibrate_files(
    paths: Sequence[str | os.PathLike],
    board: Board,
    *,
    model: str = "k3",
    outlier_factor: float = 3.0,
    scale: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    square_mm: float | None = None,
) -> CalibrationResult:
    """Calibrate a camera from image files of a board (a folder stands for its images).

    Every image is read and searched; an unreadable image, one of another size
    or one without the board becomes a view with ``used = False`` and the
    reason, and calibration goes on with the others. ``progress(done, total)`` is called
    after each image.

    A wrong board size is answered first, in seconds, with the size the images show
    (:func:`~stiffmap.vision.board_size.check_board_size` on a few of them); failing that,
    when :data:`WRONG_SIZE_AFTER` images show one larger printed board (whole) and none so
    far the board asked for, the search stops with it.

    Raises
    ------
    InputError
        When fewer than 3 views are usable (the message groups the images by reason and
        names the board size the images show, if they agree on one), or early, on a wrong
        board size.
    """
    board = as_board(board, square_mm, "board")
    if not paths:
        raise InputError("no calibration images given")
    paths = image_files(paths)
    check_board_size(paths, board, progress=progress)
    dets, sizes, larger = _detect_files(paths, board, scale, _counting(progress, len(paths)), early=True)
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
    if len(found) < 3:
        hint = board_size_hint(larger, board, len(paths))
        if hint is not None:
            raise InputError(hint)
    return calibrate_camera(
        dets, board, size, names=[str(p) for p in paths], model=model, outlier_factor=outlier_factor
    )


#: Images showing one larger printed board (whole), with none yet showing the board asked for,
#: after which :func:`calibrate_files` stops and names the size the images show.
WRONG_SIZE_AFTER = 3


def board_size_hint(larger: Sequence, board: Board, n_images: int, done: int | None = None) -> str | None:
    """One sentence naming the board size the images show, when they agree on one; else None.

    Parameters
    ----------
    larger : sequence of LargerBoard or None
        Per image searched, the larger printed board it showed (``DetectionError.larger``).
    board : Chessboard or CharucoBoard
        The board asked for.
    n_images : int
        Images given.
    done : int, optional
        Images searched so far (default all).
    """
    whole = [lb.size for lb in larger if lb is not None and lb.whole]
    if not whole:
        return None
    best = max(dict.fromkeys(whole), key=whole.count)
    cb = grid_of(board)
    searched = n_images if done is None else done
    where = f"{whole.count(best)} of the {searched} images searched" + (
        f" (of {n_images})" if searched < n_images else ""
    )
    return (
        f"no image shows a {cb.cols}x{cb.rows} chessboard (inner corners), but {where} show a "
        f"{best} chessboard: did you mean --board {best}?"
    )


def _counting(progress: Callable[[int, int], None] | None, total: int) -> Callable[[], None] | None:
    """A per-image tick that reports (done, total) to ``progress``."""
    if progress is None:
        return None
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        progress(done, total)

    return tick


def _detect_files(
    paths: Sequence[Path],
    board: Board,
    scale: int | None,
    progress: Callable[[], None] | None = None,
    early: bool = False,
) -> tuple[list[BoardDetection | str], list[tuple[int, int] | None], list]:
    """Read each image and find the board: its detection or why not, its size (None: unreadable),
    and the larger printed board it showed instead (None when not).

    ``early``: stop with an :class:`InputError` naming the size as soon as
    :data:`WRONG_SIZE_AFTER` images agree on one larger board and none showed ``board``.
    """
    dets: list[BoardDetection | str] = []
    sizes: list[tuple[int, int] | None] = []
    larger: list = []
    for p in paths:
        src = str(p)
        big = None
        try:
            img = read_image(p)
        except InputError as e:
            dets.append(e.detail)
            sizes.append(None)
        else:
            h, w = img.shape
            sizes.append((w, h))
            try:
                dets.append(detect_board(img, board, scale=scale, source=src))
            except DetectionError as e:
                dets.append(e.detail)
                big = e.larger
            except InputError as e:
                dets.append(e.detail)
        larger.append(big)
        if progress is not None:
            progress()
        if early and not any(isinstance(d, BoardDetection) for d in dets):
            whole = [lb.size for lb in larger if lb is not None and lb.whole]
            if whole and max(whole.count(x) for x in whole) >= WRONG_SIZE_AFTER:
                raise InputError(board_size_hint(larger, board, len(paths), len(dets)))
    return dets, sizes, larger


_GLOB_CHARS = re.compile(r"[*?\[]")


def camera_images(name: str, pattern: str | os.PathLike) -> list[Path]:
    """The image files of one camera of a rig: a file pattern (``img/left*.jpg``), a folder or a file.

    A pattern gives the files it matches, a folder its images (:func:`image_files`), in
    natural order (``left2`` before ``left10``).

    Raises
    ------
    InputError
        Naming the camera and the pattern that matches no file.
    """
    text = str(pattern)
    if not text.strip():
        raise InputError(
            f"camera {name}: empty file pattern (give a pattern such as 'img/{name}*.png' or a folder)"
        )
    files, several = _named_files(text)
    if several and not files:
        raise InputError(f"camera {name}: no file matches the pattern {text!r}")
    if not several and not files[0].is_file():
        raise InputError(f"camera {name}: {text!r} is no file, folder or file pattern that matches anything")
    return files


def _named_files(text: str) -> tuple[list[Path], bool]:
    """The files ``text`` names and whether it names several: a file pattern (its matches, maybe
    none), a folder (its images, :func:`image_files`), or one file (which may not exist);
    natural order (``left2`` before ``left10``)."""
    p = Path(text)
    if _GLOB_CHARS.search(text):
        found = (Path(f) for f in glob.glob(text) if Path(f).is_file())
        return sorted(found, key=lambda f: (_natural_key(f), str(f))), True
    if p.is_dir():
        return image_files([p]), True
    return [p], False


def _view_number(path: Path) -> int | None:
    """The last group of digits in a file's name (without its suffix), or None."""
    groups = re.findall(r"\d+", path.stem)
    return int(groups[-1]) if groups else None


def match_views(
    names: Sequence[str], files: Sequence[Sequence[Path]]
) -> tuple[list[str], list[list[Path | None]]]:
    """Match the images of several cameras into views (one pose of the board each).

    By the number in their file names (the group of digits that tells a camera's files apart,
    :func:`_view_numbers`: ``left07.jpg`` with ``right07.jpg`` or ``img07_cam2.jpg``) when every
    camera's files carry one and no camera has two files of one number;
    a view missing for a camera is then simply not seen by it. Otherwise by sorted order,
    when the cameras have as many images each.

    Parameters
    ----------
    names : sequence of str
        The cameras' names.
    files : sequence of sequence of Path
        Each camera's images, in natural order.

    Returns
    -------
    view_names : list of str
        The views' numbers (or positions, ``"1"``...), in order.
    table : list of list of Path or None
        ``table[k][v]``: camera k's image of view v (None: it has none).

    Raises
    ------
    InputError
        When neither rule applies (naming the cameras, their numbers of images, and the
        file that has no number or shares it).
    """
    numbers = [_view_numbers(list(fs)) for fs in files]
    problem = None
    for name, fs, ns in zip(names, files, numbers, strict=True):
        if ns is not None or not fs:
            continue
        ns = [_view_number(f) for f in fs]  # why the camera's files carry no view number
        problem = f"the names of camera {name}'s images carry no view number that tells them apart"
        for f, n in zip(fs, ns, strict=True):
            if n is None:
                problem = f"{f} (camera {name}) has no number in its name"
                break
            if ns.count(n) > 1:
                other = next(g for g, m in zip(fs, ns, strict=True) if m == n and g != f)
                problem = f"{f} and {other} (camera {name}) carry the same number {n}"
                break
        if problem:
            break
    if problem is None:
        numbers = [ns or [] for ns in numbers]
        views = sorted(set().union(*map(set, numbers)))
        table = [
            [dict(zip(ns, fs, strict=True)).get(n) for n in views]
            for fs, ns in zip(files, numbers, strict=True)
        ]
        return [str(n) for n in views], table
    counts = [len(fs) for fs in files]
    if len(set(counts)) == 1:
        return [str(i + 1) for i in range(counts[0])], [list(fs) for fs in files]
    raise InputError(
        "cannot match the images into views: "
        + problem
        + ", and the cameras have different numbers of images ("
        + ", ".join(f"{n}: {c}" for n, c in zip(names, counts, strict=True))
        + "); give the images of one view the same number (left07.png, right07.png), or as many "
        "images per camera in the same order"
    )


def _camera_names(cameras) -> list[str]:
    """The cameras' names, checked: at least one camera, no outer spaces, none given twice."""
    if not cameras:
        raise InputError("no cameras given")
    names = [str(n) for n, _ in cameras]
    for n in names:
        if not n.strip() or n != n.strip():
            raise InputError(f"camera name {n!r}: a camera needs a name without outer spaces")
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise InputError(f"camera {dup} is given twice: cameras need different names")
    return names


def _camera_detections(name: str, row: list, board: Board, scale: int | None, tick):
    """One camera's detections in each view (None where it has no image) and its image size;
    refused when none of its images could be read or they differ in size."""
    paths = [p for p in row if p is not None]
    d, sz, _ = _detect_files(paths, board, scale, tick, early=True)
    seen = [s for s in sz if s is not None]
    if not seen:
        raise InputError(
            f"camera {name}: none of its {len(paths)} images could be read: "
            + "; ".join(f"{p}: {x}" for p, x in zip(paths, d, strict=True))
        )
    if len(set(seen)) > 1:
        common = max(dict.fromkeys(seen), key=seen.count)
        odd = next(p for p, s in zip(paths, sz, strict=True) if s is not None and s != common)
        w, h = next(s for s in sz if s is not None and s != common)
        raise InputError(
            f"camera {name}: its images are not all of one size: {odd} is {w}x{h} px, "
            f"{seen.count(common)} others are {common[0]}x{common[1]} px (an image of another camera?)"
        )
    it = iter(d)
    return [None if p is None else next(it) for p in row], seen[0]


def calibrate_rig_files(
    cameras: Sequence[tuple[str, str | os.PathLike]],
    board: Board,
    *,
    model: str = "k3",
    outlier_factor: float = 3.0,
    scale: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    square_mm: float | None = None,
) -> RigCalibrationResult:
    """Calibrate a rig of cameras from their image files of one board (see :func:`calibrate_rig`).

    Parameters
    ----------
    cameras : sequence of (str, str or PathLike)
        Each camera's name and its images: a file pattern (``img/left*.jpg``), a folder, or
        one file. The first camera's frame is the rig frame.
    board : Chessboard or CharucoBoard
        Or a chessboard's size ``"COLSxROWS"`` with ``square_mm`` (:func:`~stiffmap.targets.as_board`).
    model, outlier_factor
        As in :func:`~stiffmap.vision.rig_calibration.calibrate_rig`.
    scale : int, optional
        Detection's reduction factor (as :func:`calibrate_files`).
    progress : callable, optional
        ``progress(done, total)`` after each image read and searched.

    Returns
    -------
    RigCalibrationResult

    Notes
    -----
    The views are matched across cameras by :func:`match_views`. Every image is read and
    searched as :func:`calibrate_files` does; an unreadable image or one without the board
    is a view that camera does not have (with the reason), and calibration goes on.

    Raises
    ------
    InputError
        No camera, two cameras of one name, a pattern that matches nothing, images that
        cannot be matched into views, a camera whose images differ in size, a camera with
        fewer than 3 usable views or fewer than 2 shared with the others.
    """
    board = as_board(board, square_mm, "board")
    names = _camera_names(cameras)
    files = [camera_images(n, pat) for n, pat in cameras]
    view_names, table = match_views(names, files)
    check_board_size([p for fs in files for p in fs], board, progress=progress)
    total = sum(len(fs) for fs in files)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    dets: list[list[BoardDetection | str | None]] = []
    sizes: list[tuple[int, int]] = []
    for name, row in zip(names, table, strict=True):
        d, size = _camera_detections(name, row, board, scale, tick)
        sizes.append(size)
        dets.append(d)
    return calibrate_rig(
        dets,
        board,
        sizes,
        camera_names=names,
        view_names=view_names,
        image_names=[[None if p is None else str(p) for p in row] for row in table],
        model=model,
        outlier_factor=outlier_factor,
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
    square_mm: float | None = None,
    fixed_square_mm: float | None = None,
) -> list[ImageMeasurement]:
    """Poses in each image file (tracking along the list; a folder stands for its images).

    Bad files give ``error`` entries.

    ``refine`` as in :class:`~stiffmap.vision.sequence.PoseTracker`.
    """
    board = as_board(board, square_mm, "board")
    fixed_board = None if fixed_board is None else as_board(fixed_board, fixed_square_mm, "fixed_board")
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


# ------------------------------------------------------------------ several cameras


def _view_numbers(paths: Sequence[Path]) -> list[int] | None:
    """The number that tells a camera's views apart, one per file (None: no such number).

    The digit runs of each file's stem are compared across the camera's files: the one
    position where they differ is the view number (``left07.png``, ``cam1_07.png``,
    ``img07_cam1.png`` all give 7); a single file gives its last digit run. None when the
    files' names carry no such distinct number.
    """
    runs = [re.findall(r"\d+", p.stem) for p in paths]
    if not runs or any(not r for r in runs):
        return None
    if len(paths) == 1:
        return [int(runs[0][-1])]
    if len({len(r) for r in runs}) != 1:
        nums = [int(r[-1]) for r in runs]
    else:
        varying = [i for i in range(len(runs[0])) if len({r[i] for r in runs}) > 1]
        if len(varying) != 1:
            return None
        nums = [int(r[varying[0]]) for r in runs]
    return nums if len(set(nums)) == len(nums) else None


def _camera_files(text: str, camera: str, what: str) -> tuple[list[Path], bool]:
    """A camera's files named by ``text``: a pattern, a folder or a file (kept when missing).

    Returns the paths and whether ``text`` named several (a pattern or a folder).
    """
    try:
        files, several = _named_files(text)
    except InputError as e:  # a folder without images
        raise InputError(f"{what} {text!r} (camera {camera!r}): {e}") from None
    if several and not files:
        raise InputError(f"{what} {text!r} (camera {camera!r}) matches no file")
    return files, several


def _set_label(views: Mapping[str, Path | None]) -> str:
    return " + ".join(str(p) if p is not None else f"({c}: none)" for c, p in views.items())


def rig_image_sets(
    rig: Rig,
    patterns: Sequence[str] = (),
    per_camera: Sequence[str] = (),
    *,
    what: str = "image",
) -> list[tuple[str, dict[str, Path | None]]]:
    """The image sets named on a command line for a rig: one image per camera in each set.

    Parameters
    ----------
    rig : Rig
    patterns : sequence of str
        Names holding ``{camera}``, replaced by each camera's name: a file (one set, labelled by
        the pattern: ``shots/{camera}_07.png``), or a file pattern or a folder per camera (its
        files matched into sets by :func:`match_views`). Without ``{camera}``, for a rig of one
        camera only: that camera's file, pattern or folder.
    per_camera : sequence of str
        ``NAME=GLOB`` items (a camera's file pattern, folder or file; several items for one
        camera add up); every camera of the rig needs one; matched by :func:`match_views`.
    what : str
        The option's name in messages.

    Returns
    -------
    list of (label, dict camera name -> Path or None)
        A missing file stays in its set (its camera's view will say so); a camera without an
        image in a matched set has None.

    Raises
    ------
    InputError
        Naming the item: ``{camera}`` missing for a rig of several cameras, an unknown camera,
        a pattern that matches nothing, a camera without images, sets that cannot be matched.
    """
    names = rig.names
    out: list[tuple[str, dict[str, Path | None]]] = []
    for text in patterns:
        text = str(text)
        if "{camera}" not in text:
            if len(rig) > 1:
                raise InputError(
                    f"{what} {text!r}: with a rig of {len(rig)} cameras ({', '.join(names)}), name each "
                    "image set by a pattern holding {camera} (e.g. 'shots/{camera}_07.png'), or give "
                    "each camera's images with --images NAME=GLOB"
                )
            files, several = _camera_files(text, names[0], what)
            out += [(str(f), {names[0]: f}) for f in files]
            continue
        expanded = {c: _camera_files(text.replace("{camera}", c), c, what) for c in names}
        if not any(several for _, several in expanded.values()):
            out.append((text, {c: files[0] for c, (files, _) in expanded.items()}))
            continue
        for views in _sets_of(names, [expanded[c][0] for c in names]):
            out.append((_set_label(views), views))
    if per_camera:
        given: dict[str, list[Path]] = {}
        for item in per_camera:
            try:
                name, text = parse_named_pattern(item)
            except ValueError as e:
                raise InputError(f"--images {item!r}: {e} (a camera of the rig, then its images)") from None
            if name not in names:
                raise InputError(
                    f"--images {item!r}: no camera {name!r} in the rig (cameras: {', '.join(names)})"
                )
            given.setdefault(name, []).extend(_camera_files(text, name, "--images")[0])
        lacking = [c for c in names if c not in given]
        if lacking:
            raise InputError(
                f"--images: no images given for camera(s) {', '.join(map(repr, lacking))} (the rig's "
                f"cameras: {', '.join(names)}); give --images NAME=GLOB for each"
            )
        for views in _sets_of(names, [given[c] for c in names]):
            out.append((_set_label(views), views))
    return out


def _sets_of(names: Sequence[str], files: Sequence[Sequence[Path]]) -> list[dict[str, Path | None]]:
    """:func:`match_views` as one mapping camera name -> image (or None) per view."""
    _, table = match_views(names, files)
    return [{c: table[k][v] for k, c in enumerate(names)} for v in range(len(table[0]) if table else 0)]


def measure_image_sets(
    sets: Sequence[tuple[str, Mapping[str, str | os.PathLike | None]]],
    rig: Rig,
    board: Board,
    fixed_board: Board | None = None,
    fixed2base=None,
    *,
    scale: int | None = None,
    rig_source: str = "rig.json",
    refine: str = "auto",
    square_mm: float | None = None,
    fixed_square_mm: float | None = None,
) -> list[ImageMeasurement]:
    """Fused poses in each image set of a rig (tracking along the list in every camera).

    ``sets`` as :func:`rig_image_sets` gives them; a camera's missing, unreadable or
    wrong-sized image is named in its view and the others go on; a set where no camera saw a
    target gives an ``error`` entry (:class:`~stiffmap.vision.sequence.PoseTracker`).
    """
    board = as_board(board, square_mm, "board")
    fixed_board = None if fixed_board is None else as_board(fixed_board, fixed_square_mm, "fixed_board")
    return measure_sequence(
        [dict(views) for _, views in sets],
        rig,
        board,
        fixed_board,
        fixed2base,
        names=[label for label, _ in sets],
        scale=scale,
        camera_source=rig_source,
        refine=refine,
    )
