"""Exact area coverage: the light a pixel gathers from a board print of axis-aligned cells.

Each pixel integrates the scene over its square (box filter, 100 % fill factor): pixel
``[row, col]`` covers [col - 1/2, col + 1/2] x [row - 1/2, row + 1/2] (pixel centres at
integer coordinates, ``docs/conventions.md``). The map from the image to a board plane
is computed exactly at every pixel centre -- the ray of the pixel met with the board
plane (:func:`board_coords`) -- and linearised over the pixel by its Jacobian. The
board's print is a grid of axis-aligned cells (:mod:`.texture`), so the pixel's preimage
is a parallelogram and the light it gathers is

    sum over cells c of  area(parallelogram intersect c) / area(parallelogram) * value(c),

computed in closed form (:func:`render_block`): a pixel away from every line of the grid
takes its cell's value; a pixel crossed by one line gets the area cut off by a straight
line from a unit square (:func:`half_plane_area`, a piecewise-quadratic formula); any
other pixel is clipped polygon by polygon (Sutherland-Hodgman). The linearisation is the
only approximation; it moves an edge by (pixel size)^2 times the curvature of the map,
below 1e-4 px for the reference camera.
"""

from __future__ import annotations

import numpy as np

from .texture import BoardTexture

__all__ = ["board_coords", "half_plane_area", "render_block", "render_block_tiled", "UNIFORM_TILE_PX"]


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


def board_coords(rx, ry, board2cam):
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


def render_block(rx, ry, tex: BoardTexture, board2cam: np.ndarray):
    """Premultiplied reflectance and coverage of one target over a block of pixels.

    ``rx``, ``ry`` hold the rays of the block with a one-pixel halo, shape
    (h + 2, w + 2); the Jacobian of the map pixel -> board at each pixel is the
    central difference over the halo (exact to ~1e-7 relative: the map's third
    derivative is tiny over one pixel). Returns two arrays of shape (h * w,).
    """
    X, Y, OK = board_coords(rx, ry, board2cam)
    x = X[1:-1, 1:-1].ravel()
    y = Y[1:-1, 1:-1].ravel()
    Jxu = (0.5 * (X[1:-1, 2:] - X[1:-1, :-2])).ravel()
    Jxv = (0.5 * (X[2:, 1:-1] - X[:-2, 1:-1])).ravel()
    Jyu = (0.5 * (Y[1:-1, 2:] - Y[1:-1, :-2])).ravel()
    Jyv = (0.5 * (Y[2:, 1:-1] - Y[:-2, 1:-1])).ravel()
    # A pixel whose ray or a neighbour's misses the plane (a grazing view) sees no board.
    ok = (OK[1:-1, 1:-1] & OK[1:-1, 2:] & OK[1:-1, :-2] & OK[2:, 1:-1] & OK[:-2, 1:-1]).ravel()
    return _shade(x, y, (Jxu, Jxv, Jyu, Jyv), ok, tex)


def _shade(x, y, J, ok, tex: BoardTexture):
    """Premultiplied reflectance and coverage of pixels at board points (x, y) with Jacobians
    J = (Jxu, Jxv, Jyu, Jyv) (1-D arrays; ``ok``: the pixel sees the plane)."""
    Jxu, Jxv, Jyu, Jyv = J
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


#: Side of the tiles of :func:`render_block_tiled`, px.
UNIFORM_TILE_PX = 4
#: A tile's board points may leave the box of its corners' by this share of the box's size
#: (the curvature of the map pixel -> board: at most 0.04 % measured over 8-px tiles, boards
#: tilted up to 85 degrees through a lens with k1 = -0.32; 4e-4 % with the reference camera).
_TILE_BEND = 0.05
#: A tile whose corners' rays meet the board plane at a smaller cosine-like factor than this is
#: computed pixel by pixel (a grazing view).
_TILE_MIN_ND = 0.05


def render_block_tiled(rx, ry, tex: BoardTexture, board2cam: np.ndarray, tile: int = UNIFORM_TILE_PX):
    """:func:`render_block`'s result, bit for bit, without working out every pixel of an area
    that sees one cell of the print.

    The block is cut into tiles of ``tile`` x ``tile`` pixels and the map pixel -> board is
    computed at the tiles' corner pixels only. A tile whose board points stay, with room to
    spare, inside one cell -- the box of its corners' board points, widened by
    :data:`_TILE_BEND` of its size (the map's curvature) and by the largest pixel footprint
    (its half-widths from the corners' differences, 5 % more), strictly between two lines
    of the grid in x and in y -- holds pixels that :func:`render_block` gives that cell's
    value and opacity (a lookup, no arithmetic): they take it here too. The other pixels are
    computed by :func:`render_block`'s formulas, from the same rays, one by one (their
    neighbours' board points for the Jacobian). A board seen nearly edge-on (a corner's ray
    meeting the plane at less than :data:`_TILE_MIN_ND`) is computed pixel by pixel.

    Parameters
    ----------
    rx, ry : ndarray, shape (h + 2, w + 2)
        Rays of the block with a one-pixel halo, as for :func:`render_block`.
    tex : BoardTexture
    board2cam : ndarray, shape (4, 4), mm
    tile : int
        Tile side, px (>= 2).

    Returns
    -------
    col, cov : ndarray, shape (h * w,)
    """
    H, W = rx.shape
    h, w = H - 2, W - 2
    tile = int(tile)
    if tile < 2 or h < 2 * tile or w < 2 * tile:
        return render_block(rx, ry, tex, board2cam)
    uniform, cx, cy = _uniform_tiles(rx, ry, tex, board2cam, tile, h, w)
    pre = tex.reflectance * tex.alpha
    nv, nu = uniform.shape
    rows_per = np.full(nv, tile)
    rows_per[-1] = h - tile * (nv - 1)
    cols_per = np.full(nu, tile)
    cols_per[-1] = w - tile * (nu - 1)

    def spread(T):
        return np.repeat(np.repeat(T, rows_per, axis=0), cols_per, axis=1).ravel()

    cxs, cys = np.where(uniform, cx, 0), np.where(uniform, cy, 0)
    col = spread(np.where(uniform, pre[cxs, cys], 0.0))
    cov = spread(np.where(uniform, tex.alpha[cxs, cys], 0.0))
    todo = np.zeros((H, W), dtype=bool)  # the pixels to compute, halo coordinates
    todo[1:-1, 1:-1] = ~spread(uniform).reshape(h, w)
    if not todo.any():
        return col, cov
    inner = todo[1:-1, 1:-1].ravel()
    col[inner], cov[inner] = _pixel_by_pixel(rx, ry, todo, tex, board2cam)
    return col, cov


def _uniform_tiles(rx, ry, tex: BoardTexture, board2cam: np.ndarray, tile: int, h: int, w: int):
    """Which tiles of the block see one cell of the print only (see :func:`render_block_tiled`),
    and that cell's indices (cx, cy) into the texture's lines."""
    # Corner pixels of the tiles (block coordinates, halo excluded): tile k spans k*tile ..
    # bu[k + 1] (the last tile up to the last pixel).
    bu = np.concatenate([np.arange(0, w - 1, tile), [w - 1]])
    bv = np.concatenate([np.arange(0, h - 1, tile), [h - 1]])
    srx, sry = rx[np.ix_(bv + 1, bu + 1)], ry[np.ix_(bv + 1, bu + 1)]
    Xs, Ys, _ = board_coords(srx, sry, board2cam)
    nrm = board2cam[:3, 2]
    nd = nrm[0] * srx + nrm[1] * sry + nrm[2]
    du = np.diff(bu).astype(np.float64)[None, :]
    dv = np.diff(bv).astype(np.float64)[:, None]
    xs, ys = tex.xs, tex.ys

    def cells(S):
        """The box of a tile's board coordinates S, widened by its bend and footprint."""
        c = (S[:-1, :-1], S[:-1, 1:], S[1:, :-1], S[1:, 1:])
        lo = np.minimum(np.minimum(c[0], c[1]), np.minimum(c[2], c[3]))
        hi = np.maximum(np.maximum(c[0], c[1]), np.maximum(c[2], c[3]))
        # Per-pixel steps along u and v from the tile's edges, the largest of the two edges.
        su = np.maximum(np.abs(c[1] - c[0]), np.abs(c[3] - c[2])) / du
        sv = np.maximum(np.abs(c[2] - c[0]), np.abs(c[3] - c[1])) / dv
        half = 1.05 * 0.5 * (su + sv)  # the footprint's half-width (render_block's hx, hy)
        bend = _TILE_BEND * (hi - lo + su * du + sv * dv)
        return lo - bend - half, hi + bend + half

    xlo, xhi = cells(Xs)
    ylo, yhi = cells(Ys)
    cx = np.searchsorted(xs, xlo, side="left")  # xs[cx - 1] < xlo (strictly), xs[cx] >= xlo
    cy = np.searchsorted(ys, ylo, side="left")
    uniform = (
        (np.searchsorted(xs, xhi, side="right") == cx)  # and xhi < xs[cx] (strictly)
        & (np.searchsorted(ys, yhi, side="right") == cy)
        & np.isfinite(xlo + xhi + ylo + yhi)
        & (
            np.minimum(np.minimum(nd[:-1, :-1], nd[:-1, 1:]), np.minimum(nd[1:, :-1], nd[1:, 1:]))
            > _TILE_MIN_ND
        )
    )
    return uniform, cx, cy


def _pixel_by_pixel(rx, ry, todo: np.ndarray, tex: BoardTexture, board2cam: np.ndarray):
    """:func:`render_block`'s colour and opacity of the pixels ``todo`` (halo coordinates),
    from their board points and their four neighbours' (the Jacobian)."""
    H, W = rx.shape
    p = np.flatnonzero(todo)
    need = todo.copy()
    need[1:-1, 2:] |= todo[1:-1, 1:-1]
    need[1:-1, :-2] |= todo[1:-1, 1:-1]
    need[2:, 1:-1] |= todo[1:-1, 1:-1]
    need[:-2, 1:-1] |= todo[1:-1, 1:-1]
    Xq, Yq, OKq = board_coords(rx[need], ry[need], board2cam)
    X = np.empty((H, W))
    Y = np.empty((H, W))
    OK = np.zeros((H, W), dtype=bool)
    X[need], Y[need], OK[need] = Xq, Yq, OKq
    X, Y, OK = X.ravel(), Y.ravel(), OK.ravel()
    Jxu = 0.5 * (X[p + 1] - X[p - 1])
    Jxv = 0.5 * (X[p + W] - X[p - W])
    Jyu = 0.5 * (Y[p + 1] - Y[p - 1])
    Jyv = 0.5 * (Y[p + W] - Y[p - W])
    ok = OK[p] & OK[p + 1] & OK[p - 1] & OK[p + W] & OK[p - W]
    return _shade(X[p], Y[p], (Jxu, Jxv, Jyu, Jyv), ok, tex)
