"""Compensation: commanded points whose deflected positions are the programmed ones.

For each point p of a feed move, under the force F there, the commanded point c solves
``c + delta(c, F) = p`` (fixed point ``c <- p - delta(c, F)``; the deflection changes by a
few micrometres per millimetre, so each step gains two digits). A move is written as
pieces between such points; the machine moves straight (or round an arc) between them,
and there the deflected path ``x + delta(x, F)`` may leave the programmed one. Each piece
is checked at interior points and halved until that deviation stays within the tolerance
(with a margin, :data:`CHECK_FRACTION`); arcs are written as arcs (pieces of at most a
quarter turn, through the commanded points at their ends and middle), lines as lines.

Rapids carry no force: a rapid is kept as programmed, except the rapid that starts a cut,
which goes to the compensated start of that cut. Where the force jumps between two feed
moves (a corner with a force that turns with the feed), the first ends at its compensated
end and a straight piece takes the tool to the second's compensated start while the force
changes (the tool's deflected position stays at the corner).

The result (:class:`Compensation`) holds every move's pieces and the numbers of the
summary: the deflection along the program uncompensated, and the deviation left.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..models.base import format_pose
from .field import ArmField
from .forces import ForceSpec, force_at
from .path import Toolpath

__all__ = [
    "Compensation",
    "MovePieces",
    "compensate_path",
    "solve_commanded",
    "CHECK_FRACTION",
    "CompensationError",
]

#: Pieces are accepted when their sampled deviation is below this fraction of the tolerance
#: (the deviation between samples is then within the tolerance).
CHECK_FRACTION = 0.7
#: Interior samples of each piece's check (at 1/4, 1/2, 3/4: the deviation between two commanded
#: points grows from zero at both ends, smoothly, as the deflection varies over tens of mm).
CHECK_SAMPLES = 3
#: The fixed point stops when a step moves the commanded points less than this (mm).
FIXED_POINT_TOL_MM = 1e-6
FIXED_POINT_MAX = 60
#: A piece is never shorter than this share of its move (2^-24): the deflection would change
#: too fast to follow (a singularity).
MAX_DEPTH = 24
#: Arcs are cut into pieces of at most this angle (rad) before checking.
MAX_ARC_PIECE = math.pi / 2


class CompensationError(InputError):
    """A program the model cannot compensate: a point out of reach or at a singularity (named).

    ``programmed_point`` is True when the point is one the program itself asks for (not a
    commanded point the compensation moved): where the program is placed decides it."""

    programmed_point: bool = False


@dataclass(frozen=True)
class MovePieces:
    """The output of one feed move (or of a rapid that starts a cut).

    Attributes
    ----------
    s : ndarray, shape (k + 1,)
        Parameters along the move of the pieces' ends (0 first, 1 last).
    points : ndarray, shape (k + 1, 3), mm
        Commanded points there (program frame).
    centres : ndarray, shape (k, 3), mm, or None
        An arc's pieces' commanded centres (normal coordinate unused).
    deviation : ndarray, shape (k,), mm
        Largest sampled distance of each piece's deflected path from the programmed move.
    spin : ndarray, shape (k + 1,), rad, or None
        A serial arm's tool spin at the pieces' ends.
    """

    s: np.ndarray
    points: np.ndarray
    centres: np.ndarray | None
    deviation: np.ndarray
    spin: np.ndarray | None = None


@dataclass(frozen=True)
class Compensation:
    """A compensated toolpath.

    Attributes
    ----------
    pieces : dict of int to MovePieces
        Feed moves and the rapids that start a cut (their single piece: the cut's start).
    transitions : dict of int to ndarray, shape (3,)
        Feed move m -> where a straight piece takes the tool after m (the next cut's
        compensated start, the force changing between the two).
    tolerance_mm : float
    before : ndarray, shape (N,), mm
        Deflection magnitude at N points along the feed moves, uncompensated.
    before_at : ndarray, shape (N,), mm
        Their distance along the feed moves (cumulative length).
    after : ndarray, shape (M,), mm
        Deviation of the deflected path from the programmed one at the check samples.
    after_at : ndarray, shape (M,), mm
    n_points : int
        Points written (pieces' ends).
    """

    pieces: dict[int, MovePieces]
    transitions: dict[int, np.ndarray]
    tolerance_mm: float
    before: np.ndarray
    before_at: np.ndarray
    after: np.ndarray
    after_at: np.ndarray
    n_points: int
    notes: tuple[str, ...] = field(default=())

    @property
    def worst_before_mm(self) -> float:
        return float(np.max(self.before)) if self.before.size else 0.0

    @property
    def rms_before_mm(self) -> float:
        return float(np.sqrt(np.mean(self.before**2))) if self.before.size else 0.0

    @property
    def worst_after_mm(self) -> float:
        return float(np.max(self.after)) if self.after.size else 0.0


def _raise_invalid(path: Toolpath, m: np.ndarray, res, fld, P: np.ndarray, what: str, F=None) -> None:
    """Raise a :class:`CompensationError` for the first invalid point in program order (with the
    force ``F`` (N, 3) that put a commanded point there, when given)."""
    bad = np.flatnonzero(~res.valid)
    if bad.size == 0:
        return
    j = bad[np.argmin(path.line[m[bad]] * 1.0)]
    under = "" if F is None else " under F = ({:.6g}, {:.6g}, {:.6g}) N".format(*F[j])
    err = CompensationError(
        f"line {path.line[m[j]]}: {what} {fld.describe_point(P[j])}{under} "
        f"{res.reasons[j] or 'cannot be evaluated'} (nothing written)"
    )
    err.programmed_point = what == "programmed point"
    raise err


def check_reach(fld, path: Toolpath) -> None:
    """Refuse at once a placement that puts a programmed point (a move's start or end) beyond a
    serial arm's reach (:meth:`~stiffmap.models.chain.Chain.reach_mm`): a
    :class:`CompensationError` naming the first such point in program order, its distance from
    the arm's first joint and the reach. Without it, such a program fails only after the inverse
    kinematics (and every tool spin of ``--free-tool-spin``) has been tried at its points."""
    if not isinstance(fld, ArmField) or len(path) == 0:
        return
    ch = fld.robot.chain
    P = np.stack([path.start, path.end], axis=1).reshape(-1, 3)
    far = np.flatnonzero(fld.beyond_reach(P))  # NaN (an axis unknown) is not far
    if far.size == 0:
        return
    j = int(far[0])
    centre, radius = ch.reach_mm()
    d = np.linalg.norm(fld.base_points(P) - centre, axis=1)
    err = CompensationError(
        f"line {path.line[j // 2]}: programmed point {fld.describe_point(P[j])} is out of the arm's "
        f"reach: {d[j]:.4g} mm from {ch.joint_names[0]}'s origin {format_pose(centre)}, where {ch.name}'s "
        f"tool point is never more than {radius:.4g} mm away (nothing written)"
    )
    err.programmed_point = True
    raise err


def solve_commanded(fld, path: Toolpath, forces: ForceSpec, m, s, q0=None, spin=None, guess=None):
    """Commanded points c with ``c + delta(c, F) = p`` at parameters ``s`` of moves ``m``.

    Parameters
    ----------
    fld : field (``machining.field``)
    path : Toolpath
    forces : ForceSpec
    m, s : ndarray, shape (N,)
    q0 : ndarray, shape (N, n), optional
        An arm's configurations near the points (warm starts).
    spin : ndarray, shape (N,), rad, optional
    guess : ndarray, shape (N, 3), mm, optional
        Where to start (default: the programmed points).

    Returns
    -------
    C : ndarray, shape (N, 3), mm
    q : ndarray, shape (N, n), or None

    Raises
    ------
    CompensationError
        The first point (in program order) the model cannot evaluate.
    """
    P = path.point(m, s)
    F = force_at(path, forces, m, s)
    C = P.copy() if guess is None else np.array(guess, dtype=float)
    q = q0
    for _ in range(FIXED_POINT_MAX):
        res = fld(C, F, q, spin)
        _raise_invalid(path, m, res, fld, C, "commanded point", F)
        new = P - res.delta
        q = res.q
        moved = np.max(np.abs(new - C), axis=1) if C.size else np.zeros(0)
        C = new
        if not np.any(moved >= FIXED_POINT_TOL_MM):
            break
    else:  # the deflection changes as much as the point moves: no commanded point to find
        j = int(
            np.flatnonzero(moved >= FIXED_POINT_TOL_MM)[np.argmin(path.line[m[moved >= FIXED_POINT_TOL_MM]])]
        )
        raise CompensationError(
            f"line {path.line[m[j]]}: no commanded point brings the tool onto the programmed point "
            f"{fld.describe_point(P[j])} under F = ({F[j][0]:.6g}, {F[j][1]:.6g}, {F[j][2]:.6g}) N: the "
            f"deflection ({np.linalg.norm(P[j] - C[j]):.4g} mm) changes as fast as the point moves (a force "
            "too large for the model, or a singularity near) (nothing written)"
        )
    return C, q


def _circle_centre(A, B, M, axes) -> np.ndarray:
    """Centres (N, 3) of the circles through A, M, B in each row's plane (a, b) (normal coordinate
    that of A); NaN where the three points are aligned."""
    rows = np.arange(A.shape[0])
    a, b = axes[:, 0], axes[:, 1]
    ax, ay = A[rows, a], A[rows, b]
    bx, by = B[rows, a], B[rows, b]
    mx, my = M[rows, a], M[rows, b]
    d = 2 * (ax * (my - by) + mx * (by - ay) + bx * (ay - my))
    a2, m2, b2 = ax * ax + ay * ay, mx * mx + my * my, bx * bx + by * by
    with np.errstate(divide="ignore", invalid="ignore"):
        ux = (a2 * (my - by) + m2 * (by - ay) + b2 * (ay - my)) / d
        uy = (a2 * (bx - mx) + m2 * (ax - bx) + b2 * (mx - ax)) / d
    C = A.copy()
    C[rows, a], C[rows, b] = ux, uy
    return C


def _arc_samples(A, B, centre, axes, sign, t) -> np.ndarray:
    """Points at fractions t (N,) of the arcs from A to B about ``centre`` turning with ``sign``
    (+1 counter-clockwise in (a, b)); the normal coordinate linear in t."""
    rows = np.arange(A.shape[0])
    a, b, n = axes[:, 0], axes[:, 1], axes[:, 2]
    t0 = np.arctan2(A[rows, b] - centre[rows, b], A[rows, a] - centre[rows, a])
    t1 = np.arctan2(B[rows, b] - centre[rows, b], B[rows, a] - centre[rows, a])
    sw = np.where(sign > 0, (t1 - t0) % (2 * math.pi), -((t0 - t1) % (2 * math.pi)))
    r = np.hypot(A[rows, a] - centre[rows, a], A[rows, b] - centre[rows, b])
    th = t0 + t * sw
    X = A + t[:, None] * (B - A)
    X[rows, a] = centre[rows, a] + r * np.cos(th)
    X[rows, b] = centre[rows, b] + r * np.sin(th)
    X[rows, n] = A[rows, n] + t * (B[rows, n] - A[rows, n])
    return X


@dataclass
class _Pieces:
    """Pieces being checked (parallel arrays; private)."""

    m: np.ndarray
    sa: np.ndarray
    sb: np.ndarray
    A: np.ndarray
    B: np.ndarray
    qa: np.ndarray | None
    depth: np.ndarray
    M: np.ndarray | None = None  # commanded midpoints (arcs)

    def take(self, keep: np.ndarray) -> _Pieces:
        def pick(x):
            return None if x is None else x[keep]

        return _Pieces(
            self.m[keep],
            self.sa[keep],
            self.sb[keep],
            self.A[keep],
            self.B[keep],
            pick(self.qa),
            self.depth[keep],
            pick(self.M),
        )


def _check(fld, path: Toolpath, forces: ForceSpec, pc: _Pieces, spin_of) -> tuple[np.ndarray, np.ndarray]:
    """Largest deviation (mm) of each piece's deflected path from its move, and the arcs' centres."""
    k = CHECK_SAMPLES
    n = pc.m.size
    t = np.tile(np.arange(1, k + 1) / (k + 1), n)
    rep = np.repeat(np.arange(n), k)
    m = pc.m[rep]
    s = pc.sa[rep] + t * (pc.sb[rep] - pc.sa[rep])
    arc = path.is_arc[pc.m]
    centres = np.full((n, 3), np.nan)
    if np.any(arc):
        centres[arc] = _circle_centre(pc.A[arc], pc.B[arc], pc.M[arc], path.axes[pc.m[arc]])
    X = pc.A[rep] + t[:, None] * (pc.B[rep] - pc.A[rep])
    ar = arc[rep]
    if np.any(ar):
        sign = np.sign(path.sweep[m[ar]])
        X[ar] = _arc_samples(pc.A[rep][ar], pc.B[rep][ar], centres[rep][ar], path.axes[m[ar]], sign, t[ar])
    F = force_at(path, forces, m, s)
    q0 = None if pc.qa is None else pc.qa[rep]
    res = fld(X, F, q0, spin_of(m, s))
    _raise_invalid(path, m, res, fld, X, "point between commanded points", F)
    dev = path.distance(m, X + res.delta)
    worst = np.max(dev.reshape(n, k), axis=1)
    return worst, centres


def compensate_path(
    fld,
    path: Toolpath,
    forces: ForceSpec,
    tolerance_mm: float,
    *,
    spin_of: Callable | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Compensation:
    """Compensate every feed move of a toolpath (module docstring).

    Parameters
    ----------
    fld : MechanismField or ArmField
        The model's deflections (``machining.field``), placed.
    path : Toolpath
    forces : ForceSpec
    tolerance_mm : float
        Largest distance (mm) allowed between the deflected and the programmed path.
    spin_of : callable (m, s) -> ndarray or None, optional
        A serial arm's tool spin (rad) along the moves (``machining.spin``).
    progress : callable (done, total), optional
        Called as moves are finished.

    Returns
    -------
    Compensation

    Raises
    ------
    CompensationError
        Naming the first line with a point out of reach or at a singularity.
    ValueError
        A tolerance that is not a positive number.
    """
    if not (math.isfinite(tolerance_mm) and tolerance_mm > 0):
        raise ValueError(f"the tolerance must be a positive number of mm, got {tolerance_mm!r}")
    spin_of = spin_of or (lambda m, s: None)
    feed = np.flatnonzero(path.feed)
    _check_known(path, feed)
    q_prog = _programmed_configurations(fld, path, spin_of)
    pc = _initial_pieces(fld, path, forces, feed, q_prog, spin_of)
    done: list[tuple] = []
    total = max(int(feed.size), 1)
    while pc.m.size:
        worst, centres = _check(fld, path, forces, pc, spin_of)
        ok = worst <= CHECK_FRACTION * tolerance_mm
        done.append((pc.take(ok), worst[ok], centres[ok]))
        if progress is not None:
            progress(min(total, sum(int(d[0].m.size) for d in done)), total)
        pc = _split(fld, path, forces, pc.take(~ok), spin_of)
    return _assemble(fld, path, forces, feed, done, tolerance_mm, spin_of, q_prog)


def _check_known(path: Toolpath, feed: np.ndarray) -> None:
    """Refuse a feed move from or to a position the program left unknown (after G28/G30/G53)."""
    bad = feed[~np.all(path.known[feed] & path.known_start[feed], axis=1)]
    if bad.size:
        raise CompensationError(
            f"line {path.line[bad[0]]}: a cut from or to a position the program left unknown (after "
            "G28/G30/G53 or a line passed through): give X, Y and Z absolutely before cutting"
        )


def _programmed_configurations(fld, path: Toolpath, spin_of) -> np.ndarray | None:
    """Refuse the first programmed point (rapids' too) out of reach or at a singularity; an arm's
    configurations at every move's start and end, solved along the program in order (one
    branch), None for other mechanisms. A
    point the program left unknown (after G28) takes the configuration of the next known one."""
    if len(path) == 0:
        return None
    n = len(path)
    m = np.repeat(np.arange(n), 2)
    s = np.tile([0.0, 1.0], n)
    known = np.ravel(np.column_stack([np.all(path.known_start, axis=1), np.all(path.known, axis=1)]))
    idx = np.flatnonzero(known)
    P = path.point(m[idx], s[idx])
    res = fld(P, np.zeros_like(P), None, spin_of(m[idx], s[idx]))
    _raise_invalid(path, m[idx], res, fld, P, "programmed point")
    if res.q is None:
        return None
    Q = np.empty((m.size, res.q.shape[1]))
    nxt = np.minimum(np.searchsorted(idx, np.arange(m.size)), idx.size - 1)
    Q[:] = res.q[nxt]
    return np.stack([Q[0::2], Q[1::2]])


def _initial_pieces(fld, path, forces, feed, q_prog, spin_of) -> _Pieces:
    """One piece per feed move (arcs cut into pieces of at most a quarter turn), ends compensated."""
    nseg = np.ones(feed.size, dtype=np.intp)
    arc = path.is_arc[feed]
    nseg[arc] = np.maximum(1, np.ceil(np.abs(path.sweep[feed[arc]]) / MAX_ARC_PIECE - 1e-9)).astype(np.intp)
    m = np.repeat(feed, nseg)
    first = np.repeat(np.cumsum(nseg) - nseg, nseg)
    j = np.arange(m.size) - first
    sa = j / np.repeat(nseg, nseg)
    sb = (j + 1) / np.repeat(nseg, nseg)
    q0a = None if q_prog is None else q_prog[0][m]
    q0b = None if q_prog is None else q_prog[1][m]
    # the pieces' ends, each solved once (a move's pieces share theirs)
    key = np.column_stack([np.concatenate([m, m]), np.concatenate([sa, sb])])
    _, first_at, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    mm_ = np.concatenate([m, m])[first_at]
    ss_ = np.concatenate([sa, sb])[first_at]
    q0 = None if q0a is None else np.concatenate([q0a, q0b])[first_at]
    X, qx = solve_commanded(fld, path, forces, mm_, ss_, q0, spin_of(mm_, ss_))
    A, B = X[inv[: m.size]], X[inv[m.size :]]
    qa = None if qx is None else qx[inv[: m.size]]
    pc = _Pieces(m, sa, sb, A, B, qa, np.zeros(m.size, dtype=np.intp))
    return _with_midpoints(fld, path, forces, pc, spin_of)


def _with_midpoints(fld, path, forces, pc: _Pieces, spin_of) -> _Pieces:
    """The arcs' pieces get their commanded midpoints (the circle through three points)."""
    M = np.full_like(pc.A, np.nan)
    arc = path.is_arc[pc.m]
    if np.any(arc):
        sm = 0.5 * (pc.sa[arc] + pc.sb[arc])
        q = None if pc.qa is None else pc.qa[arc]
        g = _guess(path, pc.m[arc], pc.sa[arc], pc.sb[arc], pc.A[arc], pc.B[arc])
        M[arc], _ = solve_commanded(fld, path, forces, pc.m[arc], sm, q, spin_of(pc.m[arc], sm), g)
    pc.M = M
    return pc


def _guess(path: Toolpath, m, sa, sb, A, B) -> np.ndarray:
    """A start for the commanded point between two solved ones: the programmed midpoint less the
    mean of the two ends' corrections (a few micrometres off, not a deflection off)."""
    corr = 0.5 * ((path.point(m, sa) - A) + (path.point(m, sb) - B))
    return path.point(m, 0.5 * (sa + sb)) - corr


def _split(fld, path, forces, pc: _Pieces, spin_of) -> _Pieces:
    """Halve pieces: each gives two, their common end compensated."""
    if pc.m.size == 0:
        return pc
    if np.any(pc.depth >= MAX_DEPTH):
        i = int(np.flatnonzero(pc.depth >= MAX_DEPTH)[0])
        raise CompensationError(
            f"line {path.line[pc.m[i]]}: the deflection changes too fast to follow within the tolerance "
            "(a singularity near the path?) (nothing written)"
        )
    sm = 0.5 * (pc.sa + pc.sb)
    arc = path.is_arc[pc.m]
    Mid = pc.M.copy() if pc.M is not None else np.full_like(pc.A, np.nan)
    lin = ~arc
    qm = pc.qa
    if np.any(lin):
        q = None if pc.qa is None else pc.qa[lin]
        g = _guess(path, pc.m[lin], pc.sa[lin], pc.sb[lin], pc.A[lin], pc.B[lin])
        ml, sl = pc.m[lin], sm[lin]
        Mid[lin], _ = solve_commanded(fld, path, forces, ml, sl, q, spin_of(ml, sl), g)
    two = np.concatenate
    new = _Pieces(
        m=two([pc.m, pc.m]),
        sa=two([pc.sa, sm]),
        sb=two([sm, pc.sb]),
        A=two([pc.A, Mid]),
        B=two([Mid, pc.B]),
        qa=None if qm is None else two([qm, qm]),
        depth=two([pc.depth + 1, pc.depth + 1]),
    )
    return _with_midpoints(fld, path, forces, new, spin_of)


def _assemble(fld, path, forces, feed, done, tolerance_mm, spin_of, q_prog=None) -> Compensation:
    """Gather the accepted pieces per move, the rapids into cuts, the corners and the summary."""
    m = np.concatenate([d[0].m for d in done]) if done else np.zeros(0, dtype=np.intp)
    sa = np.concatenate([d[0].sa for d in done]) if done else np.zeros(0)
    sb = np.concatenate([d[0].sb for d in done]) if done else np.zeros(0)
    A = np.concatenate([d[0].A for d in done]) if done else np.zeros((0, 3))
    B = np.concatenate([d[0].B for d in done]) if done else np.zeros((0, 3))
    dev = np.concatenate([d[1] for d in done]) if done else np.zeros(0)
    cen = np.concatenate([d[2] for d in done]) if done else np.zeros((0, 3))
    order = np.lexsort((sa, m))
    m, sa, sb, A, B, dev, cen = m[order], sa[order], sb[order], A[order], B[order], dev[order], cen[order]
    pieces: dict[int, MovePieces] = {}
    bounds = np.searchsorted(m, feed), np.searchsorted(m, feed, side="right")
    for mv, lo, hi in zip(feed, *bounds, strict=True):
        s = np.append(sa[lo:hi], 1.0)
        pts = np.vstack([A[lo:hi], B[hi - 1 : hi]])
        sp = spin_of(np.full(s.size, mv), s)
        pieces[int(mv)] = MovePieces(s, pts, cen[lo:hi] if path.is_arc[mv] else None, dev[lo:hi], sp)
    transitions = _corners(path, pieces, feed)
    _rapids_into_cuts(path, pieces, feed, spin_of)
    L = path.length()
    cum = np.concatenate([[0.0], np.cumsum(np.where(path.feed, L, 0.0))])
    before, before_at = _before(fld, path, forces, feed, cum, spin_of, q_prog)
    after_at = cum[m] + 0.5 * (sa + sb) * L[m]
    n_points = int(sum(p.s.size for p in pieces.values()) + len(transitions))
    return Compensation(pieces, transitions, tolerance_mm, before, before_at, dev, after_at, n_points)


def _corners(path: Toolpath, pieces: dict[int, MovePieces], feed: np.ndarray) -> dict[int, np.ndarray]:
    """Feed moves followed by a feed move whose compensated start is elsewhere (the force jumps)."""
    out = {}
    for a, b in zip(feed[:-1], feed[1:], strict=True):
        if b != a + 1:
            continue
        end, start = pieces[int(a)].points[-1], pieces[int(b)].points[0]
        if np.max(np.abs(end - start)) > 1e-7:
            out[int(a)] = start.copy()
    return out


def _rapids_into_cuts(path: Toolpath, pieces: dict[int, MovePieces], feed: np.ndarray, spin_of) -> None:
    """A rapid just before a cut goes to the cut's compensated start (a one-piece entry)."""
    for b in feed:
        a = int(b) - 1
        if a >= 0 and not path.feed[a]:
            start = pieces[int(b)].points[0]
            sp = spin_of(np.array([a, a]), np.array([0.0, 1.0]))
            pieces[a] = MovePieces(
                np.array([0.0, 1.0]), np.vstack([path.start[a], start]), None, np.zeros(1), sp
            )


def _before(fld, path, forces, feed, cum, spin_of, q_prog=None) -> tuple[np.ndarray, np.ndarray]:
    """|delta| along the feed moves, uncompensated: at their ends and CHECK_SAMPLES points inside each
    (an arm's configurations there: :func:`_along_moves`)."""
    if feed.size == 0:
        return np.zeros(0), np.zeros(0)
    k = CHECK_SAMPLES + 2
    t = np.tile(np.linspace(0.0, 1.0, k), feed.size)
    m = np.repeat(feed, k)
    P = path.point(m, t)
    F = force_at(path, forces, m, t)
    q0 = None
    if hasattr(fld, "solve_path"):
        q0 = _along_moves(fld, P, spin_of(m, t), k, None if q_prog is None else q_prog[0][feed])
    res = fld(P, F, q0, spin_of(m, t))
    _raise_invalid(path, m, res, fld, P, "programmed point")
    return np.linalg.norm(res.delta, axis=1), cum[m] + t * path.length()[m]


def _along_moves(fld: ArmField, P: np.ndarray, spin, k: int, starts) -> np.ndarray:
    """An arm's configurations at ``k`` points of each feed move (P: k rows a move), solved in
    order from the configuration at the move's start on the program's branch (``starts``: from
    :func:`_programmed_configurations`, which follows every programmed point, rapids' too); from
    the seed along all the points when not known. The feed points alone, solved in order from the
    seed, skip the rapids' points: the first cut's start may then land on another branch (a joint
    beyond its limits at a point the program reaches)."""
    if starts is None:
        return fld.solve_path(P, spin)[0]
    out = []
    for i, q in enumerate(starts):
        rows = slice(i * k, (i + 1) * k)
        out.append(replace(fld, q_seed=q).solve_path(P[rows], None if spin is None else spin[rows])[0])
    return np.concatenate(out)
