"""Render planar targets through a distorted pinhole camera, with exact anti-aliasing.

Geometry (``docs/simulation.md``). Each pixel integrates the scene over its
square (box filter, 100 % fill factor): pixel ``[row, col]`` covers
[col - 1/2, col + 1/2] x [row - 1/2, row + 1/2] (pixel centres at integer
coordinates, ``docs/conventions.md``). The map from the image to a board plane
is computed exactly at every pixel centre -- the ray of the pixel (the
camera's distortion inverted, :meth:`CameraModel.rays_from_pixels`) met with
the board plane -- and linearised over the pixel by its exact Jacobian. The
board's print is a grid of axis-aligned cells (:mod:`.texture`), so the
pixel's preimage is a parallelogram and the light it gathers is

    sum over cells c of  area(parallelogram intersect c) / area(parallelogram) * value(c),

computed in closed form: a pixel away from every line of the grid takes its
cell's value; a pixel crossed by one line gets the area cut off by a straight
line from a unit square (a piecewise-quadratic formula); any other pixel is
clipped polygon by polygon (Sutherland-Hodgman). The linearisation is the only
approximation; it moves an edge by (pixel size)^2 times the curvature of the
map, below 1e-4 px for the reference camera.

Photometry (:class:`Photometry`) then turns the reflectance image into an
8-bit image: illumination gain and black level, cos^4 vignetting, Gaussian
defocus, shot and read noise from a seeded generator, rounding.

The undistorted rays of the pixel grid are the same for every image of a
camera; they come from the camera's ray cache (:func:`stiffmap.camera.pixel_rays`,
shared with the photometric pose refinement).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..camera import CameraModel, pixel_rays
from ..geometry import as_transform
from ..targets import CharucoBoard, Chessboard
from .texture import BoardTexture, texture_from_board

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

# -------------------------------------------------------------------- scene


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


@dataclass(frozen=True)
class Photometry:
    """From scene reflectance to 8-bit pixel values.

    The mean value of a pixel seeing reflectance rho is
    ``offset_dn + 255 gain V rho`` digital numbers (DN), V the vignetting;
    its noise is Gaussian with variance ``read_noise_dn^2 + shot_dn_per_e * signal``
    (photon shot noise, signal = the mean above the black level, in DN).

    Attributes
    ----------
    gain : float
        Fraction of full scale reached by reflectance 1 at the image centre.
    offset_dn : float
        Black level, DN.
    read_noise_dn : float
        Read noise, 1 sigma, DN.
    shot_dn_per_e : float
        Conversion gain, DN per photo-electron (0: no shot noise).
    blur_px : float
        Gaussian blur of the optics, 1 sigma, px: the lens's point-spread
        function plus any defocus (default 0.8 px, a sharp lens on a sensor
        with pixels of a few micrometres; 0: an ideal step edge).
    vignetting : float
        0..1: blend of the cos^4 law of the angle between a pixel's line of sight and
        the optical axis (pinhole angle, distortion neglected; 1: full cos^4 fall-off).
    background : float
        Reflectance of the scene behind the targets.
    clutter : bool
        Random shapes (seeded) in the background instead of a plain one.
    colour : bool
        A colour camera: a Bayer sensor (R at even rows and columns, noise per
        photosite) demosaiced by OpenCV (edge-aware) into BGR, instead of grey.
    white_balance : (float, float, float)
        Gains of the B, G and R photosites of a colour camera.
    """

    gain: float = 0.8
    offset_dn: float = 6.0
    read_noise_dn: float = 0.8
    shot_dn_per_e: float = 0.04
    blur_px: float = 0.8
    vignetting: float = 0.3
    background: float = 0.35
    clutter: bool = False
    colour: bool = False
    white_balance: tuple[float, float, float] = (0.92, 1.0, 0.88)

    def __post_init__(self) -> None:
        for k in (
            "gain",
            "offset_dn",
            "read_noise_dn",
            "shot_dn_per_e",
            "blur_px",
            "vignetting",
            "background",
        ):
            v = float(getattr(self, k))
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"Photometry.{k} must be a finite number >= 0, got {getattr(self, k)!r}")
            object.__setattr__(self, k, v)
        if self.vignetting > 1 or self.background > 1:
            raise ValueError("Photometry.vignetting and .background must be in [0, 1]")
        wb = tuple(float(x) for x in self.white_balance)
        if len(wb) != 3 or not all(np.isfinite(x) and x > 0 for x in wb):
            raise ValueError(
                f"white_balance must be three positive gains (B, G, R), got {self.white_balance!r}"
            )
        object.__setattr__(self, "white_balance", wb)

    @classmethod
    def noise_free(cls, **kw) -> Photometry:
        """No read or shot noise and no vignetting (the optics blur stays): only 8-bit rounding.

        Keyword arguments override fields, e.g. ``Photometry.noise_free(blur_px=0.0)``.
        """
        base = {"read_noise_dn": 0.0, "shot_dn_per_e": 0.0, "vignetting": 0.0}
        base.update(kw)
        return cls(**base)


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


# ----------------------------------------------------------- coverage maths


def half_plane_area(a, b, c) -> np.ndarray:
    """Area of {(s, t) in [-1/2, 1/2]^2 : a s + b t >= c} (closed form).

    This is P(aU + bV >= c) for independent U, V uniform on [-1/2, 1/2]: the
    density of aU + bV is a trapezoid, so the area is piecewise quadratic in c.

    Parameters
    ----------
    a, b, c : array_like (broadcast)
        Line coefficients; (a, b) must not both be 0.

    Returns
    -------
    ndarray
        Area in [0, 1].
    """
    a = np.abs(np.asarray(a, dtype=np.float64))
    b = np.abs(np.asarray(b, dtype=np.float64))
    c = np.asarray(c, dtype=np.float64)
    P = np.maximum(a, b)
    Q = np.minimum(a, b)
    h1 = 0.5 * (P - Q)
    h2 = 0.5 * (P + Q)
    tt = np.abs(c)
    # Area on the far side of |c| (the smaller part), G(-|c|) for the CDF G of aU + bV.
    tail = np.where(
        tt >= h2,
        0.0,
        np.where(
            tt > h1, (h2 - tt) ** 2 / (2.0 * np.maximum(P * Q, 1e-300)), 0.5 - tt / np.maximum(P, 1e-300)
        ),
    )
    return np.where(c >= 0, tail, 1.0 - tail)


def _clip_axis(px, py, n, coord: int, bound, keep_ge: bool):
    """Clip convex polygons (rows of px, py with n vertices) to x >= bound (or <=, or y)."""
    val = px if coord == 0 else py
    s = (val - bound[:, None]) if keep_ge else (bound[:, None] - val)
    M = px.shape[1]
    idx = np.arange(M)[None, :]
    valid = idx < n[:, None]
    nxt = np.where(idx + 1 < n[:, None], idx + 1, 0)
    qx = np.take_along_axis(px, nxt, 1)
    qy = np.take_along_axis(py, nxt, 1)
    qs = np.take_along_axis(s, nxt, 1)
    inside = s >= 0
    emit_v = valid & inside
    cross = valid & (inside != (qs >= 0))
    den = np.where(cross, s - qs, 1.0)
    t = np.where(cross, s / den, 0.0)
    ix = px + t * (qx - px)
    iy = py + t * (qy - py)
    ox = np.stack([px, ix], axis=2).reshape(len(px), 2 * M)
    oy = np.stack([py, iy], axis=2).reshape(len(px), 2 * M)
    ok = np.stack([emit_v, cross], axis=2).reshape(len(px), 2 * M)
    order = np.argsort(~ok, axis=1, kind="stable")
    n_new = ok.sum(axis=1)
    m_new = max(int(n_new.max(initial=0)), 1)
    order = order[:, :m_new]
    return np.take_along_axis(ox, order, 1), np.take_along_axis(oy, order, 1), n_new


def _polygon_area(px, py, n) -> np.ndarray:
    M = px.shape[1]
    idx = np.arange(M)[None, :]
    valid = idx < n[:, None]
    nxt = np.where(idx + 1 < n[:, None], idx + 1, 0)
    qx = np.take_along_axis(px, nxt, 1)
    qy = np.take_along_axis(py, nxt, 1)
    cross = np.where(valid, px * qy - qx * py, 0.0)
    return 0.5 * np.abs(cross.sum(axis=1))


_BIG = 1e9  # mm: stands for the unbounded outer cells


def _rect_fraction(J, x0, y0, xl, xr, yl, yr) -> np.ndarray:
    """Fraction of each pixel's parallelogram inside the cell [xl, xr] x [yl, yr] (board mm)."""
    Jxu, Jxv, Jyu, Jyv = J
    su = np.array([-0.5, 0.5, 0.5, -0.5])
    sv = np.array([-0.5, -0.5, 0.5, 0.5])
    px = Jxu[:, None] * su + Jxv[:, None] * sv
    py = Jyu[:, None] * su + Jyv[:, None] * sv
    n = np.full(len(px), 4)
    px, py, n = _clip_axis(px, py, n, 0, xl - x0, True)
    px, py, n = _clip_axis(px, py, n, 0, xr - x0, False)
    px, py, n = _clip_axis(px, py, n, 1, yl - y0, True)
    px, py, n = _clip_axis(px, py, n, 1, yr - y0, False)
    det = np.abs(Jxu * Jyv - Jxv * Jyu)
    return _polygon_area(px, py, n) / det


def _bounds(lines: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper line of cells ``idx`` (the outer cells are unbounded)."""
    ext = np.concatenate([[-_BIG], lines, [_BIG]])
    return ext[idx], ext[idx + 1]


# ---------------------------------------------------------------- rendering


def _target_bbox(camera: CameraModel, tex: BoardTexture, board2cam: np.ndarray, roi) -> tuple | None:
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


def _board_coords(rx, ry, board2cam):
    """Board-plane coordinates (mm) of the rays (rx, ry, 1), and where the ray meets the plane."""
    R = board2cam[:3, :3]
    t = board2cam[:3, 3]
    nrm = R[:, 2]
    nd = nrm[0] * rx + nrm[1] * ry + nrm[2]
    ok = nd > 1e-9
    lam = float(nrm @ t) / np.where(ok, nd, 1.0)
    # Point lam (rx, ry, 1) - t in the board frame: R^T (lam d - t).
    x = lam * (R[0, 0] * rx + R[1, 0] * ry + R[2, 0]) - R[:, 0] @ t
    y = lam * (R[0, 1] * rx + R[1, 1] * ry + R[2, 1]) - R[:, 1] @ t
    return x, y, ok


def _render_block(rx, ry, tex: BoardTexture, board2cam: np.ndarray):
    """Premultiplied reflectance and coverage of one target over a block of pixels.

    ``rx``, ``ry`` hold the rays of the block with a one-pixel halo, shape
    (h + 2, w + 2); the Jacobian of the map pixel -> board at each pixel is the
    central difference over the halo (exact to ~1e-7 relative: the map's third
    derivative is tiny over one pixel). Returns two arrays of shape (h * w,).
    """
    X, Y, OK = _board_coords(rx, ry, board2cam)
    x = X[1:-1, 1:-1].ravel()
    y = Y[1:-1, 1:-1].ravel()
    Jxu = (0.5 * (X[1:-1, 2:] - X[1:-1, :-2])).ravel()
    Jxv = (0.5 * (X[2:, 1:-1] - X[:-2, 1:-1])).ravel()
    Jyu = (0.5 * (Y[1:-1, 2:] - Y[1:-1, :-2])).ravel()
    Jyv = (0.5 * (Y[2:, 1:-1] - Y[:-2, 1:-1])).ravel()
    # A pixel whose ray or a neighbour's misses the plane (a grazing view) sees no board.
    ok = (OK[1:-1, 1:-1] & OK[1:-1, 2:] & OK[1:-1, :-2] & OK[2:, 1:-1] & OK[:-2, 1:-1]).ravel()
    hx = 0.5 * (np.abs(Jxu) + np.abs(Jxv))
    hy = 0.5 * (np.abs(Jyu) + np.abs(Jyv))
    x = np.where(ok, x, -_BIG / 2)
    y = np.where(ok, y, -_BIG / 2)
    xs, ys = tex.xs, tex.ys
    xe = np.concatenate([[-_BIG], xs, [_BIG]])
    ye = np.concatenate([[-_BIG], ys, [_BIG]])
    pre = tex.reflectance * tex.alpha  # premultiplied
    A = tex.alpha
    # Cell of the pixel centre; the pixel is uniform when its footprint stays in that cell.
    ic = np.searchsorted(xs, x, side="right")
    jc = np.searchsorted(ys, y, side="right")
    col = pre[ic, jc]
    cov = A[ic, jc]
    edge = (x - hx <= xe[ic]) | (x + hx >= xe[ic + 1]) | (y - hy <= ye[jc]) | (y + hy >= ye[jc + 1])
    e = np.flatnonzero(edge & ok)
    if e.size:
        xq, yq = x[e], y[e]
        hxq, hyq = hx[e], hy[e]
        J = (Jxu[e], Jxv[e], Jyu[e], Jyv[e])
        ilo = np.searchsorted(xs, xq - hxq, side="right")
        nx = np.searchsorted(xs, xq + hxq, side="right") - ilo
        jlo = np.searchsorted(ys, yq - hyq, side="right")
        ny = np.searchsorted(ys, yq + hyq, side="right") - jlo
        ce = np.empty(e.size)
        ae = np.empty(e.size)
        m0 = (nx == 0) & (ny == 0)  # touches a line only at the footprint's bounding box
        ce[m0] = pre[ilo[m0], jlo[m0]]
        ae[m0] = A[ilo[m0], jlo[m0]]
        # One x-line: the area beyond a straight line.
        m = (nx == 1) & (ny == 0)
        i, j = ilo[m], jlo[m]
        H = half_plane_area(J[0][m], J[1][m], xs[i] - xq[m])
        ce[m] = (1 - H) * pre[i, j] + H * pre[i + 1, j]
        ae[m] = (1 - H) * A[i, j] + H * A[i + 1, j]
        m1 = m
        m = (nx == 0) & (ny == 1)
        i, j = ilo[m], jlo[m]
        H = half_plane_area(J[2][m], J[3][m], ys[j] - yq[m])
        ce[m] = (1 - H) * pre[i, j] + H * pre[i, j + 1]
        ae[m] = (1 - H) * A[i, j] + H * A[i, j + 1]
        # Anything else: clip the footprint with every cell it may meet.
        g = np.flatnonzero(~(m0 | m1 | m))
        if g.size:
            ce[g], ae[g] = _clipped_cells(
                tuple(v[g] for v in J), xq[g], yq[g], ilo[g], nx[g], jlo[g], ny[g], xs, ys, pre, A
            )
        col[e] = ce
        cov[e] = ae
    col[~ok] = 0.0
    cov[~ok] = 0.0
    return col, cov


#: Above this many cells in one pixel's footprint (a board seen nearly edge-on, squares far
#: below a pixel) the pixel is averaged over 16 x 16 affine sub-samples instead.
_MAX_CELLS = 36


def _clipped_cells(J, x, y, ilo, nx, jlo, ny, xs, ys, pre, A):
    """Exact coverage of footprints that meet several lines (polygon clipping per cell)."""
    cg = np.zeros(x.size)
    ag = np.zeros(x.size)
    many = (nx + 1) * (ny + 1) > _MAX_CELLS
    if np.any(many):
        k = np.flatnonzero(many)
        off = (np.arange(16) + 0.5) / 16 - 0.5
        su, sv = (a.ravel() for a in np.meshgrid(off, off))
        bx = x[k, None] + J[0][k, None] * su + J[1][k, None] * sv
        by = y[k, None] + J[2][k, None] * su + J[3][k, None] * sv
        ix = np.searchsorted(xs, bx, side="right")
        iy = np.searchsorted(ys, by, side="right")
        cg[k] = pre[ix, iy].mean(axis=1)
        ag[k] = A[ix, iy].mean(axis=1)
    few = ~many
    if not np.any(few):
        return cg, ag
    nxf, nyf = np.where(few, nx, -1), np.where(few, ny, -1)
    for da in range(int(nxf.max()) + 1):
        for db in range(int(nyf.max()) + 1):
            sel = np.flatnonzero((da <= nxf) & (db <= nyf))
            if not sel.size:
                continue
            ci = ilo[sel] + da
            cj = jlo[sel] + db
            xl, xr = _bounds(xs, ci)
            yl, yr = _bounds(ys, cj)
            f = _rect_fraction(tuple(v[sel] for v in J), x[sel], y[sel], xl, xr, yl, yr)
            cg[sel] += f * pre[ci, cj]
            ag[sel] += f * A[ci, cj]
    return cg, ag


def render_reflectance(
    camera: CameraModel,
    targets,
    *,
    background=0.35,
    roi: tuple[int, int, int, int] | None = None,
    chunk_rows: int = 128,
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

    Returns
    -------
    ndarray, shape (r1 - r0, c1 - c0), float64
        Reflectance in [0, 1].
    """
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    targets = list(targets)
    for tg in targets:
        if not isinstance(tg, Target):
            raise ValueError(f"targets must be Target objects, got {type(tg).__name__}")
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
    rm = pixel_rays(camera)
    # Painter's order: the farthest target first.
    order = sorted(targets, key=lambda tg: -float(np.linalg.norm(tg.board2cam[:3, 3])))
    for tg in order:
        T = tg.board2cam
        if float(T[:3, 2] @ T[:3, 3]) <= 0:
            raise ValueError(
                f"target {tg.name or '(unnamed)'} is seen from behind: "
                "its z axis must point away from the camera"
            )
        tex = tg.texture()
        bb = _target_bbox(camera, tex, T, (c0, r0, c1, r1))
        if bb is None:
            continue
        br0, br1, bc0, bc1 = bb
        cols = np.arange(bc0 - 1, bc1 + 1, dtype=np.float64)  # with a one-pixel halo
        for rs in range(br0, br1, chunk_rows):
            re = min(rs + chunk_rows, br1)
            rows = np.arange(rs - 1, re + 1, dtype=np.float64)
            colv, covv = _render_block(*rm.block(rows, cols), tex, T)
            sub = img[rs - r0 : re - r0, bc0 - c0 : bc1 - c0]
            sub[...] = colv.reshape(sub.shape) + (1.0 - covv.reshape(sub.shape)) * sub
    return img


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


# -------------------------------------------------------------- photometry

_VIGNETTES: OrderedDict = OrderedDict()


def _cos4(camera: CameraModel) -> np.ndarray:
    key = camera.key
    v = _VIGNETTES.get(key)
    if v is None:
        w, h = camera.image_size
        x = ((np.arange(w, dtype=np.float32) - camera.cx) / camera.fx)[None, :]
        y = ((np.arange(h, dtype=np.float32) - camera.cy) / camera.fy)[:, None]
        v = (1.0 / (1.0 + x * x + y * y)) ** 2
        v = v.astype(np.float32)
        v.setflags(write=False)
        _VIGNETTES[key] = v
        while len(_VIGNETTES) > 4:
            _VIGNETTES.popitem(last=False)
    return v


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


#: Supersampling of the targets' regions for the optics blur (see :func:`blurred_reflectance`).
BLUR_SUPERSAMPLE = 2


def _supersampled_camera(camera: CameraModel, ss: int) -> CameraModel:
    """The same camera with ``ss`` x ``ss`` pixels per pixel: pixel u spans sub-pixels ss*u .. ss*u+ss-1."""
    w, h = camera.image_size
    return CameraModel(
        (w * ss, h * ss),
        camera.fx * ss,
        camera.fy * ss,
        camera.cx * ss + (ss - 1) / 2,
        camera.cy * ss + (ss - 1) / 2,
        camera.dist,
    )


def blurred_reflectance(
    camera: CameraModel,
    targets,
    *,
    background=0.35,
    blur_px: float,
    supersample: int = BLUR_SUPERSAMPLE,
) -> np.ndarray:
    """Scene reflectance through the optics: a Gaussian PSF, then integration over each pixel.

    What a pixel records is the scene convolved with the lens's point-spread
    function and integrated over the pixel's area (box). Blurring the exact
    box-filtered image with a Gaussian kernel sampled at whole pixels is not the
    same near sharp edges: the error depends on where an edge falls within its
    pixel, and with board edges nearly parallel to the pixel grid it moved
    estimated board depths by tens of micrometres from image to image. Here the
    targets' regions are rendered at ``supersample`` x ``supersample`` sub-pixels
    (exact area coverage), blurred there (the kernel is then well sampled), and
    averaged back to pixels; the smooth background keeps the one-pixel blur.
    At 2x the board depths are within about 2 um of a 4x rendering.

    Parameters
    ----------
    camera : CameraModel
    targets : sequence of Target
    background : float or ndarray, shape (h, w)
    blur_px : float
        PSF sigma, px (0: no blur, the box-filtered image).
    supersample : int
        Sub-pixels per pixel and axis in the targets' regions (1: sampled kernel only).

    Returns
    -------
    ndarray, shape (h, w), float32
    """
    targets = list(targets)
    ss = int(supersample)
    if blur_px <= 0 or ss <= 1:
        refl = render_reflectance(camera, targets, background=background).astype(np.float32)
        if blur_px <= 0:
            return refl
        return cv2.GaussianBlur(refl, (0, 0), blur_px, borderType=cv2.BORDER_REPLICATE)
    # The targets are drawn only at the fine resolution below; the background alone at 1x.
    w, h = camera.image_size
    if np.isscalar(background):
        out = np.full((h, w), float(background), dtype=np.float32)
    else:
        out = cv2.GaussianBlur(
            np.asarray(background, dtype=np.float32), (0, 0), blur_px, borderType=cv2.BORDER_REPLICATE
        )
    cam_s = _supersampled_camera(camera, ss)
    m = int(np.ceil(4 * blur_px)) + 2  # beyond 4 sigma the PSF is negligible
    for tg in targets:
        bb = _target_bbox(camera, tg.texture(), tg.board2cam, (0, 0, w, h))
        if bb is None:
            continue
        r0, r1, c0, c1 = bb
        R0, R1, C0, C1 = max(r0 - 2 * m, 0), min(r1 + 2 * m, h), max(c0 - 2 * m, 0), min(c1 + 2 * m, w)
        if np.isscalar(background):
            bg = float(background)
        else:
            bg = np.repeat(np.repeat(np.asarray(background)[R0:R1, C0:C1], ss, axis=0), ss, axis=1)
        fine = render_reflectance(cam_s, targets, background=bg, roi=(C0 * ss, R0 * ss, C1 * ss, R1 * ss))
        fine = cv2.GaussianBlur(
            fine.astype(np.float32), (0, 0), blur_px * ss, borderType=cv2.BORDER_REPLICATE
        )
        coarse = fine.reshape(R1 - R0, ss, C1 - C0, ss).mean(axis=(1, 3))
        # Keep the part at least m pixels inside the rendered area (the blur there saw no border).
        i0, i1, j0, j1 = max(r0 - m, 0), min(r1 + m, h), max(c0 - m, 0), min(c1 + m, w)
        out[i0:i1, j0:j1] = coarse[i0 - R0 : i1 - R0, j0 - C0 : j1 - C0]
    return out


def apply_photometry(
    reflectance: np.ndarray,
    camera: CameraModel,
    photometry: Photometry,
    rng: np.random.Generator | None = None,
    *,
    blurred: bool = False,
) -> np.ndarray:
    """8-bit image from a full-frame reflectance image (see :class:`Photometry`).

    Parameters
    ----------
    reflectance : ndarray, shape (h, w)
        As from :func:`render_reflectance` over the whole image.
    camera : CameraModel
    photometry : Photometry
    rng : numpy Generator, optional
        The noise source (seeded by the caller); needed when the photometry has noise.
    blurred : bool
        The reflectance already went through the optics (:func:`blurred_reflectance`);
        otherwise it is blurred here with a sampled Gaussian kernel, which is exact
        only for smooth images.

    Returns
    -------
    ndarray of uint8, shape (h, w) or (h, w, 3)
    """
    w, h = camera.image_size
    img = np.asarray(reflectance, dtype=np.float32)
    if img.shape != (h, w):
        raise ValueError(f"reflectance must have shape ({h}, {w}), got {img.shape}")
    ph = photometry
    if ph.blur_px > 0 and not blurred:
        img = cv2.GaussianBlur(img, (0, 0), ph.blur_px, borderType=cv2.BORDER_REPLICATE)
    sig = img * np.float32(255.0 * ph.gain)
    if ph.vignetting > 0:
        sig *= np.float32(1.0 - ph.vignetting) + np.float32(ph.vignetting) * _cos4(camera)
    if ph.colour:
        # A Bayer sensor: one colour filter per pixel, R at even rows and columns.
        b, g, r = (np.float32(x) for x in ph.white_balance)
        sig[0::2, 0::2] *= r
        sig[0::2, 1::2] *= g
        sig[1::2, 0::2] *= g
        sig[1::2, 1::2] *= b
    if ph.read_noise_dn > 0 or ph.shot_dn_per_e > 0:
        if rng is None:
            raise ValueError("apply_photometry needs a random generator (rng) when the photometry has noise")
        sd = np.sqrt(np.float32(ph.read_noise_dn**2) + np.float32(ph.shot_dn_per_e) * sig)
        sig = sig + sd * rng.standard_normal(sig.shape, dtype=np.float32)
    sig += np.float32(ph.offset_dn)
    raw = np.clip(np.rint(sig), 0, 255).astype(np.uint8)
    if ph.colour:
        return cv2.cvtColor(raw, cv2.COLOR_BayerBG2BGR_EA)
    return raw


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
