"""Render planar targets through a distorted pinhole camera, with exact anti-aliasing.

:func:`render` is the test-bed's camera (``docs/simulation.md``): the targets' scene
geometry (:mod:`.reflectance`: which board cell each pixel sees, with exact area
coverage, :mod:`.coverage`) then the image-formation model (:mod:`.photometry`: optics
blur, vignetting, noise, 8 bits), and the ground truth of every target
(:class:`TargetTruth`). :func:`encode_image` writes the image as PNG or JPEG.

The names of those modules that users of the renderer need are importable from here too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..camera import CameraModel
from .coverage import half_plane_area
from .photometry import Photometry, apply_photometry, blurred_reflectance
from .reflectance import Target, clutter_background, render_reflectance, true_corners

__all__ = [
    "Target",
    "Photometry",
    "TargetTruth",
    "Rendering",
    "render",
    "render_reflectance",
    "apply_photometry",
    "blurred_reflectance",
    "true_corners",
    "encode_image",
    "half_plane_area",
]


@dataclass(frozen=True)
class TargetTruth:
    """Ground truth of one rendered target.

    Attributes
    ----------
    name : str
    board2cam : ndarray, shape (4, 4)
        mm.
    corners_px : ndarray, shape (n, 2)
        True (u, v) of the inner corners, px, row-major (``r * cols + c``).
    in_image : ndarray of bool, shape (n,)
        Corner inside the image (by at least half a pixel).
    """

    name: str
    board2cam: np.ndarray
    corners_px: np.ndarray
    in_image: np.ndarray


@dataclass(frozen=True)
class Rendering:
    """A rendered image and its ground truth.

    Attributes
    ----------
    image : ndarray of uint8, shape (h, w) or (h, w, 3)
    targets : tuple of TargetTruth
    """

    image: np.ndarray
    targets: tuple[TargetTruth, ...] = field(default_factory=tuple)


def render(
    camera: CameraModel,
    targets,
    *,
    photometry: Photometry | None = None,
    seed: int | np.random.Generator | None = 0,
) -> Rendering:
    """Render targets into a full 8-bit image and export the ground truth.

    Parameters
    ----------
    camera : CameraModel
    targets : sequence of Target
    photometry : Photometry, optional
        Default :class:`Photometry` () (with noise).
    seed : int or numpy Generator
        Noise and clutter source: the same seed gives the same image, bit for bit.

    Returns
    -------
    Rendering
    """
    ph = Photometry() if photometry is None else photometry
    if not isinstance(ph, Photometry):
        raise ValueError(f"photometry must be a Photometry, got {type(ph).__name__}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    targets = list(targets)
    w, h = camera.image_size
    bg = clutter_background((h, w), rng, ph.background) if ph.clutter else ph.background
    refl = blurred_reflectance(camera, targets, background=bg, blur_px=ph.blur_px)
    image = apply_photometry(refl, camera, ph, rng, blurred=True)
    truths = []
    for tg in targets:
        uv = true_corners(camera, tg.board, tg.board2cam)
        inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)
        truths.append(TargetTruth(tg.name, tg.board2cam, uv, inside))
    return Rendering(image=image, targets=tuple(truths))


def encode_image(image: np.ndarray, fmt: str = "png", *, jpeg_quality: int = 95) -> bytes:
    """Encode an 8-bit image as PNG (lossless, deterministic) or JPEG.

    Parameters
    ----------
    image : ndarray of uint8, shape (h, w) or (h, w, 3) (BGR)
    fmt : {"png", "jpg", "jpeg"}
    jpeg_quality : int
        0..100.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise ValueError(f"image must be uint8 of shape (h, w) or (h, w, 3), got {img.dtype} {img.shape}")
    f = fmt.lower().lstrip(".")
    if f == "png":
        # Huffman coding only: camera noise leaves little for LZ77 to find, so this is
        # faster to write and read, and smaller, than deflate at level 1.
        params = [
            cv2.IMWRITE_PNG_COMPRESSION,
            1,
            cv2.IMWRITE_PNG_STRATEGY,
            cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
        ]
        ok, buf = cv2.imencode(".png", img, params)
    elif f in ("jpg", "jpeg"):
        if not 0 <= int(jpeg_quality) <= 100:
            raise ValueError(f"jpeg_quality must be in 0..100, got {jpeg_quality}")
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
    else:
        raise ValueError(f"image format must be png or jpeg, got {fmt!r}")
    if not ok:  # pragma: no cover
        raise RuntimeError("OpenCV could not encode the image")
    return buf.tobytes()
