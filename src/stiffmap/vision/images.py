"""Reading camera images, with a clear error for every file that cannot be used.

:func:`read_image` returns an 8-bit grey image (h, w) for PNG, TIFF, BMP, JPEG,
PGM/PPM and WebP files (whatever the installed OpenCV decodes). Colour images
are converted to grey by the decoder; 16-bit images are scaled to 8 bits by
their own maximum (the corner positions do not depend on a grey-level gain).

Every failure is an :class:`ImageError` (an :class:`~stiffmap.errors.InputError`)
naming the file: missing, a directory, empty, truncated (checked from the
file's own structure for PNG and JPEG before decoding, and by the decoder for
the others), not an image or an unsupported format. :func:`check_image_size`
compares an image with the size in ``camera.json``.

:func:`check_image` is the one check of an image array handed to the vision
functions (detection, corner refinement, photometric refinement): a grey image
(h, w) of uint8 (or uint16 where the function reads 16 bits), at least 8x8 px; a
BGR uint8 image (h, w, 3) is converted to grey. :func:`coarse_scales` and
:func:`reduce_image` give the reduced images the board detectors search first.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError

__all__ = [
    "ImageError",
    "read_image",
    "check_image",
    "check_image_size",
    "coarse_scales",
    "reduce_image",
    "IMAGE_SUFFIXES",
    "COARSE_TARGET_PX",
]

#: File name endings read as images.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".pgm", ".ppm", ".pnm", ".webp")

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"IEND\xaeB`\x82"


class ImageError(InputError):
    """An image file that cannot be read (missing, truncated, not an image)."""


def _format_of(head: bytes) -> str | None:
    if head.startswith(_PNG_MAGIC):
        return "PNG"
    if head[:2] == b"\xff\xd8":
        return "JPEG"
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "TIFF"
    if head[:2] == b"BM":
        return "BMP"
    if head[:2] in (b"P2", b"P5", b"P3", b"P6"):
        return "PNM"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "WebP"
    return None


def _check_complete(fmt: str, tail: bytes, size: int, src: str) -> None:
    """Cheap structural checks (the file's last bytes) that catch truncation before decoding."""
    if fmt == "PNG" and _PNG_IEND not in tail:
        raise ImageError(f"truncated PNG file ({size} bytes; the closing IEND chunk is missing)", source=src)
    if fmt == "JPEG" and b"\xff\xd9" not in tail.rstrip(b"\x00"):
        raise ImageError(
            f"truncated JPEG file ({size} bytes; the end-of-image marker is missing)", source=src
        )


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as 8-bit grey.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    ndarray, shape (h, w), uint8

    Raises
    ------
    ImageError
        Naming the file and what is wrong: not found, a directory, empty,
        truncated, not an image, unsupported format, or undecodable.
    """
    p = Path(path)
    src = str(path)
    if not p.exists():
        raise ImageError("image file not found", source=src)
    if p.is_dir():
        raise ImageError("is a directory, expected an image file", source=src)
    try:
        size = p.stat().st_size
        with open(p, "rb") as f:
            head = f.read(16)
            f.seek(max(size - 32, 0))
            tail = f.read()
    except OSError as e:
        raise ImageError(f"cannot read: {e.strerror or e}", source=src) from None
    if size == 0:
        raise ImageError("empty file (0 bytes), expected an image", source=src)
    fmt = _format_of(head)
    if fmt is None:
        raise ImageError(
            "not an image file this tool can read (expected PNG, TIFF, BMP, JPEG, PGM or WebP)",
            source=src,
        )
    _check_complete(fmt, tail, size, src)
    flags = cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        img = cv2.imread(str(p), flags)
        if img is None:
            # imread cannot open some paths (non-ASCII names on Windows): decode from memory.
            img = cv2.imdecode(np.fromfile(p, dtype=np.uint8), flags)
    except cv2.error as e:  # pragma: no cover - OpenCV returns None rather than raising
        raise ImageError(f"cannot decode the {fmt} data: {e}", source=src) from None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None:
        raise ImageError(
            f"cannot decode the {fmt} data ({size} bytes): truncated or corrupt file, "
            "or a variant of the format this OpenCV build does not support",
            source=src,
        )
    return _as_grey8(img, src)


def _as_grey8(img: np.ndarray, src: str) -> np.ndarray:
    if img.ndim == 3:  # pragma: no cover - IMREAD_GRAYSCALE already converts
        img = cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or img.shape[0] < 2 or img.shape[1] < 2:
        raise ImageError(f"expected a 2-D image, got an array of shape {img.shape}", source=src)
    if img.dtype == np.uint8:
        return img
    if img.dtype in (np.uint16, np.int16, np.float32, np.float64):
        f = img.astype(np.float32)
        top = float(f.max()) if f.size else 0.0
        if not np.isfinite(top) or top <= 0:
            raise ImageError("image holds no positive grey levels (all black or not finite)", source=src)
        return np.clip(np.rint(f * (255.0 / top)), 0, 255).astype(np.uint8)
    raise ImageError(f"unsupported pixel type {img.dtype}", source=src)


#: Smallest image side the vision functions accept, px.
MIN_IMAGE_PX = 8


def check_image(image, *, uint16: bool = False) -> np.ndarray:
    """Check an image array handed to a vision function; return it grey and C-contiguous.

    Parameters
    ----------
    image : array_like
        Grey (h, w) of uint8 (or uint16 when ``uint16``), or BGR (h, w, 3) of uint8
        (converted to grey by OpenCV); at least 8x8 px.
    uint16 : bool
        The caller reads 16-bit grey images too (the photometric refinement does;
        OpenCV's board detectors read 8 bits only).

    Returns
    -------
    ndarray, shape (h, w), uint8 or uint16

    Raises
    ------
    ValueError
        Saying what is accepted and what came (dtype and shape).
    """
    img = np.asarray(image)
    depths = (np.uint8, np.uint16) if uint16 else (np.uint8,)
    bgr = img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    grey_ok = img.ndim == 2 and img.dtype in depths
    if not (grey_ok or bgr) or min(img.shape[:2]) < MIN_IMAGE_PX:
        grey = " or ".join(np.dtype(d).name for d in depths)
        raise ValueError(
            f"image must be a 2-D grey {grey} array (h, w) or a BGR uint8 array (h, w, 3), "
            f"at least {MIN_IMAGE_PX}x{MIN_IMAGE_PX} px; got {img.dtype} {img.shape}"
        )
    if bgr:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(img)


def check_image_size(
    image: np.ndarray,
    image_size: tuple[int, int],
    *,
    source: str | None = None,
    camera_source: str = "camera.json",
) -> None:
    """Check that an image has the size the camera was calibrated at.

    Parameters
    ----------
    image : ndarray, shape (h, w)
    image_size : (int, int)
        [w, h] from ``camera.json``.
    source : str, optional
        The image's file name, for the message.
    camera_source : str
        The camera file's name, for the message.

    Raises
    ------
    InputError
        Naming the image, its size and the camera's size.
    """
    h, w = image.shape[:2]
    cw, ch = (int(v) for v in image_size)
    if (w, h) != (cw, ch):
        raise InputError(
            f"image is {w}x{h} px but {camera_source} was calibrated at {cw}x{ch} px "
            "(wrong camera file, or a resized/cropped image)",
            source=source,
        )


#: Longest side of the reduced image used for the coarse search, px.
COARSE_TARGET_PX = 900


def coarse_scales(shape: tuple[int, int], scale: int | None) -> list[int]:
    """Reduction factors to search at, coarsest first: ``scale`` (default about
    :data:`COARSE_TARGET_PX` on the longest side), then finer ones down to 1."""
    if scale is not None:
        s = int(scale)
        if s < 1:
            raise ValueError(f"scale must be an integer >= 1, got {scale}")
    else:
        s = max(1, int(round(max(shape) / COARSE_TARGET_PX)))
    out = [s]
    while s > 1:
        s = max(1, s // 2) if s > 3 else 1
        out.append(s)
    return out


def reduce_image(image: np.ndarray, s: int) -> np.ndarray:
    """The image reduced by the integer factor ``s`` (area averaging; a copy for s = 1)."""
    if s == 1:
        return image.copy()
    h, w = image.shape
    return cv2.resize(image, (w // s, h // s), interpolation=cv2.INTER_AREA)
