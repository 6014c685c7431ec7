"""Images of chessboards at known poses, for the vision and test-bed tests and the benchmarks.

Three ways to make one:

- :func:`quick_board_image`, the tests' own light renderer, kept beside the virtual
  test-bed's because it is quick on small images and takes an occluding rectangle: it
  draws chessboards at known poses through a :class:`~stiffmap.camera.CameraModel` (lens
  distortion included) by inverse mapping of supersampled pixel positions onto the board
  plane, then applies a Gaussian optical blur, a shot + read noise model and 8-bit
  quantisation (:class:`QuickPhotometry`). Only the region around each board is
  supersampled; the rest of the image is a flat background, so a 2592x1944 frame renders
  in about a second. The corners' ground truth is
  :func:`helpers.board_scenes.exact_corners`.
- :func:`testbed_board_image`, the virtual test-bed's renderer (``stiffmap.sim.render``)
  with its realistic default photometry, used by the benchmarks and the end-to-end tests
  (:data:`TESTBED_RENDERER` says so in the benchmarks' tables).
- :func:`warped_board_image` and :func:`area_board_image`, boards drawn without
  stiffmap (OpenCV's warp of a raster; exact pixel-area coverage) and blurred after pixel
  integration: image formations that are not the test-bed's (pinhole cameras only).
- :func:`bayer_board_image` and :func:`jpeg_image`: the test-bed's optics and pixel
  integration, then a colour camera's Bayer mosaic demosaiced by OpenCV, or JPEG
  compression (image formations that are not the test-bed's, for the photometric model).
- :func:`brute_force_reflectance`, a slow reference of the test-bed's reflectance (point
  samples mapped exactly), independent of its coverage formulas.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from stiffmap.camera import CameraModel
from stiffmap.sim.photometry import Photometry, blurred_reflectance
from stiffmap.sim.render import Target, render
from stiffmap.targets import Chessboard


@dataclass(frozen=True)
class QuickPhotometry:
    """Grey levels and noise of :func:`quick_board_image` (8-bit units).

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


def quick_board_image(
    camera: CameraModel,
    scene: Sequence[tuple[Chessboard, np.ndarray]],
    *,
    photometry: QuickPhotometry | None = None,
    supersample: int = 2,
    rng: np.random.Generator | None = None,
    margin_sq: float = 1.0,
    occluder: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """Render chessboards at known poses, quickly (the tests' light renderer).

    Parameters
    ----------
    camera : CameraModel
    scene : sequence of (Chessboard, board2cam (4, 4) mm)
    photometry : QuickPhotometry, optional
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
    ph = photometry or QuickPhotometry()
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


#: Which renderer the benchmarks and end-to-end tests use: the virtual test-bed's.
TESTBED_RENDERER = (
    "stiffmap.sim.render (virtual test-bed: exact area coverage, default Photometry: "
    "gain 0.8, read noise 0.8 DN, shot 0.04 DN/e, blur 0.8 px, vignetting 0.3)"
)


def testbed_board_image(camera: CameraModel, scene, rng: np.random.Generator, photometry=None) -> np.ndarray:
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
    return render(camera, targets, photometry=photometry, seed=rng).image


def brute_force_reflectance(camera: CameraModel, target, roi, n: int = 64, background: float = 0.35):
    """Reference render: n x n point samples per pixel, each mapped exactly (no linearisation).

    Every sub-sample's ray is undistorted by Newton's method
    (``CameraModel.rays_from_pixels``) and met with the board plane; the print is
    point-sampled. Independent of the renderer's coverage formulas; its own error
    on an edge pixel is at most about 1/n of the contrast.
    """
    c0, r0, c1, r1 = roi
    off = (np.arange(n) + 0.5) / n - 0.5
    cols = np.arange(c0, c1, dtype=np.float64)
    rows = np.arange(r0, r1, dtype=np.float64)
    U = cols[None, :, None, None] + off[None, None, None, :]
    V = rows[:, None, None, None] + off[None, None, :, None]
    U, V = np.broadcast_arrays(U, V)
    rays = camera.rays_from_pixels(np.stack([U, V], axis=-1))
    d = np.concatenate([rays, np.ones((*rays.shape[:-1], 1))], axis=-1)
    T = target.board2cam
    R, t = T[:3, :3], T[:3, 3]
    lam = (R[:, 2] @ t) / (d @ R[:, 2])
    p = lam[..., None] * d - t
    refl, alpha = target.texture().sample(p @ R[:, 0], p @ R[:, 1])
    return (refl * alpha + (1 - alpha) * background).mean(axis=(2, 3))


def _blur_noise_8bit(
    img: np.ndarray, blur_after_px: float, noise: float, rng: np.random.Generator | None
) -> np.ndarray:
    """The last steps of the drawings: a Gaussian blur after pixel integration (sigma px),
    additive Gaussian noise (grey levels) and 8-bit quantisation."""
    if blur_after_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_after_px)
    rng = rng if rng is not None else np.random.default_rng(0)
    img = img + rng.normal(0.0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def warped_board_image(
    camera: CameraModel,
    board: Chessboard,
    board2cam: np.ndarray,
    *,
    white_first: bool = False,
    margin_sq: float = 1.0,
    supersample: int = 2,
    blur_after_px: float = 0.8,
    black: float = 30.0,
    white: float = 220.0,
    background: float = 70.0,
    noise: float = 1.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """A chessboard drawn through OpenCV alone, with a blur applied after pixel integration.

    An image formation that is neither the test-bed's nor :func:`quick_board_image`'s: a
    fine raster of the printed board (squares from -1 to ``cols`` and ``rows``, a white
    margin of ``margin_sq`` squares) is mapped into a ``supersample`` times finer image
    by ``cv2.warpPerspective`` (bilinear), integrated over each pixel by
    ``cv2.resize(INTER_AREA)`` (the raster box-filtered first over a fine pixel's
    footprint, so each fine pixel is an area average too), then blurred by ``cv2.GaussianBlur`` (sigma
    ``blur_after_px``) -- the order of a camera whose optics are sharp but whose image
    is softened afterwards (sensor cross-talk, demosaicing, compression) -- and given
    Gaussian noise, 8 bits. ``white_first`` prints square (0, 0) white (the colour
    phase of a board whose right-handed orderings cannot tell it).

    Every grid line of the raster lies on a raster pixel boundary, so the drawn squares
    have their true sizes; the raster's box filter and the bilinear warp only add a
    symmetric blur of about 1/``supersample`` px, which moves no edge. Poses measured on
    it agree with :func:`area_board_image`'s (exact coverage) within 0.5 um at 520 mm for
    ``supersample`` 2 and 4.

    The camera must have no lens distortion (the map is a homography).
    """
    if np.any(camera.dist_array != 0):
        raise ValueError("warped_board_image draws through a homography: the camera must have no distortion")
    s = board.square_mm
    x0, y0 = -(1 + margin_sq) * s, -(1 + margin_sq) * s
    x1, y1 = (board.cols + margin_sq) * s, (board.rows + margin_sq) * s
    w, h = camera.image_size
    T = np.asarray(board2cam, dtype=np.float64)
    Hb = camera.matrix @ np.c_[T[:3, 0], T[:3, 1], T[:3, 3]]  # board mm -> image px
    # Raster fine enough that one raster pixel is under a quarter of a supersampled pixel,
    # with a whole number of raster pixels per square and its origin on a multiple of the
    # square: every grid line falls on a raster pixel boundary. (A raster of 4 ss span_px
    # px/mm moved each line to the nearest boundary, by up to 1/(8 ss) px, differently for
    # each line: the squares' sizes were wrong by about 1e-4, and the board's distance
    # with them -- 25-80 um at 520 mm, 3-36 sigma of the photometric pose, in both poses.)
    corners = np.array([[x0, y0, 1], [x1, y0, 1], [x1, y1, 1], [x0, y1, 1]]) @ Hb.T
    px = corners[:, :2] / corners[:, 2:]
    span_px = max(np.ptp(px[:, 0]) / (x1 - x0), np.ptp(px[:, 1]) / (y1 - y0))
    r = np.ceil(4.0 * supersample * span_px * s) / s  # raster px per mm, an integer number per square
    x0, y0 = np.floor(x0 * r) / r, np.floor(y0 * r) / r
    nu, nv = int(np.ceil((x1 - x0) * r)), int(np.ceil((y1 - y0) * r))
    u = x0 + (np.arange(nu) + 0.5) / r
    v = y0 + (np.arange(nv) + 0.5) / r
    i = np.floor(u / s).astype(int)[None, :]
    j = np.floor(v / s).astype(int)[:, None]
    checkered = (i >= -1) & (i <= board.cols - 1) & (j >= -1) & (j <= board.rows - 1)
    is_black = checkered & (((i + j) % 2 == 0) != white_first)
    raster = np.where(is_black, black, white).astype(np.float32)
    # Box-filter the raster over about one supersampled pixel's footprint, so that the
    # bilinear warp samples an area average, not a point (no staircase edges).
    k = int(round(r / (supersample * span_px))) | 1  # odd: centred, no shift
    raster = cv2.blur(raster, (k, k), borderType=cv2.BORDER_REPLICATE)
    A = np.array([[1 / r, 0, x0 + 0.5 / r], [0, 1 / r, y0 + 0.5 / r], [0, 0, 1]])
    ss = supersample
    S = np.array([[ss, 0, (ss - 1) / 2], [0, ss, (ss - 1) / 2], [0, 0, 1]])
    fine = cv2.warpPerspective(
        raster, S @ Hb @ A, (w * ss, h * ss), flags=cv2.INTER_LINEAR, borderValue=float(background)
    )
    img = cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA)
    return _blur_noise_8bit(img, blur_after_px, noise, rng)


def _quadrant_area(poly: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Area of a polygon (k, 2) px inside each quadrant {x <= X, y <= Y} (X, Y broadcast).

    Green's theorem with the potential (x - X) dy, which vanishes along the quadrant's own
    sides x = X and y = Y: the area is the sum over the polygon's edges, each clipped to the
    quadrant, of ((x_a + x_b) / 2 - X) (y_b - y_a). Exact for straight edges.
    """
    total = np.zeros(np.broadcast_shapes(X.shape, Y.shape))
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        d = b - a
        lo = np.zeros_like(total)
        hi = np.ones_like(total)
        for k, lim in ((0, X), (1, Y)):
            if d[k] > 0:
                hi = np.minimum(hi, (lim - a[k]) / d[k])
            elif d[k] < 0:
                lo = np.maximum(lo, (lim - a[k]) / d[k])
            else:
                hi = np.where(a[k] <= lim, hi, -1.0)
        xa, xb = a[0] + lo * d[0], a[0] + hi * d[0]
        total += np.where(hi > lo, (0.5 * (xa + xb) - X) * (hi - lo) * d[1], 0.0)
    x, y = poly[:, 0], poly[:, 1]
    signed = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    return total * np.sign(signed)


def paint_polygon(img: np.ndarray, poly: np.ndarray, value: float) -> None:
    """Add ``value`` times the exact area of ``poly`` (k, 2) px inside each pixel of ``img``."""
    h, w = img.shape
    c0 = int(max(np.floor(poly[:, 0].min() + 0.5), 0))
    c1 = int(min(np.floor(poly[:, 0].max() + 0.5) + 1, w))
    r0 = int(max(np.floor(poly[:, 1].min() + 0.5), 0))
    r1 = int(min(np.floor(poly[:, 1].max() + 0.5) + 1, h))
    if c1 <= c0 or r1 <= r0:
        return
    X = (np.arange(c0, c1 + 1) - 0.5)[None, :]
    Y = (np.arange(r0, r1 + 1) - 0.5)[:, None]
    F = _quadrant_area(poly, X, Y)
    img[r0:r1, c0:c1] += value * (F[1:, 1:] - F[1:, :-1] - F[:-1, 1:] + F[:-1, :-1])


def area_board_image(
    camera: CameraModel,
    board: Chessboard,
    board2cam: np.ndarray,
    *,
    white_first: bool = False,
    margin_sq: float = 1.0,
    blur_after_px: float = 0.8,
    black: float = 30.0,
    white: float = 220.0,
    background: float = 70.0,
    noise: float = 1.0,
    rng: np.random.Generator | None = None,
    ink_mm: float = 0.0,
) -> np.ndarray:
    """A chessboard drawn by exact pixel-area coverage, blurred after pixel integration.

    The same image formation as :func:`warped_board_image` without its raster: through a
    pinhole camera (no distortion) each printed square is a convex quadrilateral in the
    image, and each pixel ``[row, col]`` (the square [col - 1/2, col + 1/2] x
    [row - 1/2, row + 1/2]) gathers the exact area of it that it covers (Green's theorem
    over the quadrilateral's edges clipped to the pixel's corners' quadrants; no sampling,
    no linearisation, nothing shared with ``stiffmap.sim``). Then ``cv2.GaussianBlur``
    (sigma ``blur_after_px``), Gaussian noise, 8 bits. Fast: a 1024x768 image in about
    0.1 s.

    ``ink_mm``: ink spread, every black square printed ``ink_mm`` larger on each side (two
    diagonal neighbours then overlap in a 2 ``ink_mm`` square at their common corner, drawn
    once): each edge moves towards its white side, the corners stay.
    """
    if np.any(camera.dist_array != 0):
        raise ValueError("area_board_image draws through a homography: the camera must have no distortion")
    s = board.square_mm
    T = np.asarray(board2cam, dtype=np.float64)
    Hb = camera.matrix @ np.c_[T[:3, 0], T[:3, 1], T[:3, 3]]  # board mm -> image px

    def to_image(xy):
        q = np.c_[xy, np.ones(len(xy))] @ Hb.T
        if np.any(q[:, 2] <= 0):
            raise ValueError("area_board_image: part of the board is behind the camera")
        return q[:, :2] / q[:, 2:]

    w, h = camera.image_size
    img = np.full((h, w), float(background))
    m = margin_sq * s
    x0, y0, x1, y1 = -s - m, -s - m, board.cols * s + m, board.rows * s + m
    paint_polygon(img, to_image(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])), white - background)
    for i in range(-1, board.cols):
        for j in range(-1, board.rows):
            if ((i + j) % 2 == 0) != white_first:
                sq = s * np.array([[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1]], dtype=float)
                sq += ink_mm * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
                paint_polygon(img, to_image(sq), black - white)
            if ink_mm > 0 and i >= 0 and j >= 0:  # the overlap at inner corner (i, j), drawn twice
                sq = np.array([[i * s, j * s]]) + ink_mm * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
                paint_polygon(img, to_image(sq), white - black)
    return _blur_noise_8bit(img, blur_after_px, noise, rng)


#: OpenCV's demosaicing of an RGGB mosaic (R at even rows and columns: OpenCV's "BayerBG").
DEMOSAIC = {
    "bilinear": cv2.COLOR_BayerBG2BGR,
    "edge-aware": cv2.COLOR_BayerBG2BGR_EA,
    "VNG": cv2.COLOR_BayerBG2BGR_VNG,
}


def bayer_board_image(
    camera: CameraModel,
    scene,
    rng: np.random.Generator,
    *,
    demosaic: str = "bilinear",
    photometry: Photometry | None = None,
    colour: bool = False,
) -> np.ndarray:
    """The test-bed's scene through an RGGB Bayer sensor, demosaiced by OpenCV, in grey.

    The test-bed's optics blur and pixel integration (``stiffmap.sim.photometry.blurred_reflectance``)
    give each photosite's light; the photometry's gain and vignetting make it DN; each
    photosite keeps one colour (R at even rows and columns, B at odd ones) with the
    photometry's white balance; shot and read noise per photosite, black level, 8 bits;
    ``cv2.cvtColor`` with :data:`DEMOSAIC` [``demosaic``] makes BGR, and ``COLOR_BGR2GRAY``
    grey (``colour=True`` returns the BGR image). The scene is neutral grey, so the
    colour planes differ only by the white balance: what the demosaicing does to an edge
    is what is left.

    Parameters
    ----------
    camera : CameraModel
    scene : sequence of (Chessboard, board2cam (4, 4) mm)
    rng : numpy Generator
    demosaic : {"bilinear", "edge-aware", "VNG"}
    photometry : stiffmap.sim.render.Photometry, optional
        Default ``Photometry()`` (its ``colour`` flag is not used).
    colour : bool

    Returns
    -------
    ndarray, shape (h, w) or (h, w, 3), uint8
    """
    ph = photometry or Photometry()
    targets = [Target(b, T) for b, T in scene]
    refl = blurred_reflectance(camera, targets, background=ph.background, blur_px=ph.blur_px)
    w, h = camera.image_size
    x = ((np.arange(w) - camera.cx) / camera.fx)[None, :]
    y = ((np.arange(h) - camera.cy) / camera.fy)[:, None]
    vignette = (1 - ph.vignetting) + ph.vignetting / (1 + x * x + y * y) ** 2
    sig = refl * (255.0 * ph.gain) * vignette
    b, g, r = ph.white_balance
    sig[0::2, 0::2] *= r
    sig[0::2, 1::2] *= g
    sig[1::2, 0::2] *= g
    sig[1::2, 1::2] *= b
    sd = np.sqrt(ph.read_noise_dn**2 + ph.shot_dn_per_e * np.clip(sig, 0, None))
    raw = np.clip(np.rint(sig + sd * rng.standard_normal(sig.shape) + ph.offset_dn), 0, 255).astype(np.uint8)
    bgr = cv2.cvtColor(raw, DEMOSAIC[demosaic])
    return bgr if colour else cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)


def jpeg_image(image: np.ndarray, quality: int) -> np.ndarray:
    """``image`` (grey or BGR, uint8) through JPEG at ``quality`` (cv2.imencode / imdecode), in grey.

    A BGR image is compressed in colour (OpenCV's default 4:2:0 chroma subsampling) and
    decoded to grey; a grey one is compressed as grey.
    """
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise RuntimeError("cv2.imencode failed")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
