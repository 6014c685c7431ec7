"""The pixel set of the photometric fit: which pixels of a board it uses, and what stays fixed.

:func:`prepare_pixels` chooses, at the starting pose, the pixels that tell where the
board's edges are, and keeps with each what does not change during the fit
(:class:`PhotometricSetup`): its ray (x/z, y/z) (the lens distortion inverted, from the
camera's ray cache :func:`~stiffmap.camera.pixel_rays`: it does not depend on the pose),
its value, the nearest grid lines and the values on either side of them, the local
mm -> px scale, the direction of the edge, and the shading monomials.

Pixels within 3 sigma of both an X and a Y line (the corners, where the blur is not
separable in board coordinates when the board is seen obliquely; see
:mod:`~stiffmap.vision.photometric.model`) are left out. So are pixels farther than
``band_px`` from every line (no information on the pose), outside the checkered area
grown by the band (the margin beyond and the background are not modelled), saturated
pixels, and pixels inside ``exclude`` polygons (another board).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ...camera import CameraModel, pixel_rays
from ...errors import InputError
from ...posemath import check_pose, faces_camera, ray2board_homography
from ...targets import Chessboard
from ..images import check_image

__all__ = [
    "PhotometricError",
    "PhotometricSetup",
    "prepare_pixels",
    "check_board2cam",
    "CORNER_SIGMAS",
    "MIN_PIXELS",
    "DOUBLE_FIELDS",
]

#: Corner zones: pixels within this many blur sigmas of both an X and a Y line are left out.
CORNER_SIGMAS = 3.0
#: The default band of pixels along every grid line: this many blur sigmas, ...
#: A narrower band is faster but not better: the edge of a real image (and of the renderer's:
#: pixel-area integration, then a Gaussian blur) is not quite the model's Gaussian, and the fit
#: trades that for a dilation that moves the depth. On 1300 px / 520 mm exact renders (blur
#: 0.85 px) the depth moved by -3.5, -1.0 and 0 um (sigma 1.8 um) for bands of 1.27, 1.52 and
#: 1.69 px, and its sigma grew by 10, 11 and 9 % over the 2.1 px band's.
BAND_SIGMAS = 2.5
#: ... and at least this many px, on either side.
BAND_MIN_PX = 2.0
#: Fewest pixels for a fit.
MIN_PIXELS = 200


class PhotometricError(InputError):
    """The photometric fit could not be done or did not converge (the corner pose stays usable)."""


#: Per-pixel fields a float32 set-up keeps in double precision (the model's geometry: the
#: distance of a ray's board point to its grid line is a small difference of large coordinates).
DOUBLE_FIELDS = frozenset({"rx", "ry", "line_x", "line_y"})


@dataclass(frozen=True)
class PhotometricSetup:
    """The pixels of one board used by the fit and what does not change during it.

    Per-pixel arrays all have shape (N,) (contiguous, for speed).

    Attributes
    ----------
    board : Chessboard
    rx, ry : ndarray
        Undistorted rays (x/z, y/z) of the pixel centres.
    u, v : ndarray
        Pixel centres, px.
    values : ndarray
        Image values, DN.
    line_x, line_y : ndarray
        Position k s (mm) of the nearest X and Y grid line, k in -1..cols (rows).
    isx, isy : ndarray
        1 / |grad_p X| and 1 / |grad_p Y| at the starting pose, px/mm (the local
        mm -> px scale, fixed during the fit: it sets the blur's width, not the
        edges' positions).
    bsx, bsy : ndarray
        For a pixel near an X line (Y line): +1 when the black square is on its low side,
        -1 when it is on its high side, 0 when there is no edge (white on both sides) or the
        pixel belongs to the other axis. The black squares grow by ``dilation_px``: the
        edge moves towards the white side.
    c2, s2 : ndarray
        cos 2 theta and sin 2 theta of the direction theta of the edge's normal in the
        image (for the blur and the dilation that depend on it).
    fx0, fx1, gx0, gx1, fy0, fy1, gy0, gy1 : ndarray
        Across the nearest line of each axis: the value A on the low side and the jump
        B - A of the indicator I (f) and of I S (g), so that the blurred factors are
        A + (B - A) Phi(d / sigma).
    basis : ndarray, shape (n_basis, N)
        Shading monomials of (u - u0) / L, (v - v0) / L.
    centre : (float, float)
    length : float
    region : (int, int, int, int) or None
        The pixels the selection looked at, (c0, r0, c1, r1): columns c0..c1-1, rows
        r0..r1-1 (the checkered area grown by 0.6 square); areas left out (``exclude``)
        that miss it leave the set unchanged. None: unknown (any area may change it).
    """

    board: Chessboard
    rx: np.ndarray
    ry: np.ndarray
    u: np.ndarray
    v: np.ndarray
    values: np.ndarray
    line_x: np.ndarray
    line_y: np.ndarray
    isx: np.ndarray
    isy: np.ndarray
    bsx: np.ndarray
    bsy: np.ndarray
    c2: np.ndarray
    s2: np.ndarray
    fx0: np.ndarray
    fx1: np.ndarray
    gx0: np.ndarray
    gx1: np.ndarray
    fy0: np.ndarray
    fy1: np.ndarray
    gy0: np.ndarray
    gy1: np.ndarray
    basis: np.ndarray
    centre: tuple[float, float]
    length: float
    region: tuple[int, int, int, int] | None = None

    @property
    def n_pixels(self) -> int:
        return int(self.values.size)

    def slice(self, start: int, stop: int) -> PhotometricSetup:
        """Pixels start..stop-1 (views, no copy)."""
        kw = {}
        for f in self.__dataclass_fields__:
            val = getattr(self, f)
            if f == "basis":
                kw[f] = val[:, start:stop]
            elif isinstance(val, np.ndarray):
                kw[f] = val[start:stop]
            else:
                kw[f] = val
        return PhotometricSetup(**kw)

    def astype(self, dtype) -> PhotometricSetup:
        """The same set-up with every per-pixel array in ``dtype`` (float32: the fast fit), but
        the rays and the grid lines: they stay double (:data:`DOUBLE_FIELDS`)."""
        dt = np.dtype(dtype)
        kw = {}
        for f in self.__dataclass_fields__:
            val = getattr(self, f)
            if isinstance(val, np.ndarray):
                val = np.ascontiguousarray(val, dtype=np.float64 if f in DOUBLE_FIELDS else dt)
            kw[f] = val
        return PhotometricSetup(**kw)

    def subset(self, idx: np.ndarray) -> PhotometricSetup:
        """The same set-up restricted to pixels ``idx``."""
        kw = {}
        for f in self.__dataclass_fields__:
            val = getattr(self, f)
            if f == "basis":
                kw[f] = np.ascontiguousarray(val[:, idx])
            elif isinstance(val, np.ndarray):
                kw[f] = np.ascontiguousarray(val[idx])
            else:
                kw[f] = val
        return PhotometricSetup(**kw)


def _monomials(un: np.ndarray, vn: np.ndarray, degree: int) -> np.ndarray:
    rows = [np.ones_like(un)]
    for d in range(1, degree + 1):
        for i in range(d + 1):
            rows.append(un ** (d - i) * vn**i)
    return np.ascontiguousarray(np.stack(rows, axis=0))


def _jumps(k: np.ndarray, n: int, phase: int = 0) -> tuple[np.ndarray, ...]:
    """(A_F, B_F - A_F, A_G, B_G - A_G) across line k of the indicator F = I and of G = I S.

    Lines k = -1..n at k s; square i spans [i s, (i + 1) s] for i = -1..n-1 with S = (-1)^(i + phase)
    (square (i, j) black when i + j + phase is even: black = (1 + Sx Sy) / 2 on the checkered
    area; the phase is given to one axis only).
    """
    sgn_right = np.where((k + phase) % 2 == 0, 1.0, -1.0)  # the sign S of the square right of line k
    AF = np.where(k == -1, 0.0, 1.0)
    BF = np.where(k == n, 0.0, 1.0)
    AG = np.where(k == -1, 0.0, -sgn_right)
    BG = np.where(k == n, 0.0, sgn_right)
    return AF, BF - AF, AG, BG - AG


def _black_side(k: np.ndarray, j: np.ndarray, n: int, m: int, phase: int = 0) -> np.ndarray:
    """+1 when square (k - 1, j) is black, -1 when square (k, j) is, 0 when neither.

    Squares (i, j) with i in -1..n-1 and j in -1..m-1 are printed, black when i + j +
    phase is even; anything else is the white margin.
    """
    inside_j = (j >= -1) & (j <= m - 1)
    left = inside_j & (k - 1 >= -1) & (k - 1 <= n - 1) & ((k - 1 + j + phase) % 2 == 0)
    right = inside_j & (k >= -1) & (k <= n - 1) & ((k + j + phase) % 2 == 0)
    return left.astype(np.float64) - right.astype(np.float64)


def check_board2cam(board2cam) -> np.ndarray:
    """The starting pose, checked: a rigid transform of a board seen from its front."""
    T = check_pose(board2cam, "board2cam")
    if not faces_camera(T):
        raise ValueError("board2cam: the board is seen from behind (its z axis points towards the camera)")
    return T


def _check_inputs(image, board, board2cam, camera, band_px, blur_px, shading_degree, phase):
    """The image, the starting pose and the band (px), checked."""
    img = check_image(image, uint16=True)
    T = check_board2cam(board2cam)
    if not isinstance(board, Chessboard):
        raise ValueError(f"the photometric model is for chessboards, got {type(board).__name__}")
    if phase not in (0, 1):
        raise ValueError(f"phase must be 0 or 1, got {phase!r}")
    if int(shading_degree) not in (0, 1, 2):
        raise ValueError(f"shading_degree must be 0, 1 or 2, got {shading_degree}")
    if not (np.isfinite(blur_px) and blur_px > 0):
        raise ValueError(f"blur_px must be positive, got {blur_px}")
    band = max(BAND_SIGMAS * blur_px, BAND_MIN_PX) if band_px is None else float(band_px)
    if not (np.isfinite(band) and band > 0):
        raise ValueError(f"band_px must be positive, got {band_px}")
    h, w = img.shape
    if camera.image_size != (w, h):
        raise ValueError(
            f"image is {w}x{h} px but the camera is {camera.image_size[0]}x{camera.image_size[1]} px"
        )
    return img, T, band


def _region(
    board: Chessboard, camera: CameraModel, T: np.ndarray, w: int, h: int
) -> tuple[int, int, int, int]:
    """Pixels c0..c1-1, r0..r1-1 around the checkered area grown by 0.6 square, whose
    neighbours (for the local scale) are in the image."""
    s = board.square_mm
    grow = 0.6 * s
    extent = (-s - grow, -s - grow, board.cols * s + grow, board.rows * s + grow)
    try:
        uv = camera.project_rectangle(T, extent, samples=33)
    except ValueError:
        raise PhotometricError("the board reaches behind the camera") from None
    c0 = max(int(np.floor(uv[:, 0].min())), 1)
    c1 = min(int(np.ceil(uv[:, 0].max())) + 1, w - 1)
    r0 = max(int(np.floor(uv[:, 1].min())), 1)
    r1 = min(int(np.ceil(uv[:, 1].max())) + 1, h - 1)
    if c1 - c0 < 8 or r1 - r0 < 8:
        raise PhotometricError("the board is outside the image")
    return c0, r0, c1, r1


class _BoardPlane:
    """Board (X, Y) in float32 (1e-4 px is plenty to choose pixels) and w2 of pixels (u, v)."""

    def __init__(self, rm, T: np.ndarray, w: int):
        try:
            Hi = ray2board_homography(T)
        except ValueError as e:
            raise PhotometricError(str(e)) from None
        self.h32 = Hi.astype(np.float32)
        self.rm = rm
        self.w = w
        corr_x, corr_y = rm.correction_maps
        self.cxf, self.cyf = corr_x.ravel(), corr_y.ravel()

    def __call__(self, u_i, v_i):
        h32, rm = self.h32, self.rm
        flat = v_i * self.w + u_i
        rx = rm.px32[u_i] + self.cxf.take(flat)
        ry = rm.py32[v_i] + self.cyf.take(flat)
        w2 = h32[2, 0] * rx + h32[2, 1] * ry + h32[2, 2]
        iw = np.float32(1.0) / w2
        return (
            (h32[0, 0] * rx + h32[0, 1] * ry + h32[0, 2]) * iw,
            (h32[1, 0] * rx + h32[1, 1] * ry + h32[1, 2]) * iw,
            w2,
        )


def _outside(Z, n, isz, sf):
    """Distance (px) outside the checkered area along one axis (negative inside)."""
    return np.maximum(-sf - Z, Z - n * sf) * isz


@dataclass
class _Tiles:
    """The coarse pass: 4 x 4 tiles that may hold pixels near a line, and their candidate pixels.

    gx, gy: gradients of X and Y over the tile grid; isXc, isYc: 4 / |grad|, px/mm, per tile;
    ti, tj: the kept tiles' row and column; u_i, v_i: their pixels in the region; tile: the
    index (into ti, tj) of each pixel's tile.
    """

    gx: list
    gy: list
    isXc: np.ndarray
    isYc: np.ndarray
    ti: np.ndarray
    tj: np.ndarray
    u_i: np.ndarray
    v_i: np.ndarray
    tile: np.ndarray


def _coarse_tiles(plane, region, board: Chessboard, band: float) -> _Tiles:
    """Coarse pass on 4 x 4 tiles, sampled at one pixel of each (every pixel of a tile lies
    within 2.9 px of it): keep the tiles that may hold pixels near a line."""
    c0, r0, c1, r1 = region
    sf = np.float32(board.square_mm)
    cols, rows = board.cols, board.rows
    tu = np.arange(c0, c1, 4)
    tv = np.arange(r0, r1, 4)
    su = np.minimum(tu + 2, c1 - 1)
    sv = np.minimum(tv + 2, r1 - 1)
    Xc, Yc, w2c = plane(su[None, :], sv[:, None])
    gx = np.gradient(Xc) if min(Xc.shape) > 1 else None
    gy = np.gradient(Yc) if min(Yc.shape) > 1 else None
    if gx is None or gy is None:
        raise PhotometricError("the board is too small in the image")
    with np.errstate(divide="ignore", invalid="ignore"):
        isXc = np.float32(4.0) / np.sqrt(gx[0] ** 2 + gx[1] ** 2)
        isYc = np.float32(4.0) / np.sqrt(gy[0] ** 2 + gy[1] ** 2)
        reach = band + 3.0
        dXc = np.abs(Xc - np.clip(np.rint(Xc / sf), -1, cols) * sf) * isXc
        dYc = np.abs(Yc - np.clip(np.rint(Yc / sf), -1, rows) * sf) * isYc
        tiles = (
            ((dXc < reach) & (_outside(Yc, rows, isYc, sf) <= reach))
            | ((dYc < reach) & (_outside(Xc, cols, isXc, sf) <= reach))
        ) & (w2c > 0)
    ti, tj = np.nonzero(tiles)  # tile row, tile column
    off_v, off_u = (a.ravel() for a in np.meshgrid(np.arange(4), np.arange(4), indexing="ij"))
    v_i = (tv[ti][:, None] + off_v[None, :]).ravel()
    u_i = (tu[tj][:, None] + off_u[None, :]).ravel()
    tile = np.repeat(np.arange(ti.size), 16)
    inb = (v_i < r1) & (u_i < c1)
    return _Tiles(gx, gy, isXc, isYc, ti, tj, u_i[inb], v_i[inb], tile[inb])


@dataclass
class _Candidates:
    """The candidate pixels' board coordinates X, Y, their nearest lines kx, ky and distances
    to them dX, dY (px), and the selection ``sel`` near the edges."""

    X: np.ndarray
    Y: np.ndarray
    dX: np.ndarray
    dY: np.ndarray
    kx: np.ndarray
    ky: np.ndarray
    sel: np.ndarray


def _near_edges(plane, tl: _Tiles, board: Chessboard, band, blur_px, outer_edges, inner_only) -> _Candidates:
    """Fine selection of the candidate pixels: near one grid line (within the band), away
    from the corner zones, in front of the camera."""
    sf = np.float32(board.square_mm)
    cols, rows = board.cols, board.rows
    # Corner zones at least as wide as the band: every pixel kept is near one line only.
    cz = max(CORNER_SIGMAS * blur_px, band)
    isX = tl.isXc[tl.ti, tl.tj][tl.tile]
    isY = tl.isYc[tl.ti, tl.tj][tl.tile]
    X, Y, w2 = plane(tl.u_i, tl.v_i)
    with np.errstate(divide="ignore", invalid="ignore"):
        kx = np.clip(np.rint(X / sf), -1, cols)
        ky = np.clip(np.rint(Y / sf), -1, rows)
        dX = np.abs(X - kx * sf) * isX
        dY = np.abs(Y - ky * sf) * isY
        near_x = (dX < band) & (_outside(Y, rows, isY, sf) <= band)
        near_y = (dY < band) & (_outside(X, cols, isX, sf) <= band)
        if not outer_edges:
            near_x &= (kx > -1) & (kx < cols) & (_outside(Y, rows, isY, sf) < -band)
            near_y &= (ky > -1) & (ky < rows) & (_outside(X, cols, isX, sf) < -band)
        if inner_only:
            near_x &= (kx > -1) & (kx < cols) & (Y >= 0) & (Y <= (rows - 1) * sf)
            near_y &= (ky > -1) & (ky < rows) & (X >= 0) & (X <= (cols - 1) * sf)
        sel = (near_x | near_y) & ~((dX < cz) & (dY < cz)) & (w2 > 0)
    return _Candidates(X, Y, dX, dY, kx, ky, sel)


def _excluded(polygons, region, u_i, v_i) -> np.ndarray | None:
    """Which pixels lie inside the ``exclude`` polygons (None: no polygons)."""
    polys = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons]
    if not polys:
        return None
    c0, r0, c1, r1 = region
    m = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
    for p in polys:
        if p.shape[0] >= 3 and np.all(np.isfinite(p)):
            q = np.rint((p - [c0, r0]) * 16).astype(np.int32)
            cv2.fillPoly(m, [q], 1, lineType=cv2.LINE_8, shift=4)
    return m[v_i - r0, u_i - c0] != 0


def _usable(img, rm, region, tl: _Tiles, cand: _Candidates, saturation, exclude):
    """The indices of the selected pixels that are usable (not saturated, not black, inside
    the lens model's invertible field, outside ``exclude``), and their image values."""
    w = img.shape[1]
    sel = cand.sel
    vals = img.ravel().take(tl.v_i * w + tl.u_i)
    sat = np.iinfo(img.dtype).max if saturation is None else int(saturation)
    sel &= (vals < sat) & (vals > 0)
    # Only pixels whose rays are right: inside the field where the lens model is invertible.
    n_out = 0
    if not rm.covers_image:
        in_field = rm.valid_map.ravel().take(tl.v_i * w + tl.u_i)
        n_out = int(np.count_nonzero(sel & ~in_field))
        sel &= in_field
    inside = _excluded(exclude, region, tl.u_i, tl.v_i)
    if inside is not None:
        sel &= ~inside
    idx = np.flatnonzero(sel)
    n = idx.size
    if n < MIN_PIXELS:
        msg = f"only {n} usable pixels near the board's edges (at least {MIN_PIXELS})"
        if n_out:
            msg += f"; {n_out} lie beyond the lens model's invertible field: {rm.field.describe()}"
        raise PhotometricError(msg)
    return idx, vals[idx]


def _pixel_geometry(rm, tl: _Tiles, idx, region, shading_degree: int) -> dict:
    """Per kept pixel: its centre, its ray and the shading monomials (the
    :class:`PhotometricSetup` fields of the same names)."""
    ui, vi = tl.u_i[idx], tl.v_i[idx]
    u = ui.astype(np.float64)
    v = vi.astype(np.float64)
    c0, r0, c1, r1 = region
    u0, v0 = 0.5 * (c0 + c1 - 1), 0.5 * (r0 + r1 - 1)
    L = 0.5 * max(c1 - c0, r1 - r0, 2)
    corr_x, corr_y = rm.correction_maps
    return dict(
        rx=rm.px[ui] + corr_x[vi, ui],
        ry=rm.py[vi] + corr_y[vi, ui],
        u=u,
        v=v,
        basis=_monomials((u - u0) / L, (v - v0) / L, shading_degree),
        centre=(u0, v0),
        length=L,
    )


def _edge_geometry(tl: _Tiles, cand: _Candidates, idx, board: Chessboard, phase: int) -> dict:
    """Per kept pixel: its lines, the jumps across them, the black side, the local scale and
    the edge's direction (the :class:`PhotometricSetup` fields of the same names)."""
    sf = np.float32(board.square_mm)
    cols, rows = board.cols, board.rows
    X, Y, dX, dY = cand.X[idx], cand.Y[idx], cand.dX[idx], cand.dY[idx]
    kxs = cand.kx[idx].astype(np.int64)
    kys = cand.ky[idx].astype(np.int64)
    # Local scale |grad_p X|, |grad_p Y| (mm/px) and edge directions: those of the pixel's tile
    # (they vary by ~0.1 % over 4 px; they set the blur's width, not the edges' positions).
    tk = (tl.ti[tl.tile[idx]], tl.tj[tl.tile[idx]])
    gXu, gXv = tl.gx[1][tk].astype(np.float64), tl.gx[0][tk].astype(np.float64)
    gYu, gYv = tl.gy[1][tk].astype(np.float64), tl.gy[0][tk].astype(np.float64)
    sXk = 1.0 / tl.isXc[tk].astype(np.float64)
    sYk = 1.0 / tl.isYc[tk].astype(np.float64)
    fx0, fx1, gx0, gx1 = _jumps(kxs, cols, phase)
    fy0, fy1, gy0, gy1 = _jumps(kys, rows)
    # Which side of its line is black (the squares either side: (k - 1, j) and (k, j)).
    on_x = dX <= dY
    jx = np.floor(Y / sf).astype(np.int64)  # square row of an X-edge pixel
    iy = np.floor(X / sf).astype(np.int64)  # square column of a Y-edge pixel
    # Direction of the edge's normal in the image (the gradient of X or Y).
    nu = np.where(on_x, gXu, gYu)
    nv = np.where(on_x, gXv, gYv)
    n2 = nu * nu + nv * nv
    s = board.square_mm
    return dict(
        line_x=kxs * s,
        line_y=kys * s,
        isx=1.0 / sXk,
        isy=1.0 / sYk,
        bsx=np.where(on_x, _black_side(kxs, jx, cols, rows, phase), 0.0),
        bsy=np.where(on_x, 0.0, _black_side(kys, iy, rows, cols, phase)),
        c2=(nu * nu - nv * nv) / n2,
        s2=2.0 * nu * nv / n2,
        fx0=fx0,
        fx1=fx1,
        gx0=gx0,
        gx1=gx1,
        fy0=fy0,
        fy1=fy1,
        gy0=gy0,
        gy1=gy1,
    )


def prepare_pixels(
    image,
    board: Chessboard,
    camera: CameraModel,
    board2cam,
    *,
    band_px: float | None = None,
    blur_px: float = 1.0,
    shading_degree: int = 2,
    outer_edges: bool = True,
    exclude=(),
    saturation: int | None = None,
    phase: int = 0,
    inner_only: bool = False,
) -> PhotometricSetup:
    """Select the pixels of a board for the photometric fit at a starting pose.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8 or uint16
    board : Chessboard
    camera : CameraModel
    board2cam : array_like, shape (4, 4), mm
        Starting pose (e.g. the corner-based one).
    band_px : float, optional
        Pixels farther than this from every grid line are left out, px (default
        :data:`BAND_SIGMAS` ``blur_px``, at least :data:`BAND_MIN_PX`: beyond it an edge's
        gradient is below 5 % of its peak and the pixels hold under 0.5 % of the information
        on its position).
    blur_px : float
        Expected effective blur sigma, px (sets the default band and the corner
        zones left out: 3 sigma around every corner).
    shading_degree : int
        Degree (0, 1 or 2) of the black-level and contrast polynomials.
    outer_edges : bool
        Also use the outer edges of the checkered area against the white margin (the
        margin must then be white over at least ``band_px``).
    exclude : sequence of array_like, shape (k, 2)
        Polygons (px) whose pixels are not used (another board, a known obstruction).
    saturation : int, optional
        Pixels at or above this value are left out (default the dtype's maximum), and so
        are pixels at 0.
    phase : {0, 1}
        Colour phase of the board: square (i, j) is black when i + j + phase is even
        (:attr:`~stiffmap.vision.detection.BoardDetection.phase`).
    inner_only : bool
        Only the edges between the inner corners (the inner squares' sides): what every
        printed chessboard has, whatever its outer squares are (cut short, as on OpenCV's
        stereo samples, or framed by a margin that is not white).

    Returns
    -------
    PhotometricSetup

    Raises
    ------
    PhotometricError
        The board is (mostly) outside the image, or too few pixels are usable (only
        pixels inside the field where the lens model is invertible are, see
        :class:`~stiffmap.camera.InvertibleField`).
    """
    img, T, band = _check_inputs(image, board, board2cam, camera, band_px, blur_px, shading_degree, phase)
    h, w = img.shape
    region = _region(board, camera, T, w, h)
    rm = pixel_rays(camera)
    plane = _BoardPlane(rm, T, w)
    tiles = _coarse_tiles(plane, region, board, band)
    cand = _near_edges(plane, tiles, board, band, blur_px, outer_edges, inner_only)
    idx, vals = _usable(img, rm, region, tiles, cand, saturation, exclude)
    return PhotometricSetup(
        board=board,
        values=vals.astype(np.float64),
        **_pixel_geometry(rm, tiles, idx, region, int(shading_degree)),
        **_edge_geometry(tiles, cand, idx, board, phase),
        region=region,
    )
