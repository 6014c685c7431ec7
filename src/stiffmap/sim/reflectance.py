"""Scene geometry: the targets in front of the camera and the reflectance each pixel sees.

A :class:`Target` is a board (:mod:`stiffmap.targets`) at a pose ``board2cam``, printed
as a grid of cells (:mod:`.texture`). :func:`render_reflectance` gives the box-filtered
reflectance of the scene at every pixel (exact area coverage, :mod:`.coverage`) from the
rays of the camera's pixels (the camera's ray cache, :func:`stiffmap.camera.pixel_rays`:
the undistorted rays of the pixel grid are the same for every image of a camera).
:func:`true_corners` gives the truth the measurement is compared with, and
:func:`clutter_background` a random backdrop. Optics and sensor come after, in
:mod:`.photometry`.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import CameraModel, pixel_rays
from ..geometry import as_transform
from ..posemath import faces_camera
from ..targets import CharucoBoard, Chessboard
from .coverage import render_block, render_block_tiled
from .texture import BoardTexture, texture_from_board

__all__ = ["Target", "render_reflectance", "true_corners", "clutter_background", "target_bbox"]


@dataclass(frozen=True)
class Target:
    """A board placed in front of the camera.

    Attributes
    ----------
    board : Chessboard or CharucoBoard
    board2cam : ndarray, shape (4, 4)
        Pose of the board frame in the camera frame, mm.
    name : str
        Name used in the exported truth (``"fixed"``, ``"mobile"``...).
    margin_mm : float or None
        White border around the squares, mm (default one square).
    white, black : float
        Reflectances of paper and ink (0..1).
    """

    board: Chessboard | CharucoBoard
    board2cam: np.ndarray
    name: str = ""
    margin_mm: float | None = None
    white: float = 0.92
    black: float = 0.06

    def __post_init__(self) -> None:
        if not isinstance(self.board, (Chessboard, CharucoBoard)):
            raise ValueError(f"board must be a Chessboard or CharucoBoard, got {type(self.board).__name__}")
        T = as_transform(self.board2cam, "board2cam").copy()
        T.setflags(write=False)
        object.__setattr__(self, "board2cam", T)

    @property
    def chessboard(self) -> Chessboard:
        return self.board.chessboard if isinstance(self.board, CharucoBoard) else self.board

    def texture(self) -> BoardTexture:
        return _texture(self.board, self.margin_mm, self.white, self.black)


_TEXTURES: OrderedDict = OrderedDict()


def _texture(board, margin_mm, white, black) -> BoardTexture:
    key = (board, margin_mm, white, black)
    tex = _TEXTURES.get(key)
    if tex is None:
        tex = texture_from_board(board, margin_mm=margin_mm, white=white, black=black)
        _TEXTURES[key] = tex
        while len(_TEXTURES) > 16:
            _TEXTURES.popitem(last=False)
    return tex


def target_bbox(camera: CameraModel, tex: BoardTexture, board2cam: np.ndarray, roi) -> tuple | None:
    try:
        uv = camera.project_rectangle(board2cam, tex.extent, samples=65)
    except ValueError:
        msg = "a target reaches behind the camera (Z <= 0); move it in front of the camera"
        raise ValueError(msg) from None
    c0 = max(int(np.floor(uv[:, 0].min())) - 2, roi[0])
    c1 = min(int(np.ceil(uv[:, 0].max())) + 3, roi[2])
    r0 = max(int(np.floor(uv[:, 1].min())) - 2, roi[1])
    r1 = min(int(np.ceil(uv[:, 1].max())) + 3, roi[3])
    if c0 >= c1 or r0 >= r1:
        return None
    return r0, r1, c0, c1


def render_reflectance(
    camera: CameraModel,
    targets,
    *,
    background=0.35,
    roi: tuple[int, int, int, int] | None = None,
    chunk_rows: int = 128,
    rays=None,
    tile_px: int = 0,
) -> np.ndarray:
    """Box-filtered scene reflectance seen by the camera (no photometry, no noise).

    Parameters
    ----------
    camera : CameraModel
    targets : sequence of Target
    background : float or ndarray, shape (h, w)
        Reflectance behind the targets (an image of the ROI's shape, or a constant).
    roi : (c0, r0, c1, r1), optional
        Render only columns c0..c1-1 and rows r0..r1-1 (default the whole image).
    chunk_rows : int
        Rows processed at a time (memory).
    rays : optional
        Where the rays of a block of pixels come from: an object with ``block(rows, cols)``
        returning the values of ``pixel_rays(camera).block(rows, cols)`` (default that, the
        camera's ray cache; :class:`stiffmap.sim.live_render.RayWindow` keeps them for a part of
        the image that is rendered again and again).
    tile_px : int
        0: every pixel worked out (:func:`~stiffmap.sim.coverage.render_block`); more: tiles of
        that many pixels that see one cell of a print take its value without working out each
        pixel (:func:`~stiffmap.sim.coverage.render_block_tiled`: the same values, bit for bit,
        twice as fast on the demo's mobile board, whose squares span tens of pixels).

    Returns
    -------
    ndarray, shape (r1 - r0, c1 - c0), float64
        Reflectance in [0, 1].
    """
    targets = _check_targets(camera, targets)
    roi, img = _background(camera, background, roi)
    rm = pixel_rays(camera)
    if not rm.covers_image:
        raise ValueError(f"cannot render through this camera's distortion: {rm.field.describe()}")
    block = rm.block if rays is None else rays.block
    # Painter's order: the farthest target first.
    order = sorted(targets, key=lambda tg: -float(np.linalg.norm(tg.board2cam[:3, 3])))
    for tg in order:
        _paint(img, tg, camera, roi, block, chunk_rows, tile_px)
    return img


def _check_targets(camera, targets) -> list[Target]:
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    targets = list(targets)
    for tg in targets:
        if not isinstance(tg, Target):
            raise ValueError(f"targets must be Target objects, got {type(tg).__name__}")
    return targets


def _background(camera: CameraModel, background, roi):
    """The region (c0, r0, c1, r1), checked, and the image of the background over it."""
    w, h = camera.image_size
    if roi is None:
        roi = (0, 0, w, h)
    c0, r0, c1, r1 = (int(v) for v in roi)
    if not (0 <= c0 < c1 <= w and 0 <= r0 < r1 <= h):
        raise ValueError(f"roi must be (c0, r0, c1, r1) inside the {w}x{h} image, got {roi}")
    shape = (r1 - r0, c1 - c0)
    if np.isscalar(background):
        img = np.full(shape, float(background))
    else:
        img = np.array(background, dtype=np.float64)
        if img.shape != shape:
            raise ValueError(f"background must have shape {shape}, got {img.shape}")
    return (c0, r0, c1, r1), img


def _paint(
    img: np.ndarray, tg: Target, camera: CameraModel, roi, block, chunk_rows: int, tile_px: int
) -> None:
    """Paint one target over ``img`` (the region ``roi``), ``chunk_rows`` rows at a time."""
    c0, r0, c1, r1 = roi
    T = tg.board2cam
    if not faces_camera(T):
        raise ValueError(
            f"target {tg.name or '(unnamed)'} is seen from behind: its z axis must point away from the camera"
        )
    tex = tg.texture()
    bb = target_bbox(camera, tex, T, (c0, r0, c1, r1))
    if bb is None:
        return
    br0, br1, bc0, bc1 = bb
    cols = np.arange(bc0 - 1, bc1 + 1, dtype=np.float64)  # with a one-pixel halo
    for rs in range(br0, br1, chunk_rows):
        re = min(rs + chunk_rows, br1)
        rows = np.arange(rs - 1, re + 1, dtype=np.float64)
        if tile_px:
            colv, covv = render_block_tiled(*block(rows, cols), tex, T, tile_px)
        else:
            colv, covv = render_block(*block(rows, cols), tex, T)
        sub = img[rs - r0 : re - r0, bc0 - c0 : bc1 - c0]
        sub[...] = colv.reshape(sub.shape) + (1.0 - covv.reshape(sub.shape)) * sub


def true_corners(camera: CameraModel, board: Chessboard | CharucoBoard, board2cam) -> np.ndarray:
    """True pixel positions of a board's inner corners.

    Returns
    -------
    ndarray, shape (n, 2)
        (u, v), px, row-major (``r * cols + c``).
    """
    T = as_transform(board2cam, "board2cam")
    obj = board.object_points()
    return camera.project(obj @ T[:3, :3].T + T[:3, 3])


def clutter_background(shape: tuple[int, int], rng: np.random.Generator, level: float = 0.35) -> np.ndarray:
    """A random cluttered backdrop: soft shading, discs and bars (reflectance, float32).

    Parameters
    ----------
    shape : (h, w)
    rng : numpy Generator
        The only source of randomness (reproducible).
    level : float
        Mean reflectance.
    """
    h, w = shape
    small = rng.uniform(-1, 1, size=(max(h // 128, 2), max(w // 128, 2))).astype(np.float32)
    img = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC) * 0.08 + level
    scale = max(h, w)
    for _ in range(24):
        kind = rng.integers(3)
        val = float(rng.uniform(0.05, 0.85))
        if kind == 0:
            c = (int(rng.integers(w)), int(rng.integers(h)))
            cv2.circle(img, c, int(rng.uniform(0.01, 0.08) * scale), val, -1, cv2.LINE_AA)
        elif kind == 1:
            p1 = (int(rng.integers(w)), int(rng.integers(h)))
            p2 = (int(rng.integers(w)), int(rng.integers(h)))
            cv2.line(img, p1, p2, val, int(rng.uniform(0.002, 0.02) * scale) + 1, cv2.LINE_AA)
        else:
            cen = (float(rng.integers(w)), float(rng.integers(h)))
            size = (float(rng.uniform(0.02, 0.15) * scale), float(rng.uniform(0.02, 0.15) * scale))
            box = cv2.boxPoints((cen, size, float(rng.uniform(0, 90))))
            cv2.fillConvexPoly(img, box.astype(np.int32), val, cv2.LINE_AA)
    return np.clip(img, 0.0, 1.0)
