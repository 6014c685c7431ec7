"""A grey image as a small PNG for the report (standard library only: zlib and struct).

The report embeds one of the campaign's images (with the boards drawn on it) in its
self-contained page and in ``data.json``; a photograph of several megapixels is reduced
first, by an integer factor (the mean of each block of pixels), so that the page stays a
few hundred kilobytes heavier, not megabytes.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

__all__ = ["grey_png", "reduce_image", "MAX_PAGE_WIDTH_PX"]

#: Widest image the page shows, px (a larger one is reduced by an integer factor).
MAX_PAGE_WIDTH_PX = 960


def reduce_image(image: np.ndarray, max_width: int = MAX_PAGE_WIDTH_PX) -> tuple[np.ndarray, int]:
    """``image`` reduced by the smallest integer factor that makes it at most ``max_width`` wide.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8 (or any numbers 0..255)

    Returns
    -------
    reduced : ndarray, shape (h // k, w // k), uint8
        Each pixel the mean of a k x k block (the last rows and columns that do not fill a
        block are left out).
    k : int
        The factor (1: unchanged).
    """
    a = np.asarray(image)
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"image: expected a grey image (h, w), got shape {a.shape}")
    k = max(1, -(-a.shape[1] // max_width))
    if k == 1:
        return np.clip(a, 0, 255).astype(np.uint8), 1
    h, w = (a.shape[0] // k) * k, (a.shape[1] // k) * k
    blocks = a[:h, :w].astype(np.float64).reshape(h // k, k, w // k, k)
    return np.clip(np.rint(blocks.mean(axis=(1, 3))), 0, 255).astype(np.uint8), k


def grey_png(image: np.ndarray) -> bytes:
    """The PNG file of an 8-bit grey image, shape (h, w) (no filter, zlib level 9)."""
    a = np.ascontiguousarray(image, dtype=np.uint8)
    if a.ndim != 2:
        raise ValueError(f"image: expected shape (h, w), got {a.shape}")
    h, w = a.shape
    raw = np.hstack([np.zeros((h, 1), np.uint8), a]).tobytes()  # filter type 0 on every row

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)  # 8 bits, grey, deflate, no filter, no interlace
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )
