"""Where a board's edges sit relative to a pose: the edge-by-edge check behind a refused fit.

A photometric pose is refused when it lands farther from the corner pose than the two fits'
uncertainties allow (``docs/vision.md``, "Real photographs"). :func:`edge_agreement` says how
the image's edges disagree with a given pose (the corner pose): with the blur, dilation and
noise-free model of a photometric fit, each edge segment (one grid line between two
neighbouring corner lines) is moved along its normal to where the image puts it (one
Gauss-Newton step of a single shift, with the shading refitted at that pose), and the shifts
of the inner lines' segments are split into

- a shift towards the white side (black squares larger than the fit's dilation makes them:
  ink spread, a non-linear response),
- one image vector for every edge (a point-spread function whose centre is not where the
  corner estimator's is: a camera's line processing),
- a scale: edges farther from the board's centre than the pose puts them, in proportion to
  the distance (what moves a photometric pose along the line of sight),
- the rest (RMS per segment).

A pose that fits the edges gives zeros up to the noise; the test-bed checks each term
against a pose moved by a known amount (``tests/test_vision_photometric.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...camera import CameraModel
from ...targets import Chessboard
from .model import model_and_jacobian
from .pixels import prepare_pixels

__all__ = ["EdgeAgreement", "edge_agreement"]

#: Shift of an edge for the finite difference of the model, px.
_STEP_PX = 0.01
#: Gauss-Newton steps of the shifts and shading (the shifts are a fraction of the blur).
_ROUNDS = 3
#: Fewest pixels for a segment's shift.
_MIN_PIXELS = 10


@dataclass(frozen=True)
class EdgeAgreement:
    """How a board's edges sit relative to a pose (see the module docstring).

    Attributes
    ----------
    n_edges : int
        Inner lines' segments measured.
    toward_white_px : float
        Mean shift of an edge towards its white side, px.
    offset_px : (float, float)
        Shift of every edge by one image vector (u, v), px.
    scale : float
        Edges sit (1 + scale) times as far from the board's centre as the pose puts them
        (0.001: 0.1 %; a photometric fit would move the board about scale times its distance
        closer).
    rms_px : float
        RMS of the segments' shifts left after these three, px.
    shifts_px : ndarray, shape (n_edges,)
        Each segment's shift along its normal towards the board's outside, px.
    lines : ndarray of int, shape (n_edges, 3)
        Each segment's axis (0: a line X = k s, 1: Y = k s), line k and segment j.
    """

    n_edges: int
    toward_white_px: float
    offset_px: tuple[float, float]
    scale: float
    rms_px: float
    shifts_px: np.ndarray
    lines: np.ndarray


def edge_agreement(
    image: np.ndarray,
    board: Chessboard,
    camera: CameraModel,
    board2cam,
    fit,
    *,
    phase: int = 0,
) -> EdgeAgreement:
    """Where the image's edges sit relative to ``board2cam``, with a photometric fit's edge model.

    Parameters
    ----------
    image : ndarray, shape (h, w), uint8 or uint16
    board : Chessboard
    camera : CameraModel
    board2cam : array_like, shape (4, 4), mm
        The pose checked (e.g. the corner pose).
    fit : PhotometricFit
        A photometric fit of the board in this image (its blur and dilation; whether it used the
        inner squares only).
    phase : {0, 1}
        The board's colour phase (``BoardDetection.phase``).

    Returns
    -------
    EdgeAgreement
    """
    T = np.asarray(board2cam, dtype=np.float64)
    st = prepare_pixels(image, board, camera, T, blur_px=fit.blur_px, phase=phase, inner_only=fit.inner_only)
    blur = [fit.blur_px, *fit.blur_anisotropy_px]
    dil = [fit.dilation_px, *fit.dilation_anisotropy_px]
    seg, E = _segment_index(st, T)
    shift = np.zeros(len(E))
    for _ in range(_ROUNDS):
        shift += _joint_step(st, T, blur, dil, seg, E[:, 0], shift)
    E = np.c_[E, shift]
    return _decompose(E, board, camera, T)


def _segment_index(st, T) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's segment (an index into the rows of the table, -1: none) and the table of
    segments (axis, k, j, black side: +1 when on the low side) of the inner lines."""
    s = st.board.square_mm
    Hi = np.linalg.inv(T[:3][:, [0, 1, 3]])
    w = Hi @ np.vstack([st.rx, st.ry, np.ones_like(st.rx)])
    seg = np.full(st.n_pixels, -1, dtype=np.int64)
    rows = []
    for axis, line, bs, n, along in (
        (0, st.line_x, st.bsx, st.board.cols, w[1] / w[2]),
        (1, st.line_y, st.bsy, st.board.rows, w[0] / w[2]),
    ):
        k = np.rint(line / s).astype(np.int64)
        j = np.floor(along / s).astype(np.int64)
        use = (bs != 0) & (k >= 0) & (k < n)
        key = np.where(use, k * 4096 + j + 2048, -1)
        for kk in np.unique(key[use]):
            i = key == kk
            if i.sum() >= _MIN_PIXELS:
                seg[i] = len(rows)
                rows.append((axis, kk // 4096, kk % 4096 - 2048, np.sign(np.median(bs[i]))))
    return seg, np.array(rows, dtype=np.float64).reshape(-1, 4)


def _joint_step(st, T, blur, dil, seg, axis, shift) -> np.ndarray:
    """One Gauss-Newton step of the segments' shifts (px, towards +axis) and the shading together
    (a shift of many edges changes the mean level, which a shading fitted alone would take up):
    the shading block is eliminated (Schur complement; the shifts' block is diagonal)."""
    nb = st.basis.shape[0]
    h = np.where(seg >= 0, shift[np.maximum(seg, 0)], 0.0)
    on_x = (seg >= 0) & (axis[np.maximum(seg, 0)] == 0)
    on_y = (seg >= 0) & ~on_x
    moved = replace(
        st,
        line_x=st.line_x + np.where(on_x, h, 0.0) / st.isx,
        line_y=st.line_y + np.where(on_y, h, 0.0) / st.isy,
    )
    unit = np.zeros(nb)
    unit[0] = 1.0  # the constant monomial: a = 0, b = 1 gives the blurred pattern c itself

    def pattern(m):
        return model_and_jacobian(m, T, blur, dil, np.zeros(nb), unit, jacobian=False)[0]

    c = pattern(moved)
    B = np.vstack([st.basis, st.basis * c])  # (2 nb, N): the shading's columns
    coef = np.linalg.lstsq(B.T, st.values, rcond=None)[0]
    r = st.values - coef @ B
    b = coef[nb:] @ st.basis
    # An edge moved by +d px along its axis: the pixel's distance to it shrinks by d.
    cx = pattern(replace(moved, line_x=moved.line_x + _STEP_PX / st.isx))
    cy = pattern(replace(moved, line_y=moved.line_y + _STEP_PX / st.isy))
    g = np.where(on_x, b * (cx - c), np.where(on_y, b * (cy - c), 0.0)) / _STEP_PX
    q, ns = np.maximum(seg, 0), len(shift)
    D = np.bincount(q, weights=g * g, minlength=ns)
    Gr = np.bincount(q, weights=g * r, minlength=ns)
    BG = np.stack([np.bincount(q, weights=row * g, minlength=ns) for row in B])  # (2 nb, ns)
    M = B @ B.T - (BG / D) @ BG.T
    ds = np.linalg.solve(M, B @ r - BG @ (Gr / D))
    return (Gr - BG.T @ ds) / D


def _decompose(E, board, camera, T) -> EdgeAgreement:
    """Least squares of the segments' shifts on (towards white, offset u, offset v, scale)."""
    s = board.square_mm
    if len(E) < 8:
        raise ValueError(f"edge_agreement: {len(E)} edge segments measured, at least 8 needed")
    axis, k, j = E[:, 0], E[:, 1], E[:, 2]
    mid = np.where(axis[:, None] == 0, np.c_[k * s, (j + 0.5) * s], np.c_[(j + 0.5) * s, k * s])
    step = np.where(axis[:, None] == 0, [0.5, 0.0], [0.0, 0.5])
    uv = [_project(camera, T, mid + d * step) for d in (-1.0, 0.0, 1.0)]
    nrm = uv[2] - uv[0]
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    centre = _project(camera, T, np.array([[(board.cols - 1) * s / 2, (board.rows - 1) * s / 2]]))[0]
    radial = np.sum(nrm * (uv[1] - centre), axis=1)  # px from the board's centre along the normal
    A = np.column_stack([E[:, 3], nrm, radial])
    coef, *_ = np.linalg.lstsq(A, E[:, 4], rcond=None)
    left = E[:, 4] - A @ coef
    return EdgeAgreement(
        n_edges=len(E),
        toward_white_px=float(coef[0]),
        offset_px=(float(coef[1]), float(coef[2])),
        scale=float(coef[3]),
        rms_px=float(np.sqrt(np.mean(left**2))),
        shifts_px=E[:, 4] * np.sign(radial),
        lines=E[:, :3].astype(np.int64),
    )


def _project(camera: CameraModel, T, xy) -> np.ndarray:
    P = np.c_[xy, np.zeros(len(xy))]
    return camera.project(P @ T[:3, :3].T + T[:3, 3])
