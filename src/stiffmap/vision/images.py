"""Reading camera images, with a clear error for every file that cannot be used.

:func:`read_image` returns an 8-bit grey image (h, w) for PNG, TIFF, BMP, JPEG,
PGM/PPM and WebP files (whatever the installed OpenCV decodes). Colour images
are converted to grey by the decoder; 16-bit images are scaled to 8 bits by
their own maximum (the corner positions do not depend on a grey-level gain).

Every failure is an :class:`ImageError` (an :class:`~stiffmap.errors.InputError`)
naming the file: missing, a directory, empty, truncated or corrupt (checked from the
file's own structure before decoding: every chunk of a PNG and the size its header
declares (the chunks' CRCs are checked by libpng; a failing chunk is named), the closing
marker of a JPEG; and by the decoder for the others), not an image, an unsupported
format, or smaller than 8x8 px. What the C decoders (libpng, libjpeg,
OpenCV's TIFF reader) would print on the terminal is caught instead and said in the
message: an image they report damaged is refused, not measured. :func:`check_image_size`
compares an image with the size in ``camera.json``.

:func:`check_image` is the one check of an image array handed to the vision
functions (detection, corner refinement, photometric refinement): a grey image
(h, w) of uint8 (or uint16 where the function reads 16 bits), at least 8x8 px; a
BGR uint8 image (h, w, 3) is converted to grey. :func:`coarse_scales` and
:func:`reduce_image` give the reduced images the board detectors search first.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import re
import sys
import tempfile
import threading
import warnings
import zlib
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, StiffmapWarning
from ..io import no_such_path

__all__ = [
    "ImageError",
    "ImageWarning",
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


class ImageWarning(StiffmapWarning):
    """An image was read, but its decoder noted something odd (extraneous bytes in a JPEG)."""


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


#: Largest image side read, px (beyond: not a camera image, or a decompression bomb).
MAX_IMAGE_SIDE_PX = 100_000


def _check_png(data: bytes, src: str, crc: bool = True, header_only: bool = False) -> None:
    """Walk a PNG's chunks: lengths, the header's size and (``crc``) every critical chunk's CRC.

    libpng checks the chunks itself while decoding (and fails): :func:`read_image` checks the
    header alone before decoding (a declared size no camera makes is refused before the decoder
    allocates it), and walks every chunk with its CRC only to say why a decoding failed.
    """
    size = len(data)
    pos = 8
    first = True
    n_idat = 0
    while True:
        if pos + 8 > size:
            raise ImageError(
                f"truncated PNG file ({size} bytes; a chunk header at byte {pos} is cut)", source=src
            )
        length = int.from_bytes(data[pos : pos + 4], "big")
        tag = data[pos + 4 : pos + 8]
        name = tag.decode("latin-1") if tag.isalpha() else repr(tag)
        end = pos + 12 + length
        if not tag.isalpha() or length > 2**31 - 1:
            raise ImageError(f"corrupt PNG file: no valid chunk at byte {pos} ({name})", source=src)
        if end > size:
            raise ImageError(
                f"truncated or corrupt PNG file: chunk {name} at byte {pos} needs {length} bytes, "
                f"the file ends {size - pos - 12} bytes after its header",
                source=src,
            )
        critical = tag[:1].isupper()
        if crc and critical:
            body = data[pos + 8 : pos + 8 + length]
            if zlib.crc32(tag + body) != int.from_bytes(data[pos + 8 + length : end], "big"):
                raise ImageError(
                    f"corrupt PNG file: chunk {name} at byte {pos} fails its CRC check", source=src
                )
        if first:
            if tag != b"IHDR" or length != 13:
                raise ImageError(
                    f"corrupt PNG file: it starts with chunk {name}, not a header (IHDR)", source=src
                )
            w, h = (
                int.from_bytes(data[pos + 8 : pos + 12], "big"),
                int.from_bytes(data[pos + 12 : pos + 16], "big"),
            )
            if not (0 < w <= MAX_IMAGE_SIDE_PX and 0 < h <= MAX_IMAGE_SIDE_PX):
                raise ImageError(
                    f"the PNG header declares a {w}x{h} px image: not a camera image "
                    f"(1 to {MAX_IMAGE_SIDE_PX} px per side)",
                    source=src,
                )
            first = False
            if header_only:
                return
        n_idat += tag == b"IDAT"
        if tag == b"IEND":
            break
        pos = end
    if n_idat == 0:
        raise ImageError("corrupt PNG file: it holds no image data (no IDAT chunk)", source=src)


#: fd 2 is the process's: one thread at a time redirects it (else one would restore another's).
_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _decoder_messages():
    """Catch what the C decoders print on the process's stderr (fd 2) while decoding.

    Yields a list that holds the lines afterwards. OpenCV's own log is set to errors only
    (libtiff's warnings about unknown tags are noise; its errors mean damaged data).
    """
    with _STDERR_LOCK, _caught_fd2() as lines:
        yield lines


_CAPTURE: list = []  # [(pid, file)]: the file fd 2 is sent to while decoding, one per process


def _capture_file():
    """This process's temporary file for the decoders' messages (made once: a new one per image
    cost a few hundred microseconds), closed at exit. A forked child closes its copy of the
    parent's (the parent keeps its own) and makes its own."""
    pid = os.getpid()
    if _CAPTURE and _CAPTURE[0][0] == pid:
        return _CAPTURE[0][1]
    if _CAPTURE:
        with contextlib.suppress(OSError):
            _CAPTURE[0][1].close()
    else:
        atexit.register(_close_capture_file)
    _CAPTURE[:] = [(pid, tempfile.TemporaryFile())]
    return _CAPTURE[0][1]


def _close_capture_file() -> None:
    if _CAPTURE:
        with contextlib.suppress(OSError):
            _CAPTURE[0][1].close()


@contextlib.contextmanager
def _caught_fd2():
    lines: list[str] = []
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to catch: let the decoders print where they can
        saved = None
    try:
        if saved is None:
            yield lines
            return
        tmp = _capture_file()
        tmp.seek(0)
        tmp.truncate()
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            tmp.seek(0)
            text = tmp.read(4096).decode("utf-8", errors="replace")
            lines += [" ".join(ln.split()) for ln in text.splitlines() if ln.strip()]
    finally:
        if saved is not None:
            os.close(saved)
        cv2.utils.logging.setLogLevel(level)


def _damage(lines: list[str]) -> tuple[list[str], list[str]]:
    """Split decoder messages into damage (the data is corrupt or missing) and harmless notes."""
    damage, notes = [], []
    for ln in lines:
        text = re.sub(r"^\[\s*ERROR:[^\]]*\]\s*(global\s+\S+\s+)?", "", ln)
        if ln.startswith("libpng warning"):
            continue  # e.g. "iCCP: known incorrect sRGB profile": the pixels are fine
        (notes if "extraneous bytes" in ln else damage).append(text)
    return damage, notes


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
        Naming the file and what is wrong: no such file or folder, a directory, empty,
        truncated or corrupt (with what the decoder says), not an image,
        unsupported format, undecodable, or smaller than 8x8 px.

    Warns
    -----
    ImageWarning
        The image was decoded but its decoder noted extraneous bytes (a JPEG).
    """
    p = Path(path)
    src = str(path)
    if not p.exists():
        raise ImageError(no_such_path(p), source=src)
    if p.is_dir():
        raise ImageError("is a directory, expected an image file", source=src)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise ImageError(f"cannot read: {e.strerror or e}", source=src) from None
    size = len(data)
    if size == 0:
        raise ImageError("empty file (0 bytes), expected an image", source=src)
    fmt = _format_of(data[:16])
    if fmt is None:
        raise ImageError(
            "not an image file this tool can read (expected PNG, TIFF, BMP, JPEG, PGM or WebP)",
            source=src,
        )
    _check_complete(fmt, data[-32:], size, src)
    if fmt == "PNG":
        _check_png(data, src, header_only=True)
    flags = cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH
    with _decoder_messages() as lines:
        try:
            img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), flags)
        except cv2.error as e:  # pragma: no cover - OpenCV returns None rather than raising
            img = None
            lines.append(str(e))
    damage, notes = _damage(lines)
    if fmt == "PNG" and (img is None or damage):
        _check_png(data, src)  # which chunk is corrupt, when its CRC says so
    said = f" (the decoder says: {'; '.join(damage)[:300]})" if damage else ""
    if img is None:
        raise ImageError(
            f"cannot decode the {fmt} data ({size} bytes){said}: truncated or corrupt file, "
            "or a variant of the format this OpenCV build does not support",
            source=src,
        )
    if damage:
        raise ImageError(f"damaged {fmt} data{said}: a truncated or corrupt file", source=src)
    if notes:
        warnings.warn(f"{src}: the {fmt} decoder says: {'; '.join(notes)[:300]}", ImageWarning, stacklevel=2)
    return _as_grey8(img, src)


def _as_grey8(img: np.ndarray, src: str) -> np.ndarray:
    if img.ndim == 3:  # pragma: no cover - IMREAD_GRAYSCALE already converts
        img = cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2GRAY)
    if img.ndim != 2:
        raise ImageError(f"expected a 2-D image, got an array of shape {img.shape}", source=src)
    if min(img.shape) < MIN_IMAGE_PX:
        h, w = img.shape
        raise ImageError(
            f"image is {w}x{h} px; a board image needs at least {MIN_IMAGE_PX}x{MIN_IMAGE_PX} px", source=src
        )
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
