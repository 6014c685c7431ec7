"""What a platform that turns can do: its mobility, and the pose it reaches nearest a requested one.

A ``dim = 6`` legs robot (:class:`~stiffmap.models.legs6.LegRobot6`) with fewer than six
degrees of freedom (a 3-RPS: z, roll, pitch) cannot hold every pose: the coordinates it
does not control follow from the others (its *parasitic motion*: a 3-RPS's x, y and yaw, such
that each ball joint stays in its leg's plane).

:func:`platform_mobility` finds them from the legs at the home pose (the platform level at
:meth:`~stiffmap.models.legs.LegRobot.home`): each leg, its actuator free, holds the wrenches
reciprocal to its actuated and passive columns (a 6-UPS leg: none; a 3-RPS leg: the force
along its revolute joint's axis through its ball); carried to the tool point and stacked,
their rank c leaves the platform ``6 - c`` degrees of freedom, the twists reciprocal to them.
The free coordinates are the ``6 - c`` pose coordinates that parameterise those twists best
(the largest ``|det|`` of the mobility basis's rows, rotations counted as
:attr:`~stiffmap.models.legs6.LegRobot6.length_mm` mm per rad): the ones the legs do not
constrain at home. :func:`reachable_poses` keeps those at the requested values and solves the
others by Gauss-Newton on the legs' closure residuals (each leg's platform joint's distance
from the nearest point its chain reaches, actuator free). A full-mobility robot (a hexapod)
gets its poses back unchanged.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..geometry import matrix_from_euler
from .base import POSE_DIM, RANK_RTOL, as_points, constrained_directions, skew

__all__ = [
    "Mobility",
    "COORDINATES",
    "platform_mobility",
    "reachable_poses",
    "held_as_given",
    "lower_mobility",
    "nearest_held",
    "nearest_pose_note",
    "pose_text",
    "CLOSURE_TOL_MM",
    "HELD_TOL_MM",
]

#: The pose coordinates, in order.
COORDINATES = ("x", "y", "z", "roll", "pitch", "yaw")
#: A pose is closed when every leg's platform joint is this close to where its chain reaches (mm).
CLOSURE_TOL_MM = 1e-10
#: A solved pose is one the platform holds when its legs close this well (mm).
HELD_TOL_MM = 1e-6
#: Most Gauss-Newton steps per pose.
MAX_STEPS = 30


@dataclass(frozen=True)
class Mobility:
    """The degrees of freedom of a platform at its home pose.

    Attributes
    ----------
    rank : int
        How many (6 for a hexapod, 3 for a 3-RPS).
    free : tuple of int
        The pose coordinates it controls (indices into :data:`COORDINATES`).
    twists : ndarray, shape (6, rank)
        An orthonormal basis of its motions at the tool point (u mm, rotation times the
        robot's size in mm).
    held : ndarray, shape (6, 6 - rank)
        An orthonormal basis of the wrenches its legs hold there (force N, moment over the size).
    """

    rank: int
    free: tuple[int, ...]
    twists: np.ndarray
    held: np.ndarray

    @property
    def follow(self) -> tuple[int, ...]:
        """The coordinates that follow from the free ones."""
        return tuple(j for j in range(POSE_DIM) if j not in self.free)

    def describe(self, name: str) -> str:
        """``"3rps moves in z, roll, pitch: x, y, yaw follow"`` (or ``"... in all six coordinates"``)."""
        if not self.follow:
            return f"{name} moves in all six coordinates"
        names = [", ".join(COORDINATES[j] for j in js) for js in (self.free, self.follow)]
        return f"{name} moves in {names[0]}: {names[1]} follow{'s' if len(self.follow) == 1 else ''}"


def _leg_targets(model, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each leg's platform joint at ``pose`` (legs, 3), its arm ``R attach`` and d(target)/d(pose)."""
    R = matrix_from_euler(pose[3:])
    attach = np.array([d.attach_mm for d in model.description], dtype=float)
    arms = attach @ R.T
    # Euler rates to the angular velocity (R = Rz(yaw) Ry(pitch) Rx(roll)): omega = E d(rpy).
    E = np.stack(
        [
            matrix_from_euler([0.0, pose[4], pose[5]])[:, 0],
            matrix_from_euler([0.0, 0.0, pose[5]])[:, 1],
            [0.0, 0.0, 1.0],
        ],
        axis=1,
    )
    T = np.zeros((len(arms), 3, POSE_DIM))
    T[:, :, :3] = np.eye(3)
    T[:, :, 3:] = -skew(arms) @ E  # d(P + R a) = du + omega x (R a)
    return pose[:3] + arms, arms, T


def platform_mobility(model, pose=None) -> Mobility:
    """The platform's degrees of freedom at ``pose`` (default: home, level) and the coordinates it controls.

    Parameters
    ----------
    model : LegRobot6
    pose : array_like, shape (6,), optional
        x, y, z (mm), roll, pitch, yaw (rad); default the home position, the platform level.

    Returns
    -------
    Mobility

    Raises
    ------
    ValueError
        A pose the legs do not reach (their reason).

    Examples
    --------
    >>> from importlib.resources import files
    >>> from stiffmap.models.legs import LegRobot
    >>> m = platform_mobility(LegRobot.from_toml(files("stiffmap.models") / "robots" / "3rps.toml"))
    >>> m.rank, m.free
    (3, (2, 3, 4))
    >>> m.describe("3rps")
    '3rps moves in z, roll, pitch: x, y, yaw follow'
    """
    p = np.r_[model.home()[0], 0.0, 0.0, 0.0] if pose is None else as_points(pose, POSE_DIM)[0][0]
    st = model.legs(p[None])
    if not st.reachable[0]:
        raise ValueError(st.reasons[0])
    L = model.length_mm
    S = np.array([1.0, 1.0, 1.0, L, L, L])
    free_cols = np.concatenate([st.actuated[0], st.passive[0]], axis=-1) * S[:, None]  # (legs, 6, m)
    U, held = constrained_directions(free_cols)
    W = U * held[..., None, :]  # each leg's held wrenches (f, m / L) at its platform joint
    A = np.zeros((len(W), 6, 6))  # the wrench carried to the tool point: m / L + (r / L) x f
    A[:, :3, :3] = A[:, 3:, 3:] = np.eye(3)
    A[:, 3:, :3] = skew(st.arms[0] / L)
    Z = np.concatenate(list(A @ W), axis=1)  # (6, legs * 6)
    Uz, sv, _ = np.linalg.svd(Z)
    c = int(np.sum(sv > RANK_RTOL * max(sv[0], 1e-300))) if sv.size and sv[0] > 0 else 0
    twists, wrenches = Uz[:, c:], Uz[:, :c]
    rank = POSE_DIM - c
    best, free = -1.0, tuple(range(rank))
    for js in itertools.combinations(range(POSE_DIM), rank):  # the coordinates that move it best
        d = abs(float(np.linalg.det(twists[list(js), :]))) if rank else 1.0
        if d > best * (1 + 1e-9):
            best, free = d, js
    return Mobility(rank, tuple(int(j) for j in free), twists, wrenches)


def _closure(model, pose: np.ndarray, qs: list, follow: list[int]):
    """The legs' closure residuals at ``pose`` (legs * 3, mm) and their derivative in the ``follow``
    coordinates; each leg's joints (least squares from ``qs``, its actuator free) updated."""
    targets, _, T = _leg_targets(model, pose)
    r, J = [], []
    for k, (chain, _) in enumerate(model.leg_chains()):
        res = chain.inverse(targets[k], q0=qs[k], max_iter=50)
        qs[k] = res.q
        e = targets[k] - chain.forward(res.q)[0]
        U, held = constrained_directions(chain.jacobian(res.q)[:3])
        Q = U[:, held] @ U[:, held].T  # the leg's tip moves freely across the rest
        r.append(Q @ e)
        J.append(Q @ T[k][:, follow])
    return np.concatenate(r), np.concatenate(J)


def reachable_poses(model, poses, mobility: Mobility | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The poses the robot reaches nearest ``poses``: its free coordinates as given, the others solved.

    Gauss-Newton on the legs' closure residuals (module docstring) from the requested pose,
    each leg's joints from its seed's branch. A full-mobility robot's poses come back unchanged.

    Parameters
    ----------
    model : LegRobot6
    poses : array_like, shape (N, 6) or (6,)
        x, y, z (mm), roll, pitch, yaw (rad).
    mobility : Mobility, optional
        :func:`platform_mobility`'s (default: at home).

    Returns
    -------
    poses : ndarray, shape (N, 6) or (6,)
    closure_mm : ndarray, shape (N,) or ()
        The largest distance left between a leg's platform joint and where its chain reaches
        (below :data:`CLOSURE_TOL_MM` where solved; larger where the legs cannot close).

    Examples
    --------
    >>> from importlib.resources import files
    >>> from stiffmap.models.legs import LegRobot
    >>> robot = LegRobot.from_toml(files("stiffmap.models") / "robots" / "3rps.toml")
    >>> pose, gap = reachable_poses(robot, [0, 0, 250, 0.1, 0, 0])  # 5.7 deg of roll at 250 mm
    >>> [round(float(v), 4) + 0.0 for v in pose], bool(gap < 1e-9)
    ([0.0, -0.2498, 250.0, 0.1, 0.0, 0.0], True)
    """
    P, single = as_points(poses, POSE_DIM)
    out, gap = P.copy(), np.zeros(len(P))
    mob = platform_mobility(model) if mobility is None else mobility
    follow = list(mob.follow)
    if follow:
        for i in range(len(P)):
            out[i], gap[i] = _solve_one(model, out[i], follow)
    return (out[0], gap[0]) if single else (out, gap)


def _solve_one(model, pose: np.ndarray, follow: list[int]) -> tuple[np.ndarray, float]:
    """One pose's ``follow`` coordinates solved (Gauss-Newton); the pose and the closure left (mm)."""
    p = pose.copy()
    qs = [q0.copy() for _, q0 in model.leg_chains()]
    for _ in range(MAX_STEPS):
        r, J = _closure(model, p, qs, follow)
        if np.max(np.abs(r)) < CLOSURE_TOL_MM:
            break
        p[follow] -= np.linalg.lstsq(J, r, rcond=None)[0]
    r, _ = _closure(model, p, qs, follow)
    return p, float(np.max(np.linalg.norm(r.reshape(-1, 3), axis=1)))


def lower_mobility(model) -> Mobility | None:
    """The platform's mobility at home (:func:`platform_mobility`) when it is below six (a 3-RPS);
    None for a platform that moves in all six coordinates, or whose legs do not reach their home
    (the model says why)."""
    try:
        mob = platform_mobility(model)
    except ValueError:
        return None
    return mob if mob.follow else None


def nearest_held(model, pose, mobility: Mobility) -> np.ndarray | None:
    """The pose (x, y, z mm, roll, pitch, yaw rad, base frame) the platform holds with ``pose``'s
    free coordinates (:func:`reachable_poses`; ``pose`` in the same units), when
    its legs close there and the model can evaluate it (within its strokes and joint limits); None
    otherwise (a 3-RPS rolled 179 deg closes its legs at y = -100 mm, beyond a leg's stroke)."""
    near, gap = reachable_poses(model, pose, mobility)
    if not gap < HELD_TOL_MM or not model.evaluate(near).valid[0]:
        return None
    return near


def pose_text(p) -> str:
    """``"(x, y, z) mm, roll/pitch/yaw (r, p, y) deg"`` of a pose (mm, rad; ``"(x, y, z) mm"`` of a
    position) to 1e-6 mm and deg: a held pose copied into a POSES.csv closes its legs (to 4
    significant digits, the 3-RPS rolled 30 deg at y = -6.699 mm missed by 2.3e-4 mm and could
    not be evaluated)."""
    p = np.asarray(p, dtype=float)
    xyz = ", ".join(f"{v:.12g}" for v in np.round(p[:3], 6) + 0.0)
    if p.size == 3:
        return f"({xyz}) mm"
    deg = ", ".join(f"{v:.12g}" for v in np.round(np.degrees(p[3:]), 6) + 0.0)
    return f"({xyz}) mm, roll/pitch/yaw ({deg}) deg"


def nearest_pose_note(model, pose) -> str:
    """For a platform of lower mobility (a 3-RPS) and a pose (x, y, z mm, roll, pitch, yaw rad, base
    frame) it cannot hold: ``"3rps moves in ...:
    the nearest pose it holds is ..."``, the pose its legs reach with the same free coordinates,
    when that pose is valid; "" otherwise (a full-mobility robot, or no valid pose near)."""
    mob = lower_mobility(model)
    near = None if mob is None else nearest_held(model, np.asarray(pose, dtype=np.float64), mob)
    if near is None:
        return ""
    return f"{mob.describe(model.name)}: the nearest pose it holds is {pose_text(near)}"


def held_as_given(model, poses) -> np.ndarray:
    """``poses`` when a platform of lower mobility holds each as given (its following coordinates at
    the values its legs reach), else a ValueError naming the first it cannot and the pose it holds.

    A full-mobility robot's poses pass unchanged; so do poses its legs cannot close at all, or
    close only where the model cannot evaluate it (:func:`nearest_held`: the model names the
    leg). ``stiffmap model legs --grid`` takes this: a 3-RPS's grid must keep x, y and yaw where
    its z, roll and pitch put them (0 with the platform level).

    Raises
    ------
    ValueError
        ``"3rps moves in z, roll, pitch: x, y, yaw follow: it cannot hold pose 4 ... as given
        (it holds ... there)"`` (the caller says how to give the poses it reaches).
    """
    P, _ = as_points(poses, POSE_DIM)
    mob = lower_mobility(model)
    if mob is None:
        return P
    scale = np.array([1.0, 1.0, 1.0, *(3 * [model.length_mm])])
    for i in range(len(P)):
        near = nearest_held(model, P[i], mob)
        if near is not None and np.max(np.abs(near - P[i]) * scale) > HELD_TOL_MM:
            raise ValueError(
                f"{mob.describe(model.name)}: it cannot hold pose {i + 1} {pose_text(P[i])} as given (it "
                f"holds {pose_text(near)} there)"
            )
    return P
