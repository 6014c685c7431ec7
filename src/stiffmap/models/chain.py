"""Kinematic chains in mm through Pinocchio: a serial robot from its URDF, or from a list of joints.

One home for the rigid-body kinematics of every robot stiffmap models from a
description rather than from closed-form equations: a serial arm read from a
URDF (:meth:`Chain.from_urdf`, xacro too), or one leg of a parallel robot described by its
joints (:meth:`Chain.from_joints`). Pinocchio (``pin`` on PyPI) does the work:
forward kinematics, and the 6 x n Jacobian of the *measured point* (a link frame
plus an offset), analytic and checked against finite differences in the tests.

Units. A URDF is in metres; the chain is built in millimetres, so everything it returns
is in stiffmap's units (``docs/conventions.md``): positions mm, revolute joints rad,
prismatic joints mm. The Jacobian's first three rows are the measured point's velocity
(mm per rad, or mm per mm for a prismatic joint), the last three the angular velocity
(rad per joint unit), all in the base frame (Pinocchio's ``LOCAL_WORLD_ALIGNED``).

Which joints count (a URDF as published, ``docs/models.md``). Only the kinematic tree
counts (:mod:`~stiffmap.models.robot_files` reads it): the chain is the path of joints
from the *base frame* (the root link, or the link given as ``base_frame``) down to the
tip frame. Joints off that path never matter, whatever their type (a mobile base's
wheels, the other arm, a hand's fingers). On it, revolute, continuous and prismatic
joints move, fixed joints are rigid, and a joint with ``<mimic>`` follows its leader:
its coordinate is ``multiplier * q(leader) + offset``, not a coordinate of the chain
(:attr:`Chain.mimic_names`). The chain's coordinates (:attr:`Chain.joint_names`) are its
moving joints that follow nobody, in the order of the path, and the leaders of its mimic
joints (a leader off the path, e.g. a gripper's first finger, takes the place of its
first follower). A floating or planar joint on the path is refused, by name. Joints
between the root and ``base_frame`` are held (at zero: the measurements are expressed in
the base frame, so they move nothing measured); a mimic joint on the path whose leader is
held is held too, at its offset. A fixed frame beside the path (joined to it by fixed joints
only, nothing moving below it: ROS-Industrial's ``base`` beside ``base_link``, a mounting
frame) is a constant transform: accepted as the base frame, the chain starts from it; the base
of another branch (another arm's) is refused.

Bad input (``InputError`` naming the file and the element): see
:mod:`~stiffmap.models.robot_files` for the file; here a tip or base frame the URDF does
not have (its links are listed), a tip not below the base (a base beside the chain that is
not a fixed frame), a joint on the path of a type that cannot be modelled or with a
malformed element, a mimic naming a joint the file does not define or a mimic loop, a
configuration of the wrong length.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import FieldError, InputError, StiffmapWarning
from ..stiffness import MAX_POSITION_MM
from .robot_files import MOVING_TYPES, UrdfJoint, UrdfTree, read_urdf

__all__ = ["Chain", "JointSpec", "IKResult", "Mimic", "M_TO_MM", "JOINT_TYPES"]

#: URDF lengths are metres; stiffmap's are millimetres.
M_TO_MM = 1000.0
#: The joint types a chain moves with (URDF's names; "continuous" is an unlimited revolute joint).
JOINT_TYPES = MOVING_TYPES

_TIP = "stiffmap_measured_point"
#: How many link names an error lists before saying how many more there are.
_LIST_MAX = 60


@dataclass(frozen=True)
class JointSpec:
    """One joint of a chain described without a URDF (a leg of a parallel robot).

    Attributes
    ----------
    name : str
    type : {"revolute", "prismatic"}
    axis : tuple of 3 floats
        Joint axis in the joint's frame (normalised on use).
    xyz_mm : tuple of 3 floats, mm
        Origin of the joint's frame in the previous joint's frame (the base for the
        first joint), at zero joint coordinates -- URDF's ``<origin xyz>``, in mm.
    rpy : tuple of 3 floats, rad
        Orientation of the joint's frame in the previous one (URDF's roll, pitch, yaw).
    """

    name: str
    type: str
    axis: tuple[float, float, float]
    xyz_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Mimic:
    """A joint of the chain that follows another: ``q = multiplier * q[leader] + offset``.

    Attributes
    ----------
    name : str
        The mimic joint.
    leader : int or None
        Index of the coordinate it follows (:attr:`Chain.joint_names`); None when it is held
        (its leader is above the base frame), at ``offset``.
    multiplier, offset : float
        Composed along a mimic of a mimic; ``offset`` in rad, or mm for a prismatic joint.
    type : {"revolute", "prismatic"}
    lower, upper : float
        Its own limits (rad or mm).
    """

    name: str
    leader: int | None
    multiplier: float
    offset: float
    type: str
    lower: float
    upper: float


@dataclass(frozen=True)
class IKResult:
    """A configuration found by :meth:`Chain.inverse`.

    Attributes
    ----------
    q : ndarray, shape (n,)
        Joint coordinates (rad or mm).
    converged : bool
    position_error_mm : float
        Distance left between the measured point and its target.
    rotation_error_rad : float
        Angle left between the tip's orientation and its target (0 when none was given).
    iterations : int
    """

    q: np.ndarray
    converged: bool
    position_error_mm: float
    rotation_error_rad: float
    iterations: int


@dataclass(frozen=True)
class _Mover:
    """A moving joint of the chain as built: its placement after the previous one (mm)."""

    name: str
    type: str  # "revolute" or "prismatic"
    axis: np.ndarray
    placement: pin.SE3
    lower: float
    upper: float


@dataclass(frozen=True)
class _Coord:
    """A coordinate of the chain: a moving joint that follows nobody (row -1: off the path)."""

    name: str
    type: str
    lower: float
    upper: float
    row: int


#: Configurations per block in :meth:`Chain._frames_many`.
_CHUNK = 2048


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """[a]x: the matrix of the cross product with a, ``[a]x v = a x v``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = (float(v) for v in rpy)
    return pin.rpy.rpyToMatrix(r, p, y)


def _placement_mm(j: UrdfJoint) -> pin.SE3:
    """A URDF joint's origin as a placement in mm."""
    return pin.SE3(_rpy_matrix(j.rpy), np.asarray(j.xyz, dtype=float) * M_TO_MM)


def _listing(names: Sequence[str]) -> str:
    if len(names) <= _LIST_MAX:
        return ", ".join(names) or "(none)"
    return ", ".join(names[:_LIST_MAX]) + f", ... ({len(names) - _LIST_MAX} more)"


def _link_of(tree: UrdfTree, frame: str, what: str, field: str) -> str:
    """The link a frame name stands for: a link, or a joint (its child link, the same frame);
    else a FieldError naming ``field`` (the caller's parameter that gave it)."""
    if frame in tree.links:
        return frame
    if frame in tree.joints:
        return tree.joints[frame].child
    raise FieldError(
        field,
        f"no frame {frame!r} for {what}; the links are: {_listing(tree.links)} (give one as {{{field}}})",
        value=frame,
        source=tree.source,
    )


def _chain_path(tree: UrdfTree, tip: str, base: str | None) -> tuple[str, list[str], list[str], list[str]]:
    """(base link, joints held above it, joints from it to ``tip``, fixed joints from the branch
    point down to a base frame off that path) of a tree.

    A base frame off the root-to-tip path is accepted when it is a fixed frame beside it: only
    fixed joints join it to the path and no joint below it moves (ROS-Industrial's ``base``, a
    mounting frame): a constant transform. The base of another branch (another arm) is named.
    """
    path = tree.path_to(tip)
    root = tree.joints[path[0]].parent if path else tip
    if base is None or base == root:
        return root, [], path, []
    for i, jn in enumerate(path):
        if tree.joints[jn].child == base:
            return base, path[: i + 1], path[i + 1 :], []
    links = [root] + [tree.joints[jn].child for jn in path]
    bpath = tree.path_to(base)
    n = 0
    while n < min(len(path), len(bpath)) and path[n] == bpath[n]:
        n += 1
    same_tree = bool(bpath) and tree.joints[bpath[0]].parent == root
    movers = [jn for jn in bpath[n:] if tree.joints[jn].type != "fixed"]
    below = _moving_below(tree, base)
    if same_tree and not movers and not below:
        return base, path[:n], path[n:], bpath[n:]
    if not same_tree:
        why = "it is in another tree"
    elif movers:
        why = f"joint {movers[0]!r} ({tree.joints[movers[0]].type}) joins it to that chain"
    else:
        why = f"joint {below!r} moves below it (the base of another branch)"
    raise InputError(
        f"tip frame {tip!r} is not below base frame {base!r}: the chain from the root {root!r} to {tip!r} "
        f"passes through links {', '.join(links)}; {base!r} is on another branch: {why} (choose a base "
        "frame among those links, or a fixed frame beside them: joined by fixed joints, nothing moving "
        "below it)",
        source=tree.source,
    )


def _warn_roots(tree: UrdfTree, tip_frame: str, root: str) -> None:
    """A URDF is one tree: several roots (a joint dropped, a parent link misspelt) make the chain
    start at the root of the tip's tree, which may not be the robot's base: said, not refused
    (a base frame chosen says which)."""
    roots = tree.roots
    if len(roots) > 1:
        shown = ", ".join(repr(r) for r in roots[:5]) + (", ..." if len(roots) > 5 else "")
        warnings.warn(
            f"{tree.source}: {len(roots)} root links ({shown}) where a URDF has one (a joint missing, a "
            f"parent link misspelt?); the chain to {tip_frame!r} starts at {root!r}, the root of its tree "
            "(choose the base frame to say which)",
            StiffmapWarning,
            stacklevel=3,
        )


def _moving_below(tree: UrdfTree, link: str) -> str | None:
    """The first moving joint (breadth first) in the subtree below ``link``, or None."""
    level = {link}
    while level:
        nxt = [j for j in tree.joints.values() if j.parent in level]
        for j in nxt:
            if j.type != "fixed":
                return j.name
        level = {j.child for j in nxt}
    return None


def _check_on_path(tree: UrdfTree, j: UrdfJoint, base: str, tip: str) -> None:
    where = f"joint {j.name!r} (on the chain from {base!r} to {tip!r})"
    if j.problem:
        raise InputError(f"{where}: {j.problem}", source=tree.source)
    if j.type in ("floating", "planar"):
        dof = 6 if j.type == "floating" else 3
        raise InputError(
            f"{where} is {j.type} ({dof} degrees of freedom, no spring a stiffness model can give): "
            f"choose a base frame below it (--base {j.child}, campaign.toml base_frame) or make it fixed",
            source=tree.source,
        )


def _leader_of(tree: UrdfTree, j: UrdfJoint) -> tuple[str, float, float]:
    """(ultimate leader, multiplier, offset) of a mimic joint, following mimics of mimics."""
    mult, off, at, seen = 1.0, 0.0, j, [j.name]
    while at.mimic is not None:
        m = at.mimic
        leader = tree.joints.get(m.joint)
        if leader is None:
            raise InputError(
                f"joint {at.name!r}: <mimic joint={m.joint!r}> names a joint the file does not define",
                source=tree.source,
            )
        if leader.name in seen:
            raise InputError(
                f"joint {j.name!r}: mimic loop {' -> '.join([*seen, leader.name])}: no joint leads",
                source=tree.source,
            )
        if leader.type not in MOVING_TYPES or leader.problem:
            why = leader.problem or f"is {leader.type}: it does not move"
            raise InputError(
                f"joint {at.name!r}: <mimic joint={m.joint!r}>: joint {m.joint!r} {why}", source=tree.source
            )
        scale = M_TO_MM if at.type == "prismatic" else 1.0
        lead_scale = M_TO_MM if leader.type == "prismatic" else 1.0
        # q_at = m.multiplier * q_leader + m.offset (file units); composed in mm and rad.
        off = off + mult * m.offset * scale
        mult = mult * m.multiplier * scale / lead_scale
        seen.append(leader.name)
        at = leader
    return at.name, mult, off


def _limits_mm(j: UrdfJoint) -> tuple[float, float]:
    s = M_TO_MM if j.type == "prismatic" else 1.0
    return j.lower * s, j.upper * s


def _kind(jtype: str) -> str:
    return "prismatic" if jtype == "prismatic" else "revolute"


def _check_offset(tip_offset_mm, source: str) -> np.ndarray:
    try:
        off = np.asarray(tip_offset_mm, dtype=float)
    except (TypeError, ValueError):  # text that is not numbers ('a,b,c', '1;2;3')
        off = np.full(1, np.nan)
    if off.shape != (3,) or not np.all(np.isfinite(off)) or np.max(np.abs(off)) > MAX_POSITION_MM:
        raise FieldError(
            "tip_offset_mm",
            f"tip offset must be three finite numbers within {MAX_POSITION_MM:g} mm, got {tip_offset_mm!r} "
            "(give {tip_offset_mm} as X,Y,Z)",
            value=tip_offset_mm,
            source=source,
        )
    return off


def _coordinates(
    tree: UrdfTree, movers: Sequence[_Mover], held: set[str]
) -> tuple[list[_Coord], list[Mimic], list[int]]:
    """The chain's coordinates (path order; a leader off the path at its first follower's place)
    and its mimic joints with their rows among the movers."""
    rows = {mv.name: k for k, mv in enumerate(movers)}
    lead = {
        k: _leader_of(tree, tree.joints[mv.name]) for k, mv in enumerate(movers) if tree.joints[mv.name].mimic
    }
    order: dict[str, int] = {}
    for k, mv in enumerate(movers):
        name = lead[k][0] if k in lead else mv.name
        if name in held:
            continue
        key = rows.get(name, k)
        order[name] = min(order.get(name, key), key)
    coords = []
    for name in sorted(order, key=order.__getitem__):
        if name in rows:
            mv = movers[rows[name]]
            coords.append(_Coord(name, mv.type, mv.lower, mv.upper, rows[name]))
        else:
            j = tree.joints[name]
            coords.append(_Coord(name, _kind(j.type), *_limits_mm(j), -1))
    index = {c.name: i for i, c in enumerate(coords)}
    mimics = [
        Mimic(
            movers[k].name,
            index.get(lead[k][0]),
            lead[k][1],
            lead[k][2],
            movers[k].type,
            movers[k].lower,
            movers[k].upper,
        )
        for k in sorted(lead)
    ]
    return coords, mimics, sorted(lead)


class Chain:
    """A serial kinematic chain in mm, from the base frame to a measured point.

    Build it with :meth:`from_urdf` (:meth:`from_tree`) or :meth:`from_joints`.

    Attributes
    ----------
    name : str
        The robot's name (URDF ``<robot name>``), for messages.
    source : str
        Where it came from (the URDF's path, or ``name``), for messages.
    joint_names : tuple of str
        The chain's coordinates: the joints that move the measured point and follow
        nobody, base first (module docstring).
    joint_types : tuple of str
        ``"revolute"`` or ``"prismatic"`` for each (a continuous joint is revolute).
    mimics : tuple of Mimic
        The joints on the chain that follow another (:attr:`mimic_names`).
    base_frame : str
        The link the base frame is (the URDF's root, or the one chosen).
    root_frame : str
        The root of the URDF's tree above the tip (the base frame when none is chosen).
    urdf_text : str
        The URDF the chain was read from (a xacro file expanded; "" for :meth:`from_joints`).
    held_joints : tuple of str
        Moving joints between the root and the base frame (held; not coordinates).
    tip_frame : str
        The link frame the measured point is attached to.
    tip_offset_mm : ndarray, shape (3,)
        The measured point in that frame, mm.
    lower, upper : ndarray, shape (n,)
        Joint limits (rad or mm; -inf / inf where the URDF gives none).
    link_names : tuple of str
        The links of the chain, from the base frame to the tip frame.
    urdf_joint_names : tuple of str
        Every joint of the URDF (for messages naming a joint that is not a coordinate).
    """

    def __init__(
        self,
        movers: Sequence[_Mover],
        tip_placement: pin.SE3,
        *,
        name: str,
        source: str,
        tip_frame: str,
        tip_offset_mm,
        coords: Sequence[_Coord] | None = None,
        mimics: Sequence[Mimic] = (),
        mimic_rows: Sequence[int] = (),
        links: Mapping[str, tuple[int, pin.SE3]] | None = None,
        base_frame: str = "base",
        root_frame: str | None = None,
        held: Sequence[str] = (),
        all_joints: Sequence[str] = (),
        urdf_text: str = "",
    ):
        model = pin.Model()
        model.name = name
        parent = 0
        for mv in movers:
            jm = (
                pin.JointModelPrismaticUnaligned
                if mv.type == "prismatic"
                else pin.JointModelRevoluteUnaligned
            )(mv.axis)
            parent = model.addJoint(parent, jm, mv.placement, mv.name)
        # The same chain as arrays, for :meth:`forward_many` and :meth:`jacobian_many` (NumPy over
        # many configurations; Pinocchio computes one configuration at a time).
        self._prismatic = np.array([mv.type == "prismatic" for mv in movers], dtype=bool)
        self._axes = np.array(
            [np.asarray(mv.axis, float) / np.linalg.norm(mv.axis) for mv in movers]
        ).reshape(-1, 3)
        self._place_R = np.array([np.array(mv.placement.rotation) for mv in movers]).reshape(-1, 3, 3)
        self._place_p = np.array([np.array(mv.placement.translation) for mv in movers]).reshape(-1, 3)
        self._model = model
        self._data = model.createData()
        off = np.asarray(tip_offset_mm, dtype=float)
        tip = pin.Frame(_TIP, parent, 0, tip_placement * pin.SE3(np.eye(3), off), pin.FrameType.OP_FRAME)
        self._fid = int(model.addFrame(tip))
        self._tip_R = np.array(tip.placement.rotation)
        self._tip_p = np.array(tip.placement.translation)
        self._data = model.createData()
        nf = len(movers)
        if coords is None:
            coords = [_Coord(mv.name, mv.type, mv.lower, mv.upper, k) for k, mv in enumerate(movers)]
        # Full coordinates (every moving joint of the chain) from the chain's: qf = G q + b.
        G = np.zeros((nf, len(coords)))
        b = np.zeros(nf)
        for i, c in enumerate(coords):
            if c.row >= 0:
                G[c.row, i] = 1.0
        for mm, row in zip(mimics, mimic_rows, strict=True):
            if mm.leader is not None:
                G[row, mm.leader] = mm.multiplier
            b[row] = mm.offset
        self._G, self._b = G, b
        self._mimic_rows = np.asarray(mimic_rows, dtype=int)
        self.name = name
        self.source = source
        self.tip_frame = tip_frame
        self.tip_offset_mm = off.copy()
        self.tip_offset_mm.setflags(write=False)
        self.mimics = tuple(mimics)
        self.base_frame = base_frame
        self.root_frame = base_frame if root_frame is None else root_frame
        self.urdf_text = urdf_text
        self.held_joints = tuple(held)
        self.urdf_joint_names = tuple(all_joints)
        self._links = dict(links or {})
        self.link_names = tuple(self._links)
        self.joint_names = tuple(c.name for c in coords)
        self.joint_types = tuple(c.type for c in coords)
        self.lower = np.array([c.lower for c in coords], dtype=float)
        self.upper = np.array([c.upper for c in coords], dtype=float)
        self._neutral = np.zeros(nf)
        self._reach: tuple[np.ndarray, float] | None = None

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_urdf(
        cls,
        path: str | os.PathLike,
        tip_frame: str,
        tip_offset_mm=(0.0, 0.0, 0.0),
        *,
        base_frame: str | None = None,
        xacro_args: Mapping[str, str] | None = None,
        package_paths: Sequence[str | os.PathLike] = (),
    ) -> Chain:
        """Read a URDF (or xacro) and attach the measured point to one of its frames.

        Parameters
        ----------
        path : path-like
            The URDF file (lengths in metres), or a ``.xacro`` one
            (:func:`~stiffmap.models.robot_files.read_urdf`).
        tip_frame : str
            A link of the URDF (or a joint: its child link) that carries the measured point.
        tip_offset_mm : array_like, shape (3,), mm
            The measured point in that frame.
        base_frame : str, optional
            The link the measurements are expressed in (default: the root of the tip's tree).
        xacro_args, package_paths
            For a xacro file: ``xacro:arg`` values and the folders of ``$(find PKG)``.

        Raises
        ------
        InputError
            Naming the file and the element (module docstring).
        """
        tree = read_urdf(path, xacro_args=xacro_args, package_paths=package_paths)
        return cls.from_tree(tree, tip_frame, tip_offset_mm, base_frame=base_frame)

    @classmethod
    def from_tree(
        cls, tree: UrdfTree, tip_frame: str, tip_offset_mm=(0.0, 0.0, 0.0), *, base_frame: str | None = None
    ) -> Chain:
        """The chain from ``base_frame`` (default the root) to ``tip_frame`` of a URDF's tree.

        See :meth:`from_urdf`; ``tree`` is :func:`~stiffmap.models.robot_files.parse_urdf`'s.
        """
        off = _check_offset(tip_offset_mm, tree.source)
        tip = _link_of(tree, tip_frame, "the measured point", "tip_frame")
        base = None if base_frame is None else _link_of(tree, base_frame, "the base frame", "base_frame")
        base, held, path, branch = _chain_path(tree, tip, base)
        if base_frame is None:
            _warn_roots(tree, tip_frame, base)
        movers: list[_Mover] = []
        links: dict[str, tuple[int, pin.SE3]] = {base: (0, pin.SE3.Identity())}
        acc = pin.SE3.Identity()  # placement after the last mover (or the base)
        for jn in branch:  # a base frame off the path: the branch point seen from the base
            _check_on_path(tree, tree.joints[jn], base, tip)
            acc = acc * _placement_mm(tree.joints[jn])
        acc = acc.inverse()
        if branch:
            links[tree.joints[branch[0]].parent] = (0, acc)
        for jn in path:
            j = tree.joints[jn]
            _check_on_path(tree, j, base, tip)
            acc = acc * _placement_mm(j)
            if j.type in MOVING_TYPES:
                ax = np.asarray(j.axis, dtype=float)
                ax = ax / np.max(np.abs(ax))  # (1e308, 0, 0) is an axis too: no overflow in its norm
                lo, hi = _limits_mm(j)
                movers.append(_Mover(j.name, _kind(j.type), ax / np.linalg.norm(ax), acc, lo, hi))
                acc = pin.SE3.Identity()
            links[j.child] = (len(movers), acc)
        if not movers:
            raise FieldError(
                "tip_frame",
                f"no joint moves frame {tip_frame!r} (from base frame {base!r}): its stiffness cannot be "
                "modelled (give a frame the joints move as {tip_frame})",
                value=tip_frame,
                source=tree.source,
            )
        coords, mimics, rows = _coordinates(tree, movers, set(held))
        return cls(
            movers,
            acc,
            name=tree.name,
            source=tree.source,
            tip_frame=tip_frame,
            tip_offset_mm=off,
            coords=coords,
            mimics=mimics,
            mimic_rows=rows,
            links=links,
            base_frame=base,
            root_frame=tree.joints[(held or branch)[0]].parent if held or branch else base,
            held=[h for h in held if tree.joints[h].type in MOVING_TYPES],
            all_joints=tuple(tree.joints),
            urdf_text=tree.text,
        )

    @classmethod
    def from_joints(
        cls, joints: Sequence[JointSpec], tip_offset_mm=(0.0, 0.0, 0.0), *, name: str = "chain"
    ) -> Chain:
        """A chain from its joints, base first (the measured point in the last joint's frame).

        Parameters
        ----------
        joints : sequence of JointSpec
        tip_offset_mm : array_like, shape (3,), mm
            The measured point in the last joint's frame.
        name : str
            For messages.
        """
        if not joints:
            raise InputError(f"{name}: a chain needs at least one joint")
        movers = []
        seen: set[str] = set()
        for j in joints:
            if j.name in seen:
                raise InputError(f"{name}: joint {j.name!r} is named twice")
            seen.add(j.name)
            axis = np.asarray(j.axis, dtype=float)
            nrm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
            if not (math.isfinite(nrm) and nrm > 0):
                raise InputError(
                    f"{name}: joint {j.name!r}: axis must be three numbers, not all zero, got {j.axis!r}"
                )
            if j.type not in ("revolute", "continuous", "prismatic"):
                raise InputError(
                    f"{name}: joint {j.name!r}: type must be revolute or prismatic, got {j.type!r}"
                )
            xyz = np.asarray(j.xyz_mm, dtype=float)
            rpy = np.asarray(j.rpy, dtype=float)
            if (
                xyz.shape != (3,)
                or rpy.shape != (3,)
                or not (np.all(np.isfinite(xyz)) and np.all(np.isfinite(rpy)))
            ):
                raise InputError(
                    f"{name}: joint {j.name!r}: xyz_mm and rpy must be three finite numbers each"
                )
            pl = pin.SE3(_rpy_matrix(rpy), xyz)
            movers.append(_Mover(j.name, _kind(j.type), axis / nrm, pl, -math.inf, math.inf))
        off = _check_offset(tip_offset_mm, name)
        links = {"base": (0, pin.SE3.Identity())} | {
            mv.name: (k + 1, pin.SE3.Identity()) for k, mv in enumerate(movers)
        }
        return cls(
            movers,
            pin.SE3.Identity(),
            name=name,
            source=name,
            tip_frame=movers[-1].name,
            tip_offset_mm=off,
            links=links,
        )

    # ------------------------------------------------------------------ kinematics

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    def check_q(self, q, what: str = "configuration") -> np.ndarray:
        """q as a float array of shape (n,), else InputError naming the chain and the joints."""
        a = np.asarray(q, dtype=float)
        if a.shape != (self.n,):
            raise InputError(
                f"{what} has {a.size} value(s); {self.name} has {self.n} joints "
                f"({', '.join(self.joint_names)})",
                source=self.source,
            )
        if not np.all(np.isfinite(a)):
            raise InputError(f"{what} is not finite: {a.tolist()}", source=self.source)
        return a

    def full_coordinates(self, q) -> np.ndarray:
        """Every moving joint's coordinate on the chain, mimic joints included (path order).

        Parameters
        ----------
        q : array_like, shape (n,)

        Returns
        -------
        ndarray, shape (n_moving,)
            rad or mm; a mimic joint's is ``multiplier * q[leader] + offset``.
        """
        return self._G @ self.check_q(q) + self._b

    def mimic_coordinates(self, q) -> np.ndarray:
        """The mimic joints' coordinates (:attr:`mimics` order), rad or mm, shape (m,)."""
        return self.full_coordinates(q)[self._mimic_rows]

    @property
    def mimic_names(self) -> tuple[str, ...]:
        """The chain's mimic joints (they follow a coordinate; :attr:`mimics`)."""
        return tuple(m.name for m in self.mimics)

    def forward(self, q) -> tuple[np.ndarray, np.ndarray]:
        """The measured point (mm) and the tip frame's rotation, base frame.

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint coordinates (rad or mm).

        Returns
        -------
        position : ndarray, shape (3,), mm
        rotation : ndarray, shape (3, 3)
            Tip frame to base.
        """
        pin.framesForwardKinematics(self._model, self._data, self.full_coordinates(q))
        M = self._data.oMf[self._fid]
        return np.array(M.translation), np.array(M.rotation)

    def _full_jacobian(self, q) -> np.ndarray:
        qf = self.full_coordinates(q)
        J = pin.computeFrameJacobian(self._model, self._data, qf, self._fid, pin.LOCAL_WORLD_ALIGNED)
        return np.array(J).reshape(6, -1)  # Pinocchio gives a vector for a one-joint chain

    def jacobian(self, q) -> np.ndarray:
        """The 6 x n Jacobian of the measured point, base frame.

        A coordinate that leads mimic joints moves them too: its column is its own motion
        plus each follower's times the multiplier.

        Parameters
        ----------
        q : array_like, shape (n,)

        Returns
        -------
        ndarray, shape (6, n)
            Rows vx, vy, vz (mm per rad or mm per mm) then wx, wy, wz (rad per joint unit).
        """
        return self._full_jacobian(q) @ self._G

    def mimic_jacobian(self, q) -> np.ndarray:
        """The columns of the mimic joints' own motions (for a spring of their own), shape (6, m)."""
        return self._full_jacobian(q)[:, self._mimic_rows]

    def reach_mm(self) -> tuple[np.ndarray, float]:
        """A sphere that holds every point the measured point can reach: its centre (the first
        moving joint's origin, fixed in the base frame; the point itself on a chain without joints)
        and its radius (mm): the distances between successive joints' origins and from the last
        to the point, at zero coordinates (what the link between two revolute joints fixes), plus
        each prismatic joint's largest travel (inf when a prismatic joint is unlimited)."""
        if self._reach is None:
            self._reach = self._sphere()
        return self._reach[0].copy(), self._reach[1]

    def _sphere(self) -> tuple[np.ndarray, float]:
        """:meth:`reach_mm`, computed."""
        p, _, o, _ = self._frames_many(np.zeros((1, self.n)))
        if o.shape[1] == 0:
            return p[0], 0.0
        seg = np.linalg.norm(np.diff(np.concatenate([o[0], p]), axis=0), axis=1)
        lim = np.maximum(np.abs(self.lower), np.abs(self.upper))
        travel = [
            np.abs(b) + np.sum(np.abs(g[g != 0]) * lim[g != 0]) for g, b in zip(self._G, self._b, strict=True)
        ]
        return o[0, 0], float(seg.sum() + sum(t for t, pr in zip(travel, self._prismatic, strict=True) if pr))

    def forward_many(self, Q) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`forward` of many configurations: positions (N, 3) mm, rotations (N, 3, 3)."""
        p, R = self._frames_many(Q)[:2]
        return p, R

    def jacobian_many(self, Q) -> np.ndarray:
        """:meth:`jacobian` of many configurations, shape (N, 6, n)."""
        return self._full_jacobian_many(Q) @ self._G

    def _frames_many(self, Q) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The tip's position (N, 3) and rotation (N, 3, 3) at configurations Q (N, n), and each
        moving joint's origin (N, nf, 3) and axis (N, nf, 3) in the base frame: the chain's
        placements and joint motions composed with NumPy over all configurations at once."""
        Q = np.asarray(Q, dtype=float).reshape(-1, self.n)
        if Q.shape[0] > _CHUNK:  # small matrix products: a large one is slow when BLAS threads it
            parts = [self._frames_many(Q[i : i + _CHUNK]) for i in range(0, Q.shape[0], _CHUNK)]
            return tuple(np.concatenate(x) for x in zip(*parts, strict=True))
        Qf = Q @ self._G.T + self._b
        N, nf = Qf.shape[0], self._axes.shape[0]
        R = np.broadcast_to(np.eye(3), (N, 3, 3)).copy()
        p = np.zeros((N, 3))
        origins, axes = np.zeros((N, nf, 3)), np.zeros((N, nf, 3))

        def rot(A):  # R @ A for a fixed (3, 3) or (3,) A: one matrix product over all N
            return (R.reshape(-1, 3) @ A).reshape(N, 3, *A.shape[1:])

        for j in range(nf):
            p = p + rot(self._place_p[j])
            R = rot(self._place_R[j])
            a = self._axes[j]
            origins[:, j], axes[:, j] = p, rot(a)
            if self._prismatic[j]:
                p = p + axes[:, j] * Qf[:, j, None]
            else:  # R Rot(a, q) = R + sin q (R K) + (1 - cos q) (R K K), K = [a]x (Rodrigues)
                K = _cross_matrix(a)
                s, c = np.sin(Qf[:, j])[:, None, None], np.cos(Qf[:, j])[:, None, None]
                R = R + s * rot(K) + (1.0 - c) * rot(K @ K)
        return p + rot(self._tip_p), rot(self._tip_R), origins, axes

    def _full_jacobian_many(self, Q) -> np.ndarray:
        """:meth:`_full_jacobian` of many configurations (N, 6, nf): a revolute joint's column is
        ``(z x (p - o), z)``, a prismatic one's ``(z, 0)`` (z its axis, o its origin, p the tip)."""
        p, _, o, z = self._frames_many(Q)
        lin = np.where(self._prismatic[None, :, None], z, np.cross(z, p[:, None] - o))
        ang = np.where(self._prismatic[None, :, None], 0.0, z)
        return np.concatenate([lin, ang], axis=2).transpose(0, 2, 1)

    def mimic_jacobian_many(self, Q) -> np.ndarray:
        """:meth:`mimic_jacobian` of many configurations, shape (N, 6, m)."""
        return self._full_jacobian_many(Q)[:, :, self._mimic_rows]

    def link_poses(
        self, Q, frames: Sequence[tuple[str, np.ndarray, np.ndarray]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Frames fixed to links of the chain, in the base frame, at configurations.

        Parameters
        ----------
        Q : array_like, shape (N, n)
        frames : sequence of (link, rotation (3, 3), origin (3,) mm)
            Each frame in its link's frame (a link of :attr:`link_names`).

        Returns
        -------
        origins : ndarray, shape (N, F, 3), mm
        rotations : ndarray, shape (N, F, 3, 3)
            Frame to base.
        """
        Q = np.asarray(Q, dtype=float).reshape(-1, self.n)
        local = []
        for link, R, t in frames:
            if link not in self._links:
                raise InputError(
                    f"link {link!r} is not on the chain from {self.base_frame!r} to {self.tip_frame!r} "
                    f"(its links: {_listing(self.link_names)})",
                    source=self.source,
                )
            jid, pl = self._links[link]
            local.append((jid, pl * pin.SE3(np.asarray(R, dtype=float), np.asarray(t, dtype=float))))
        P = np.zeros((Q.shape[0], len(local), 3))
        Rs = np.zeros((Q.shape[0], len(local), 3, 3))
        for i, q in enumerate(Q):
            pin.forwardKinematics(self._model, self._data, self.full_coordinates(q))
            for f, (jid, pl) in enumerate(local):
                M = self._data.oMi[jid] * pl
                P[i, f], Rs[i, f] = M.translation, M.rotation
        return P, Rs

    def link_end(self, link: str) -> np.ndarray:
        """Where ``link`` ends on the chain, in its frame (mm): the next joint's origin, or the
        measured point for the tip frame's link."""
        if link not in self._links:
            raise InputError(
                f"link {link!r} is not on the chain from {self.base_frame!r} to {self.tip_frame!r} "
                f"(its links: {_listing(self.link_names)})",
                source=self.source,
            )
        jid, pl = self._links[link]
        names = self.link_names
        k = names.index(link)
        if k + 1 < len(names):
            jn, pn = self._links[names[k + 1]]
            if jn == jid:  # the next link hangs from the same joint (a fixed joint between)
                return np.array((pl.inverse() * pn).translation)
            # the next moving joint's origin, in its parent's frame
            return np.array((pl.inverse() * self._model.jointPlacements[jn]).translation)
        tip = self._model.frames[self._fid].placement
        return np.array((pl.inverse() * tip).translation)

    def beyond_limits(self, q) -> list[str]:
        """The joints of ``q`` (and its mimic joints) outside their limits, in words (empty when none)."""
        a = np.asarray(q, dtype=float)
        rows = [
            (self.joint_names[k], self.joint_types[k], a[k], self.lower[k], self.upper[k])
            for k in range(self.n)
        ]
        if self.mimics:
            qm = self.mimic_coordinates(a)
            rows += [(m.name, m.type, v, m.lower, m.upper) for m, v in zip(self.mimics, qm, strict=True)]
        out = []
        for name, kind, v, lo, hi in rows:
            if v < lo - 1e-12 or v > hi + 1e-12:
                unit, f = ("mm", 1.0) if kind == "prismatic" else ("deg", 180 / math.pi)
                span = f"[{lo * f:.6g}, {hi * f:.6g}] {unit}"
                out.append(f"joint {name} at {v * f:.6g} {unit} beyond its limits {span}")
        return out

    def inverse(
        self,
        position_mm,
        rotation=None,
        q0=None,
        *,
        tol_mm: float = 1e-9,
        tol_rad: float = 1e-12,
        max_iter: int = 200,
        length_mm: float | None = None,
    ) -> IKResult:
        """Joint coordinates that put the measured point at a position (and the tip at an orientation).

        Damped least squares (Levenberg-Marquardt on the joints, the minimum-norm step
        for a redundant chain) from ``q0``: the solution is the one of ``q0``'s branch
        (elbow up or down, wrist flipped or not), its revolute joints within half a turn
        of ``q0``'s. Joint limits are not enforced here;
        :meth:`beyond_limits` says whether the solution respects them.

        Parameters
        ----------
        position_mm : array_like, shape (3,), mm
        rotation : array_like, shape (3, 3), optional
            Tip frame to base; None for the position only.
        q0 : array_like, shape (n,), optional
            Start (default zeros).
        tol_mm, tol_rad : float
            Convergence: position and rotation errors below these.
        max_iter : int
        length_mm : float, optional
            The length that weighs rotation errors against position errors (default:
            the distance from the base to the point at ``q0``, at least 100 mm).

        Returns
        -------
        IKResult
        """
        target = np.asarray(position_mm, dtype=float).reshape(3)
        Rt = None if rotation is None else np.asarray(rotation, dtype=float).reshape(3, 3)
        q = np.zeros(self.n) if q0 is None else self.check_q(q0, "q0").copy()
        q_start = q.copy()
        p, R = self._forward_iterate(q)
        L = float(length_mm) if length_mm else max(100.0, float(np.linalg.norm(p)))
        lam = 1e-3
        it = 0
        ep = er = math.inf

        def error(p, R):
            e = target - p
            if Rt is None:
                return e, np.zeros(0)
            return e, pin.log3(Rt @ R.T)

        e_p, e_r = error(p, R)
        for it in range(1, max_iter + 1):
            ep, er = math.sqrt(e_p @ e_p), math.sqrt(e_r @ e_r) if e_r.size else 0.0  # np.linalg.norm's
            if ep < tol_mm and er < tol_rad:
                return IKResult(self._near(q, q_start), True, ep, er, it - 1)
            J = self._jacobian_iterate(q)
            A = J[:3] if Rt is None else np.vstack([J[:3], L * J[3:]])
            e = e_p if Rt is None else np.concatenate([e_p, L * e_r])
            cost = float(e @ e)
            qn, n_p, n_r, cost_n, lam = self._damped_step(q, A, e, cost, lam, error, Rt is None, L)
            if cost_n >= cost:
                break
            q, e_p, e_r = qn, n_p, n_r
            lam = max(lam / 10.0, 1e-12)
        ep, er = float(np.linalg.norm(e_p)), float(np.linalg.norm(e_r)) if e_r.size else 0.0
        # The steps stalled (round-off) or ran out: converged when within a thousand times the
        # tolerances (1e-6 mm and 1e-9 rad by default), not reached otherwise.
        return IKResult(self._near(q, q_start), ep < tol_mm * 1e3 and er < tol_rad * 1e3, ep, er, it)

    def _damped_step(self, q, A, e, cost: float, lam: float, error, position_only: bool, L: float):
        """A Levenberg-Marquardt step of :meth:`inverse`: the damping ``lam`` raised tenfold until
        the step lowers the weighted cost (or ``lam`` passes 1e6); the new joints, their position
        and rotation errors, weighted cost, and the damping."""
        H = A @ A.T
        scale, eye = np.trace(H) / H.shape[0] + 1e-30, np.eye(H.shape[0])
        while True:
            step = A.T @ np.linalg.solve(H + lam * scale * eye, e)
            qn = q + step
            pn, Rn = self._forward_iterate(qn)
            n_p, n_r = error(pn, Rn)
            en = n_p if position_only else np.concatenate([n_p, L * n_r])
            if float(en @ en) < cost or lam > 1e6:
                return qn, n_p, n_r, float(en @ en), lam
            lam *= 10.0

    def _forward_iterate(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`forward` of an iterate of :meth:`inverse` (a float array of shape (n,)): the same
        numbers, without :meth:`check_q`'s conversions (unless q is not finite: its error)."""
        if not np.isfinite(q).all():
            self.check_q(q)
        pin.framesForwardKinematics(self._model, self._data, self._G @ q + self._b)
        M = self._data.oMf[self._fid]
        return np.array(M.translation), np.array(M.rotation)

    def _jacobian_iterate(self, q: np.ndarray) -> np.ndarray:
        """:meth:`jacobian` of an iterate of :meth:`inverse` (as :meth:`_forward_iterate`)."""
        qf = self._G @ q + self._b
        J = pin.computeFrameJacobian(self._model, self._data, qf, self._fid, pin.LOCAL_WORLD_ALIGNED)
        return np.array(J).reshape(6, -1) @ self._G

    def _near(self, q: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """``q`` with each revolute joint turned by whole turns to lie within half a turn of ``seed``."""
        out = q.copy()
        for k, t in enumerate(self.joint_types):
            if t == "revolute":
                out[k] = seed[k] + (q[k] - seed[k] + math.pi) % (2 * math.pi) - math.pi
        return out

    def __repr__(self) -> str:
        tip = f"{self.tip_frame!r} + {self.tip_offset_mm.tolist()} mm"
        return f"Chain({self.name!r}, joints={list(self.joint_names)}, tip={tip})"
