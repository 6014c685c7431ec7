"""Where to cut: the placement of a program in the workspace that deflects least.

A placement t (mm) puts the program's origin at t in the base frame (the program's axes
parallel to the base's). Over a region (a box the whole program must stay in), the search
looks for the t that minimises the worst (or RMS) deflection |delta| along the program's
feed moves under its force, every programmed point (rapids' too) reachable and away from
singularities: the model's conditioning at least :data:`MIN_CONDITIONING`.

Method: the objective on a coarse grid of placements (:data:`GRID` per axis; a planar
mechanism places in x, y only), at a subset of the program's points; then a compass
search from the best three feasible grid points, on points at most :data:`DENSE_MM` apart
along the feed moves, the step halved down to :data:`STEP_MM`. A long program (more than
:data:`SEARCH_POINTS` such points) is searched on a sample instead (:func:`search_samples`:
its vertices and points spread by arc length, at most :data:`SEARCH_POINTS`), and the
searched placements are then checked on every point, best first: the first feasible one
is kept, with its objective on every point. A serial arm's searches run on fewer points
(:data:`ARM_COMPASS_POINTS`) and are polished on the sample; its configurations are followed
from one placement to the next (:func:`_follow`) rather than solved afresh. A placement is feasible
when the programmed points and their commanded points (pushed :data:`REACH_MARGIN_MM`
outwards: the optimum often lies on the edge of the workspace) are all evaluable. The
grid's values are kept for the placement map.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..models.delta import DeltaRobot
from ..models.prr3 import PRR3
from ..models.serial import SerialRobot
from .compensate import CHECK_SAMPLES
from .forces import ForceSpec, force_at
from .path import Toolpath

__all__ = [
    "Placement",
    "place_program",
    "default_region",
    "program_samples",
    "search_samples",
    "objective_at",
    "MIN_CONDITIONING",
    "OBJECTIVES",
]

#: A placement is feasible when the model's conditioning (in [0, 1]) is at least this at every point.
MIN_CONDITIONING = 0.05
#: Coarse grid points per axis (planar, spatial).
GRID = {2: 25, 3: 9}
#: The compass search stops when its step is below this, mm.
STEP_MM = 0.02
#: Points of the program the coarse grid evaluates (a subset when there are more).
COARSE_POINTS = 400
#: The compass search checks the program's feed moves at least every this many mm.
DENSE_MM = 1.0
#: The compass search runs on at most this many of the program's points (a longer program: a sample).
SEARCH_POINTS = 2000
#: Grid points the compass search starts from (on a long program, more when the first fail on
#: every point: at most :data:`MAX_STARTS`).
STARTS = 3
MAX_STARTS = 12
#: An arm's compass searches run on this many of the program's points, then are polished on
#: the search's points (at most SEARCH_POINTS) from a step of POLISH_MM (mm).
ARM_COMPASS_POINTS = 400
POLISH_MM = 2.0
#: A searched placement that fails on a point its sample left out is searched again with the
#: failing points (at most REPAIR_POINTS) added to the sample, at most REPAIRS times (:func:`_checked`).
REPAIRS = 3
REPAIR_POINTS = 200
#: An arm's configurations are followed from one placement to the next in steps of at most
#: this (mm); a point whose joint turns more than FOLLOW_JUMP_RAD in one step is not followed.
FOLLOW_MM = 20.0
FOLLOW_JUMP_RAD = 0.5
#: An arm's compass search (objective "worst") evaluates a neighbour on every point only if it
#: beats the incumbent on the program's first point and on these many points the incumbent
#: deflects most (:func:`_may_beat`).
WATCH_POINTS = 16
#: Commanded points are checked this far (mm) beyond where they are, away from the program's centre.
REACH_MARGIN_MM = 0.01


@dataclass(frozen=True)
class Placement:
    """A placement and the search's grid.

    Attributes
    ----------
    place : ndarray, shape (3,), mm
        The program's origin in the base frame.
    value : float, mm
        The objective there (worst or RMS |delta|).
    objective : str
        ``"worst"`` or ``"rms"``.
    grid : tuple of ndarray
        The coarse grid's axes (mm), one per placed axis.
    values : ndarray
        The objective on the grid (NaN where infeasible), shape of the grid.
    evaluations : int
        Placements evaluated.
    """

    place: np.ndarray
    value: float
    objective: str
    grid: tuple[np.ndarray, ...]
    values: np.ndarray
    evaluations: int


#: What ``--place auto`` minimises: the worst or the RMS deflection along the program.
OBJECTIVES = ("worst", "rms")


def default_region(mechanism) -> tuple[np.ndarray, np.ndarray]:
    """A box (lo, hi) in mm, base frame, that holds a mechanism's workspace.

    Raises
    ------
    InputError
        For a mechanism without a known workspace box (give ``--place-region``).
    """
    if isinstance(mechanism, PRR3):
        return np.array([0.0, 0.0, -1e3]), np.array([mechanism.h, mechanism.h * math.sqrt(3) / 2, 1e3])
    if isinstance(mechanism, DeltaRobot):
        r = mechanism.base_radius + mechanism.arm_length
        return np.array([-r, -r, -(mechanism.arm_length + mechanism.forearm_length)]), np.array([r, r, 0.0])
    if isinstance(mechanism, SerialRobot):
        L = 1.5 * mechanism.length
        return np.array([-L, -L, -L]), np.array([L, L, L])
    raise InputError(
        f"--place auto: no default region for {mechanism.name}: give --place-region X0:X1,Y0:Y1[,Z0:Z1] (mm)"
    )


def program_samples(
    path: Toolpath, forces: ForceSpec, per_move: int = CHECK_SAMPLES, dense_mm: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points where the objective is evaluated: every move's ends and ``per_move`` points inside
    each feed move (at least one every ``dense_mm`` when given); with the force there (zero on
    rapids) and whether it is a feed point.

    Returns
    -------
    P : ndarray, shape (N, 3), mm, program frame
    F : ndarray, shape (N, 3), N
    feed : ndarray of bool, shape (N,)
    """
    n = len(path)
    k = np.where(path.feed, per_move + 2, 2)
    if dense_mm is not None:
        k = np.where(path.feed, np.maximum(k, np.ceil(path.length() / dense_mm).astype(int) + 1), 2)
    m = np.repeat(np.arange(n), k)
    s = np.concatenate([np.linspace(0.0, 1.0, c) for c in k]) if n else np.zeros(0)
    return _samples_at(path, forces, m, s)


def search_samples(
    path: Toolpath, forces: ForceSpec, budget: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At most about ``budget`` (default :data:`SEARCH_POINTS`) points of a program for the
    placement search: the moves' ends (every k-th when there are more than half the budget, and
    each axis's extreme ends), and
    the rest of the budget spread evenly by arc length along the feed moves. Returns as
    :func:`program_samples`."""
    budget = SEARCH_POINTS if budget is None else budget
    n = len(path)
    if n == 0:
        return program_samples(path, forces)
    ends = path.point(np.arange(n), np.ones(n))
    every = max(1, math.ceil(n / max(1, budget // 2)))
    mv = np.unique(np.concatenate([np.arange(0, n, every), ends.argmin(axis=0), ends.argmax(axis=0)]))
    L = np.where(path.feed, path.length(), 0.0)
    cum = np.cumsum(L)
    r = max(0, budget - 1 - mv.size)
    u = (np.arange(r) + 0.5) * (cum[-1] / r) if r and cum[-1] > 0 else np.zeros(0)
    mr = np.minimum(np.searchsorted(cum, u, side="right"), n - 1)
    sr = np.clip((u - (cum[mr] - L[mr])) / np.where(L[mr] > 0, L[mr], 1.0), 0.0, 1.0)
    m = np.concatenate([[0], mv, mr])
    s = np.concatenate([[0.0], np.ones(mv.size), sr])
    return _samples_at(path, forces, m, s)


def _samples_at(path: Toolpath, forces: ForceSpec, m: np.ndarray, s: np.ndarray):
    """The points, forces and feed flags at moves m and fractions s (a rapid's ends only,
    points with an unknown axis left out)."""
    keep = path.feed[m] | (s == 0) | (s == 1)
    keep &= np.where(s == 0, np.all(path.known_start[m], axis=1), np.all(path.known[m], axis=1))
    m, s = m[keep], s[keep]
    return path.point(m, s), force_at(path, forces, m, s), path.feed[m]


def objective_at(fld, place, P, F, feed, objective: str) -> float:
    """The objective (mm) at one placement: inf when a point is infeasible (:func:`_many`)."""
    return float(_many(fld, np.asarray(place, dtype=float)[None], P, F, feed, objective)[0][0])


def _evaluate(
    fld, T: np.ndarray, P: np.ndarray, F: np.ndarray, q0=None, origin=None, *, all_or_none: bool = False
) -> tuple[np.ndarray, np.ndarray, object]:
    """Deflections (K, N, 3) at N points under K placements T (K, 3), which points are feasible
    under each placement (K, N: valid, conditioning at least MIN_CONDITIONING), and an arm's
    configurations (K, N, n) (else None). P is (N, 3), or (K, N, 3) for points that differ per
    placement. One evaluation for a mechanism's map; placement by placement for an arm: its
    inverse kinematics from ``q0`` (K, N, n), else followed from ``origin`` (a nearby placement
    and its configurations at P, :func:`_follow`), else along the points in order (with
    ``all_or_none``, for a caller that only asks whether every point is feasible, up to the first
    that does not converge or puts a joint beyond its limits: :meth:`ArmField.solve_path`)."""
    K = T.shape[0]
    PK = np.broadcast_to(P, (K, *P.shape[-2:]))
    N = PK.shape[1]
    Q = None
    if hasattr(fld, "mechanism"):
        res = fld.with_place(np.zeros(3))((PK + T[:, None]).reshape(-1, 3), np.tile(F, (K, 1)))
        valid, cond, delta = res.valid, res.conditioning, res.delta
    else:
        out = []
        for i, t in enumerate(T):
            f = fld.with_place(t)
            if q0 is None and origin is not None:
                Qf, conv = _follow(fld, origin[0], origin[1], t, PK[i])
                same = _seed_branch(f, PK[i], Qf, conv)  # else solved afresh, as without origin
                out.append(f.deflect(PK[i], F, Qf, conv) if same else f(PK[i], F, stop=all_or_none))
            else:
                out.append(f(PK[i], F, q0=None if q0 is None else q0[i], stop=all_or_none))
        Q = np.stack([r.q for r in out]) if all(r.q is not None for r in out) else None
        valid = np.concatenate([r.valid for r in out])
        cond = np.concatenate([r.conditioning for r in out])
        delta = np.concatenate([r.delta for r in out])
    ok = valid.reshape(K, N) & (np.nan_to_num(cond, nan=-1.0).reshape(K, N) >= MIN_CONDITIONING)
    return delta.reshape(K, N, 3), ok, Q


def _seed_branch(f, P, Q, conv) -> bool:
    """Whether configurations Q (N, n) at the points P of an arm's field f, followed from another
    placement, are those its inverse kinematics along the points in order from the seed gives
    (what the compensation uses): the first point's solution from the seed is Q's first row
    (to 1e-6 rad or mm, turns not wrapped), or both do not converge there."""
    q0, ok0 = f.solve_path(P[:1])
    if bool(ok0[0]) != bool(conv[0]):
        return False
    return not ok0[0] or float(np.max(np.abs(q0[0] - Q[0]))) <= 1e-6


def _follow(fld, t0, Q0, t1, P) -> tuple[np.ndarray, np.ndarray]:
    """An arm's configurations at the points P placed at t1, followed from its configurations Q0
    (N, n) at P placed at t0: Newton steps (:meth:`ArmField.solve`, every point at once) as the
    placement moves from t0 to t1 in steps of at most :data:`FOLLOW_MM`. A point converges when
    every step does and turns no joint more than :data:`FOLLOW_JUMP_RAD` (else it may have
    jumped to another branch); returns the configurations and which points converged."""
    d = np.asarray(t1, dtype=float) - t0
    k = max(1, math.ceil(float(np.linalg.norm(d)) / FOLLOW_MM))
    Q = np.asarray(Q0, dtype=float)
    ok = np.all(np.isfinite(Q), axis=1)
    Q = np.where(ok[:, None], Q, 0.0)
    for j in range(1, k + 1):
        Qn, conv = fld.with_place(t0 + d * (j / k)).solve(P, Q)
        ok &= conv & (np.max(np.abs(Qn - Q), axis=1) <= FOLLOW_JUMP_RAD)
        Q = np.where(ok[:, None], Qn, Q)
        if not np.any(ok):
            break
    return Q, ok


def _outward(P: np.ndarray, dims) -> np.ndarray:
    """Unit directions (N, 3) from the program's centre to its points, in the placed axes."""
    d = np.zeros_like(P)
    d[:, dims] = P[:, dims] - P[:, dims].mean(axis=0)
    n = np.linalg.norm(d, axis=1)
    return np.divide(d, n[:, None], out=np.zeros_like(d), where=n[:, None] > 0)


def _many(fld, T: np.ndarray, P, F, feed, objective: str, origin=None) -> tuple[np.ndarray, object]:
    """The objective at many placements T (K, 3); inf where a programmed point, or the commanded
    point ``c = p - delta(c)`` that compensates it (two fixed-point steps) pushed outwards by
    :data:`REACH_MARGIN_MM`, is out of reach or too poorly conditioned; and an arm's
    configurations at the programmed points (K, N, n), else None. Without ``origin`` (an arm's
    nearby placement and configurations to follow, :func:`_follow`), the placements are first
    screened on the points at each axis's extremes (an arm solves its inverse kinematics point
    by point: most placements of a large program fail there, at a few points' cost)."""
    out = np.full(T.shape[0], np.inf)
    ok = np.ones(T.shape[0], dtype=bool)
    if origin is None and P.shape[0] > 6 * 4:
        ext = _extremes(P)
        ok = _evaluate(fld, T, P[ext], F[ext], all_or_none=True)[1].all(axis=1)
    Q = None
    if np.any(ok):
        out[ok], Qok, _ = _many_all(fld, T[ok], P, F, feed, objective, origin, all_or_none=True)
        if Qok is not None:
            Q = np.full((T.shape[0], *Qok.shape[1:]), np.nan)
            Q[ok] = Qok
    return out, Q


def _extremes(P: np.ndarray) -> np.ndarray:
    """The indices of the points at each axis's extremes."""
    return np.unique(np.concatenate([P.argmin(axis=0), P.argmax(axis=0)]))


def _many_all(
    fld, T: np.ndarray, P, F, feed, objective: str, origin=None, *, all_or_none: bool = False
) -> tuple[np.ndarray, object, np.ndarray]:
    """:func:`_many` on every point, and which points are feasible under each placement (K, N):
    the programmed point and its commanded points (``all_or_none``: up to the first invalid one,
    :func:`_evaluate`)."""
    delta, okp, Q = _evaluate(fld, T, P, F, origin=origin, all_or_none=all_or_none)
    ok = okp.all(axis=1)
    if np.any(ok):
        sub = np.flatnonzero(ok)
        okp[sub] &= _commanded_ok(fld, T[sub], P, F, delta[sub], None if Q is None else Q[sub])
    return np.where(okp.all(axis=1), _value(delta, feed, objective), np.inf), Q, okp


def _commanded_ok(fld, T: np.ndarray, P, F, delta, near) -> np.ndarray:
    """Which commanded points (K, N) are feasible under placements T (K, 3): ``c = p - delta(c)``
    (two fixed-point steps from the programmed points' deflections ``delta`` (K, N, 3)), and the
    same pushed outwards by :data:`REACH_MARGIN_MM`; ``near``: an arm's configurations at the
    programmed points (K, N, n), the seeds there (else None)."""
    d1, ok1, _ = _evaluate(fld, T, P[None] - delta, F, near)
    C = P[None] - np.nan_to_num(d1) + REACH_MARGIN_MM * _outward(P, list(fld.corrected))[None]
    return ok1 & _evaluate(fld, T, C, F, near)[1]


def _value(delta: np.ndarray, feed, objective: str) -> np.ndarray:
    """The objective (K,) of deflections (K, N, 3) along the feed points (NaN counts 0)."""
    d = np.linalg.norm(np.nan_to_num(delta), axis=2)[:, feed]
    if d.shape[1] == 0:
        return np.zeros(delta.shape[0])
    return d.max(axis=1) if objective == "worst" else np.sqrt(np.mean(d * d, axis=1))


def _best_below(fld, T: np.ndarray, P, F, feed, objective: str, origin, v: float, watch=None):
    """The best feasible of placements T (K, 3) if its objective is below ``v``: its index, objective
    and an arm's configurations at P (else None); (None, inf, None) if none is. As the argmin of
    :func:`_many`, but the commanded points are checked only for the placements whose programmed
    points are feasible and whose objective beats ``v``, best first (a compass search's step keeps
    one neighbour at most: most steps keep none, and need no such check); with ``watch``
    (:class:`_Watch`), only the placements that may beat ``v`` on its points (:func:`_may_beat`)
    are evaluated on every point, and the points where they fail are added to it."""
    if origin is None:  # no configurations to follow: every point of every placement, as _many
        vals, QK = _many(fld, T, P, F, feed, objective)
        i = int(np.argmin(vals))
        return (i, float(vals[i]), None if QK is None else QK[i]) if vals[i] < v else (None, math.inf, None)
    idx = np.arange(T.shape[0])
    if watch is not None:
        idx = np.flatnonzero(_may_beat(fld, T, P, F, feed, origin, v, watch.points()))
        if idx.size == 0:
            return None, math.inf, None
    delta, okp, Q = _evaluate(fld, T[idx], P, F, origin=origin, all_or_none=True)
    if watch is not None:
        watch.learn(okp)
    vals = np.where(okp.all(axis=1), _value(delta, feed, objective), np.inf)
    for i in np.argsort(vals, kind="stable"):
        if not vals[i] < v:
            break
        near = None if Q is None else Q[i : i + 1]
        if np.all(_commanded_ok(fld, T[idx[i : i + 1]], P, F, delta[i : i + 1], near)):
            return int(idx[i]), float(vals[i]), None if Q is None else Q[i]
    return None, math.inf, None


def _may_beat(fld, T: np.ndarray, P, F, feed, origin, v: float, w: np.ndarray) -> np.ndarray:
    """Which of an arm's placements T (K, 3) may have a worst deflection below ``v``, from the points
    P[w] alone (w[0] = 0: the program's first point, whose solution from the seed says whether
    the followed configurations are the compensation's): not one whose configurations there,
    followed from ``origin`` as :func:`_evaluate` follows them, are infeasible or deflect a feed
    point by ``v`` or more (its objective on every point would be at least that). A placement whose
    first point is on another branch (solved afresh along every point) may."""
    t0, Q0 = origin
    Pw, Fw, fw = P[w], F[w], feed[w]
    out = np.ones(T.shape[0], dtype=bool)
    for i, t in enumerate(T):
        f = fld.with_place(t)
        Qf, conv = _follow(fld, t0, Q0[w], t, Pw)
        if not _seed_branch(f, Pw, Qf, conv):
            continue
        res = f.deflect(Pw, Fw, Qf, conv)
        ok = res.valid & (np.nan_to_num(res.conditioning, nan=-1.0) >= MIN_CONDITIONING)
        d = np.linalg.norm(np.nan_to_num(res.delta), axis=1)[fw]
        out[i] = bool(np.all(ok)) and not (d.size and d.max() >= v)
    return out


class _Watch:
    """The points an arm's compass search (objective ``"worst"``) screens its neighbours on
    (:func:`_may_beat`): the program's first point, the :data:`WATCH_POINTS` feed points the
    incumbent deflects most (:meth:`at`), and the first point where each neighbour evaluated on
    every point was infeasible (:meth:`learn`; the optimum is often on the edge of the workspace,
    its neighbours beyond it at a few points), at most :data:`WATCH_POINTS` of them."""

    def __init__(self) -> None:
        self.top = np.zeros(0, dtype=int)
        self.failed: list[int] = []

    def at(self, fld, t, P, F, feed, Q) -> _Watch:
        """Watch the feed points the placement t (configurations Q at P, all feasible) deflects most."""
        d = np.linalg.norm(fld.with_place(t).deflect(P, F, Q, np.ones(P.shape[0], dtype=bool)).delta, axis=1)
        d = np.where(feed, np.nan_to_num(d), -1.0)
        top = np.argsort(-d, kind="stable")[:WATCH_POINTS]
        self.top = top[d[top] >= 0]
        return self

    def learn(self, okp: np.ndarray) -> None:
        """Watch the first infeasible point of each row of okp (K, N) too."""
        for row in okp:
            bad = np.flatnonzero(~row)
            if bad.size and int(bad[0]) not in self.failed and len(self.failed) < WATCH_POINTS:
                self.failed.append(int(bad[0]))

    def points(self) -> np.ndarray:
        """The watched points' indices, the program's first (0) first."""
        rest = np.concatenate([self.top, np.asarray(self.failed, dtype=int)])
        rest = rest[rest != 0]
        return np.concatenate([[0], rest[np.sort(np.unique(rest, return_index=True)[1])]])


def place_program(
    fld,
    path: Toolpath,
    forces: ForceSpec,
    *,
    region=None,
    objective: str = "worst",
    progress: Callable[[str, int, int], None] | None = None,
) -> Placement:
    """The placement of the program that minimises the objective (module docstring).

    Parameters
    ----------
    fld : MechanismField or ArmField
    path : Toolpath
    forces : ForceSpec
    region : tuple (lo, hi) of array_like (3,), mm, optional
        The box the program must stay in (default :func:`default_region`).
    objective : str
        ``"worst"`` or ``"rms"`` deflection along the feed moves.
    progress : callable (what, done, total), optional
        Called as the search goes: ``"placement grid"`` with the grid's placements evaluated,
        then ``"placement search"`` with the compass searches' step halvings done (its total
        grows when more starts are needed); each count rises to its total.

    Raises
    ------
    InputError
        No feasible placement in the region, or the program does not fit in it.
    """
    if objective not in OBJECTIVES:
        raise InputError(f"--objective must be worst or rms, got {objective!r}")
    dims = list(fld.corrected)
    lo, hi = (
        region
        if region is not None
        else default_region(getattr(fld, "mechanism", getattr(fld, "robot", None)))
    )
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    P, F, feed = program_samples(path, forces)
    bmin, bmax = P.min(axis=0), P.max(axis=0)
    tlo, thi = lo - bmin, hi - bmax
    if np.any(thi[dims] < tlo[dims]):
        raise InputError("--place auto: the program is larger than the region it must stay in")
    axes = tuple(np.linspace(tlo[k], thi[k], GRID[len(dims)]) for k in dims)
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(dims))
    T = np.zeros((mesh.shape[0], 3))
    T[:, dims] = mesh
    sub = np.linspace(0, P.shape[0] - 1, min(P.shape[0], COARSE_POINTS)).round().astype(int)
    chunks = np.array_split(T, range(axes[0].size, T.shape[0], axes[0].size))  # a grid line each
    coarse = []
    for Tc in chunks:
        coarse.append(_many(fld, Tc, P[sub], F[sub], feed[sub], objective)[0])
        if progress is not None:
            progress("placement grid", sum(c.size for c in coarse), T.shape[0])
    coarse = np.concatenate(coarse)
    values = np.where(np.isfinite(coarse), coarse, np.nan).reshape(tuple(a.size for a in axes))
    if not np.any(np.isfinite(coarse)):
        raise InputError(
            "--place auto: no placement in the region keeps every point of the program reachable and away "
            f"from singularities (conditioning >= {MIN_CONDITIONING:g})"
        )
    step0 = np.array([(a[1] - a[0]) if a.size > 1 else 1.0 for a in axes])
    starts = T[np.argsort(coarse)[: int(np.isfinite(coarse).sum())]]
    box = (tlo, thi)
    best_t, best_v, n = _refine(fld, path, forces, starts, dims, step0 / 2, objective, _Ticks(progress), box)
    if not np.isfinite(best_v):
        raise InputError("--place auto: no feasible placement on all of the program's points")
    return Placement(best_t, best_v, objective, axes, values, T.shape[0] + n)


def _refine(
    fld, path, forces, starts, dims, step, objective, ticks, box
) -> tuple[np.ndarray | None, float, int]:
    """The best placement of compass searches from ``starts`` (best first), and the placements
    evaluated. On a program of at most :data:`SEARCH_POINTS` dense points: the best of the first
    :data:`STARTS` searches on every point. On a longer one: the searches run on
    :func:`search_samples`, and their results are checked on every point best first
    (more starts while none passes, :data:`STARTS` at a time, up to :data:`MAX_STARTS`); the first
    feasible one is returned with its objective on every point. For an arm (its inverse
    kinematics per placement), the searches run on :data:`ARM_COMPASS_POINTS` points
    (:func:`search_samples`) and each result is polished, best first, on the points above by a
    compass search from a step of :data:`POLISH_MM` before its check. ``ticks`` (:class:`_Ticks`)
    counts the searches' step halvings; ``box`` (lo, hi) bounds the placements searched."""
    Pd, Fd, feedd = program_samples(path, forces, dense_mm=DENSE_MM)
    full = Pd.shape[0] <= SEARCH_POINTS
    fine = (Pd, Fd, feedd) if full else search_samples(path, forces)
    arm = not hasattr(fld, "mechanism") and fine[0].shape[0] > ARM_COMPASS_POINTS
    coarse = search_samples(path, forces, ARM_COMPASS_POINTS) if arm else fine
    polish = np.full(step.shape, POLISH_MM)
    evals = 0
    for k in range(0, min(STARTS if full and not arm else MAX_STARTS, starts.shape[0]), STARTS):
        batch = starts[k : k + STARTS]
        ticks.plan(len(batch) * (_halvings(step) + (_halvings(polish) if arm else 0)))
        found = []
        for t0 in batch:
            t, v, n, Q = _compass(fld, t0, dims, step, *coarse, objective, box, ticks.tick)
            evals += n
            found.append((v, t, Q))
        for v, t, Q in sorted(found, key=lambda c: c[0]):
            if arm and np.isfinite(v):
                t, v, n, Q = _compass(
                    fld, t, dims, polish, *fine, objective, box, ticks.tick, (t, coarse[0], Q)
                )
                evals += n
            if full and (not arm or np.isfinite(v)):
                ticks.finish()
                return t, v, evals
            if np.isfinite(v):
                t, v_all, n, fine = _checked(fld, t, Q, (Pd, Fd, feedd), fine, dims, objective, box, ticks)
                evals += n
                if np.isfinite(v_all):
                    ticks.finish()
                    return t, v_all, evals
        ticks.finish()
    return None, math.inf, evals


def _feasible_near(fld, t, dims, sample, objective, box, known=None) -> tuple[np.ndarray | None, int]:
    """The best feasible placement on ``sample`` (points, forces, feed flags) among t's neighbours
    along each placed axis, POLISH_MM away, then twice as far... up to 32 POLISH_MM (within the box);
    None if there is none. And the placements evaluated. An arm's configurations are followed
    from ``known`` (:func:`_near_origin`) when given and that works."""
    lo, hi = box[0][dims] - 1e-9, box[1][dims] + 1e-9
    origin = None if known is None else _near_origin(fld, known, np.asarray(t, dtype=float), sample[0])
    evals = 0
    for k in range(6):
        cand = []
        for j in dims:
            for sgn in (-1.0, 1.0):
                c = np.array(t, dtype=float)
                c[j] += sgn * POLISH_MM * 2**k
                if np.all((c[dims] >= lo) & (c[dims] <= hi)):
                    cand.append(c)
        if not cand:
            continue
        vals = _many(fld, np.array(cand), *sample, objective, origin)[0]
        evals += len(cand)
        if np.any(np.isfinite(vals)):
            return cand[int(np.argmin(vals))], evals
    return None, evals


def _halvings(step) -> int:
    """How many times a compass search halves ``step`` before it stops."""
    return max(0, math.ceil(math.log2(float(np.max(step)) / STEP_MM)))


class _Ticks:
    """The compass searches' progress, in step halvings: ``progress("placement search", done,
    total)`` (:func:`place_program`); ``total`` grows as searches are planned."""

    def __init__(self, progress):
        self.progress, self.done, self.total = progress, 0, 0

    def plan(self, n: int) -> None:
        self.total += n

    def tick(self) -> None:
        self.done = min(self.done + 1, self.total)
        self._say()

    def finish(self) -> None:
        self.done = self.total
        self._say()

    def _say(self) -> None:
        if self.progress is not None:
            self.progress("placement search", self.done, self.total)


def _every_point(fld, t, P, F, feed, objective, Ps, Qs) -> tuple[float, np.ndarray]:
    """:func:`objective_at` t on the points P, and the indices of the points that fail there (a
    programmed point or its commanded points; only those at the axes' extremes when one of them
    fails). An arm's configurations there start from its configurations Qs at the nearest of the
    points Ps (:func:`_follow`, all at once), and are solved along the points in order (as without
    Qs) if that does not converge everywhere or turns a joint more than :data:`FOLLOW_JUMP_RAD`
    between two points."""
    origin = None if Qs is None else _near_origin(fld, (t, Ps, Qs), t, P, ordered=True)
    if origin is None:  # solved along the points in order: screened on the extremes first
        ext = _extremes(P)
        ok = _evaluate(fld, t[None], P[ext], F[ext])[1][0]
        if not np.all(ok):
            return math.inf, ext[~ok]
    val, _, okp = _many_all(fld, t[None], P, F, feed, objective, origin)
    return float(val[0]), np.flatnonzero(~okp[0])


def _near_origin(fld, known, t, P, ordered: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """An arm's configurations at the points P placed at t, as an ``origin`` for :func:`_evaluate`
    (t, Q): followed (:func:`_follow`, all at once) from ``known`` (t0, Ps, Qs), its configurations
    Qs at the points Ps placed at t0, each point from the nearest of Ps; None (solve along the
    points in order) if that does not converge everywhere or, for points in the program's order
    (``ordered``), turns a joint more than :data:`FOLLOW_JUMP_RAD` between two points (a sample's
    points are not in order: each is held within that of its nearest known one by :func:`_follow`,
    as a compass search's neighbours are)."""
    t0, Ps, Qs = known
    Q, conv = _follow(fld, t0, Qs[cKDTree(Ps).query(P)[1]], t, P)
    if not np.all(conv):
        return None
    if ordered and np.max(np.abs(np.diff(Q, axis=0)), initial=0.0) > FOLLOW_JUMP_RAD:
        return None
    return t, Q


def _checked(fld, t, Q, dense, fine, dims, objective, box, ticks):
    """A searched placement t checked on every point (``dense``: points, forces, feed flags; an
    arm's configurations Q at the sample's points ``fine[0]``). When it fails, the failing points
    (at most :data:`REPAIR_POINTS` of them) are added to the sample and the search goes on from
    the best feasible placement near t (:func:`_feasible_near`; a compass search from
    :data:`POLISH_MM`), at most :data:`REPAIRS` times: a sample between
    whose points a constraint is tightest (a joint at its limit in the middle of an edge) otherwise
    leads the search to a placement that fails there. Returns the placement, its objective on every
    point (inf if none passes), the placements evaluated, and the sample with the points added."""
    evals = 0
    for attempt in range(REPAIRS + 1):
        evals += 1
        v_all, bad = _every_point(fld, t, *dense, objective, fine[0], Q)
        if np.isfinite(v_all) or attempt == REPAIRS or bad.size == 0:
            break
        pick = bad[np.linspace(0, bad.size - 1, min(bad.size, REPAIR_POINTS)).round().astype(int)]
        known = None if Q is None else (t, fine[0], Q)
        fine = tuple(np.concatenate([a, b[pick]]) for a, b in zip(fine, dense, strict=True))
        t, n = _feasible_near(fld, t, dims, fine, objective, box, known)
        evals += n
        if t is None:
            break
        polish = np.full(len(dims), POLISH_MM)
        ticks.plan(_halvings(polish))
        t, v, n, Q = _compass(fld, t, dims, polish, *fine, objective, box, ticks.tick, known)
        evals += n
    return t, v_all if np.isfinite(v_all) else math.inf, evals, fine


def _compass(
    fld, t0, dims, step, P, F, feed, objective, box, tick=None, known=None
) -> tuple[np.ndarray, float, int, object]:
    """Compass search from t0 on the points P: the best neighbour along each axis within the box
    (lo, hi) of placements, steps halved (``tick()`` called at each halving). Returns the
    placement, its objective, the placements evaluated, and an arm's configurations at P there
    (else None); an arm's are followed from the current placement to its neighbours, and at t0
    from ``known`` (t, Ps, Qs: its configurations Qs at points Ps placed at t, :func:`_near_origin`)
    when given and that works, else solved along the points in order."""
    t = t0.copy()
    origin = None if known is None else _near_origin(fld, known, t, P)
    vals, QK = _many(fld, t[None], P, F, feed, objective, origin)
    v, Q = float(vals[0]), None if QK is None else QK[0]
    watch = _Watch() if objective == "worst" and Q is not None else None
    if watch is not None and np.isfinite(v):
        watch.at(fld, t, P, F, feed, Q)
    n = 1
    step = step.copy()
    lo, hi = box[0][dims] - 1e-9, box[1][dims] + 1e-9
    while np.max(step) > STEP_MM:
        cand = []
        for j, k in enumerate(dims):
            for sgn in (-1.0, 1.0):
                c = t.copy()
                c[k] += sgn * step[j]
                if np.all((c[dims] >= lo) & (c[dims] <= hi)):
                    cand.append(c)
        origin = None if Q is None or not np.isfinite(v) else (t, Q)
        i, vi, Qi = (
            (None, v, Q)
            if not cand
            else _best_below(fld, np.array(cand), P, F, feed, objective, origin, v, watch)
        )
        n += len(cand)
        if i is not None:
            t, v, Q = cand[i], vi, Qi
            if watch is not None:
                watch.at(fld, t, P, F, feed, Q)
        else:
            step /= 2
            if tick is not None:
                tick()
    return t, v, n, Q
