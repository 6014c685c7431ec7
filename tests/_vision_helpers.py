"""Test fixtures for the vision tests: a small chessboard renderer with known ground truth.

:func:`render` is a light stand-in for the virtual test-bed's renderer
(``stiffmap.sim.render``, used by :func:`render_scene`, the benchmarks and the
end-to-end tests), kept because it is quick on small images and takes an
occluding rectangle: it draws chessboards at known poses through a :class:`~stiffmap.camera.CameraModel`
(lens distortion included) by inverse mapping of supersampled pixel positions
onto the board plane, then applies a Gaussian optical blur, a shot + read noise
model and 8-bit quantisation. Corners' ground truth is the exact projection of
the board's inner corners (``camera.project``).

Only the region around each board is supersampled; the rest of the image is a
flat background, so a 2592x1944 frame renders in about a second.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from stiffmap.camera import CameraModel
from stiffmap.geometry import matrix_from_euler
from stiffmap.sim.render import Target
from stiffmap.sim.render import render as sim_render
from stiffmap.targets import Chessboard


def _find_calib_example() -> Path | None:
    """The real calibration photographs (../shared/data/calib_example), also from a git worktree.

    ``$STIFFMAP_SHARED_DATA`` may point at the shared data folder instead.
    """
    from conftest import SHARED_DATA

    here = Path(__file__).resolve().parents[1]
    cands = [SHARED_DATA / "calib_example", here.parents[1] / "shared" / "data" / "calib_example"]
    if os.environ.get("STIFFMAP_SHARED_DATA"):
        cands.insert(0, Path(os.environ["STIFFMAP_SHARED_DATA"]) / "calib_example")
    for cand in cands:
        if (cand / "Image1.tif").is_file():
            return cand
    return None


class _SharedData:
    """Where the real photographs are; a test that uses them is skipped, with the reason, when absent."""

    def __init__(self, path: Path | None) -> None:
        self.path = path

    def _get(self) -> Path:
        if self.path is None:
            pytest.skip(
                "the real photographs ../shared/data/calib_example were not found next to the repository "
                "(set STIFFMAP_SHARED_DATA to the shared data folder)"
            )
        return self.path

    def __truediv__(self, other) -> Path:
        return self._get() / other

    def glob(self, pattern: str):
        return self._get().glob(pattern)

    def __fspath__(self) -> str:
        return str(self._get())


#: Bouguet's calibration example: 20 real 640x480 photographs of a 13x12 board, 30 mm squares.
CALIB_DIR = _SharedData(_find_calib_example())


@dataclass(frozen=True)
class Photometry:
    """Grey levels and noise of the rendered image (8-bit units).

    black, white : reflectances of the printed squares seen by the camera.
    background : grey level outside the boards.
    blur_px : standard deviation of the Gaussian point-spread function, px.
    read_noise : standard deviation of the additive noise, grey levels.
    shot_gain : variance per grey level (photon shot noise), so the noise
        variance at level I is read_noise**2 + shot_gain * I.
    """

    black: float = 35.0
    white: float = 215.0
    background: float = 90.0
    blur_px: float = 0.7
    read_noise: float = 1.0
    shot_gain: float = 0.02


def look_at_pose(distance_mm: float, board: Chessboard, *, tilt_deg=(0.0, 0.0, 0.0), offset_mm=(0.0, 0.0)):
    """A ``board2cam`` pose: the board's centre on the optical axis at ``distance_mm``.

    Parameters
    ----------
    distance_mm : float
        Distance of the board centre along the optical axis, mm.
    tilt_deg : (3,) float
        Rotations about the board's x, y and z axes, degrees (applied in that order).
    offset_mm : (2,) float
        Lateral offset of the board centre (camera x, y), mm.

    Returns
    -------
    ndarray, shape (4, 4)
    """
    R = matrix_from_euler(np.radians(np.asarray(tilt_deg, dtype=float)))
    centre = np.array([(board.cols - 1) * board.square_mm / 2, (board.rows - 1) * board.square_mm / 2, 0.0])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.array([offset_mm[0], offset_mm[1], distance_mm]) - R @ centre
    return T


def _tri(x: np.ndarray, s: float) -> np.ndarray:
    """Antiderivative of the square wave (+1 on [0, s), -1 on [s, 2s), period 2s)."""
    m = np.mod(x, 2 * s)
    return np.where(m < s, m, 2 * s - m)


def _box_wave(x: np.ndarray, a: np.ndarray, s: float, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Box means over [x - a, x + a] of the indicator of [lo, hi] and of the square wave times it.

    Exact: the box is clipped to [lo, hi] and the square wave integrated there.
    """
    a = np.maximum(a, 1e-9 * s)
    u = np.clip(x - a, lo, hi)
    v = np.clip(x + a, lo, hi)
    return (v - u) / (2 * a), (_tri(v, s) - _tri(u, s)) / (2 * a)


def _board_value(
    bx: np.ndarray, by: np.ndarray, ax: np.ndarray, ay: np.ndarray, board: Chessboard, margin_sq: float
) -> np.ndarray:
    """Mean reflectance (0 black, 1 white) over a box of half-widths (ax, ay) mm around board points.

    Black is [inside the printed squares] (1 + Sx Sy) / 2 with the square waves
    Sx = (-1)^floor(x / s), Sy likewise (square (i, j) black when i + j is even):
    a sum of two separable products, so its mean over an axis-aligned box is
    exact. NaN outside the target (printed squares plus a white margin).
    """
    s = board.square_mm
    x0, y0, x1, y1 = board.extent_mm()
    fx, gx = _box_wave(bx, ax, s, x0, x1)
    fy, gy = _box_wave(by, ay, s, y0, y1)
    val = 1.0 - 0.5 * (fx * fy + gx * gy)
    m = margin_sq * s
    on_target = (bx >= x0 - m) & (bx <= x1 + m) & (by >= y0 - m) & (by <= y1 + m)
    return np.where(on_target, val, np.nan)


def render(
    camera: CameraModel,
    scene: Sequence[tuple[Chessboard, np.ndarray]],
    *,
    photometry: Photometry | None = None,
    supersample: int = 2,
    rng: np.random.Generator | None = None,
    margin_sq: float = 1.0,
    occluder: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """Render chessboards at known poses.

    Parameters
    ----------
    camera : CameraModel
    scene : sequence of (Chessboard, board2cam (4, 4) mm)
    photometry : Photometry, optional
    supersample : int
        Sub-pixels along each axis; each sub-pixel's footprint on the board is
        integrated exactly as an axis-aligned box (separable checker), so the
        edges carry no sampling staircase.
    rng : numpy Generator, optional
        Noise source; no noise when None.
    margin_sq : float
        White margin around the printed squares, in squares.
    occluder : (x0, y0, x1, y1), optional
        A rectangle of pixels painted with the background (a partly hidden board).

    Returns
    -------
    ndarray, shape (h, w), uint8
    """
    ph = photometry or Photometry()
    w, h = camera.image_size
    radiance = np.full((h, w), ph.background, dtype=np.float64)
    n = int(supersample)
    offs = (np.arange(n) + 0.5) / n - 0.5
    for board, b2c in scene:
        b2c = np.asarray(b2c, dtype=np.float64)
        s = board.square_mm
        x0, y0, x1, y1 = board.extent_mm()
        m = margin_sq * s
        outline = np.array(
            [[x, y, 0.0] for x in np.linspace(x0 - m, x1 + m, 9) for y in np.linspace(y0 - m, y1 + m, 9)]
        )
        uv = camera.project(outline @ b2c[:3, :3].T + b2c[:3, 3])
        c0 = int(max(np.floor(uv[:, 0].min()) - 3, 0))
        c1 = int(min(np.ceil(uv[:, 0].max()) + 4, w))
        r0 = int(max(np.floor(uv[:, 1].min()) - 3, 0))
        r1 = int(min(np.ceil(uv[:, 1].max()) + 4, h))
        if c1 <= c0 or r1 <= r0:
            continue
        # Board plane homography: ideal normalised (x, y, 1) ~ H (bx, by, 1).
        H = np.column_stack([b2c[:3, 0], b2c[:3, 1], b2c[:3, 3]])
        Hinv = np.linalg.inv(H)
        U, V = np.meshgrid(np.arange(c0, c1, dtype=np.float64), np.arange(r0, r1, dtype=np.float64))
        # Rays through the pixel centres (exact undistortion), then through the
        # sub-pixel samples to first order with the inverse distortion Jacobian
        # (the second-order term is below 1e-6 px for these lenses).
        rays = camera.rays_from_pixels(np.stack([U, V], axis=-1))
        _, J = camera.distort_with_jacobian(rays)
        Jinv = np.linalg.inv(J)
        # d(board)/d(pixel): through the inverse distortion and the plane homography.
        dpix = Jinv * np.array([1.0 / camera.fx, 1.0 / camera.fy])[None, None, :]
        acc = np.zeros(U.shape)
        cnt = np.zeros(U.shape)
        for dy in offs:
            for dx in offs:
                dn = np.array([dx / camera.fx, dy / camera.fy])
                xy = rays + Jinv @ dn
                q = np.einsum(
                    "ij,...j->...i", Hinv, np.concatenate([xy, np.ones_like(U)[..., None]], axis=-1)
                )
                b = q[..., :2] / q[..., 2:3]
                Jq = (Hinv[None, None, :2, :2] - b[..., :, None] * Hinv[None, None, 2, :2][..., None, :]) / q[
                    ..., 2, None, None
                ]
                Jb = Jq @ dpix  # (.., 2, 2): d(bx, by) / d(u, v)
                half = 0.5 / n
                ax = half * (np.abs(Jb[..., 0, 0]) + np.abs(Jb[..., 0, 1]))
                ay = half * (np.abs(Jb[..., 1, 0]) + np.abs(Jb[..., 1, 1]))
                val = _board_value(b[..., 0], b[..., 1], ax, ay, board, margin_sq)
                val = np.where(q[..., 2] > 0, val, np.nan)
                ok = np.isfinite(val)
                acc += np.where(ok, ph.black + (ph.white - ph.black) * np.nan_to_num(val), 0.0)
                cnt += ok
        region = radiance[r0:r1, c0:c1]
        frac = cnt / (n * n)
        mean = np.divide(acc, cnt, out=np.zeros_like(acc), where=cnt > 0)
        radiance[r0:r1, c0:c1] = frac * mean + (1 - frac) * region
    if occluder is not None:
        a, b, c, d = occluder
        radiance[b:d, a:c] = ph.background
    if ph.blur_px > 0:
        radiance = gaussian_filter(radiance, ph.blur_px, mode="nearest")
    if rng is not None:
        sd = np.sqrt(ph.read_noise**2 + ph.shot_gain * np.clip(radiance, 0, None))
        radiance = radiance + rng.normal(size=radiance.shape) * sd
    return np.clip(np.round(radiance), 0, 255).astype(np.uint8)


def true_corners(camera: CameraModel, board: Chessboard, board2cam: np.ndarray) -> np.ndarray:
    """Exact pixel positions of the inner corners, shape (n, 2), canonical order."""
    b2c = np.asarray(board2cam, dtype=np.float64)
    return camera.project(board.object_points() @ b2c[:3, :3].T + b2c[:3, 3])


def small_camera() -> CameraModel:
    """A 640x480 camera with moderate barrel distortion, for quick tests."""
    return CameraModel((640, 480), 900.0, 905.0, 322.5, 236.0, (-0.12, 0.08, 0.0005, -0.0003, 0.0))


#: Which renderer the benchmarks and end-to-end tests use: the virtual test-bed's.
RENDERER = (
    "stiffmap.sim.render (virtual test-bed: exact area coverage, default Photometry: "
    "gain 0.8, read noise 0.8 DN, shot 0.04 DN/e, blur 0.8 px, vignetting 0.3)"
)


def render_scene(camera: CameraModel, scene, rng: np.random.Generator, photometry=None) -> np.ndarray:
    """Render [(board, board2cam), ...] with ``stiffmap.sim.render`` (default realistic photometry).

    Parameters
    ----------
    camera : CameraModel
    scene : sequence of (Chessboard or CharucoBoard, ndarray (4, 4))
    rng : numpy Generator
        Noise source.
    photometry : stiffmap.sim.render.Photometry, optional

    Returns
    -------
    ndarray, shape (h, w), uint8
    """
    targets = [Target(b, T) for b, T in scene]
    return sim_render(camera, targets, photometry=photometry, seed=rng).image
