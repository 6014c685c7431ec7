"""Kinematic chains in mm through Pinocchio: a serial robot from its URDF, or from a list of joints.

One home for the rigid-body kinematics of every robot stiffmap models from a
description rather than from closed-form equations: a serial arm read from a
URDF (:meth:`Chain.from_urdf`), or one leg of a parallel robot described by its
joints (:meth:`Chain.from_joints`). Pinocchio (``pin`` on PyPI) does the work:
forward kinematics, and the 6 x n Jacobian of the *measured point* (a link frame
plus an offset), analytic and checked against finite differences in the tests.

Units. A URDF is in metres; the chain scales its model to millimetres once, at
load, so everything it returns is in stiffmap's units (``docs/conventions.md``):
positions mm, revolute joints rad, prismatic joints mm. The Jacobian's first three
rows are the measured point's velocity (mm per rad, or mm per mm for a prismatic
joint), the last three the angular velocity (rad per joint unit), all in the
base frame (Pinocchio's ``LOCAL_WORLD_ALIGNED``).

Joints. Only the joints that move the measured point count, in the order of the
chain from the base (the URDF's joint order along that branch); joints on other
branches are held at zero. Revolute, continuous and prismatic joints are
accepted; a floating or planar joint is refused, by name.

Bad input (``InputError`` naming the file and the item): a file that is not
XML, or not a URDF Pinocchio can read (its parser's message is kept); a tip frame
the URDF does not have (its links are listed); a configuration of the wrong
length.
"""

from __future__ import annotations

import math
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..io import read_text_file

__all__ = ["Chain", "JointSpec", "IKResult", "M_TO_MM", "JOINT_TYPES"]

#: URDF lengths are metres; stiffmap's are millimetres.
M_TO_MM = 1000.0
#: The joint types a chain accepts (URDF's names; "continuous" is an unlimited revolute joint).
JOINT_TYPES = ("revolute", "continuous", "prismatic")

_TIP = "stiffmap_measured_point"


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


@contextmanager
def _captured_stderr():
    """Collect what C++ code writes on file descriptor 2 (urdfdom's parser messages)."""
    box: list[str] = []
    try:
        saved = os.dup(2)
    except OSError:  # no usable stderr: nothing to capture
        yield box
        return
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield box
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            box.append(tmp.read().decode("utf-8", "replace"))


def _parser_message(text: str) -> str:
    """urdfdom's messages without its source-file locations, on one line."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.strip().startswith("at line")]
    return "; ".join(ln.removeprefix("Error:").strip() for ln in lines)


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = (float(v) for v in rpy)
    return pin.rpy.rpyToMatrix(r, p, y)


class Chain:
    """A serial kinematic chain in mm, from the base to a measured point.

    Build it with :meth:`from_urdf` or :meth:`from_joints`.

    Attributes
    ----------
    name : str
        The robot's name (URDF ``<robot name>``), for messages.
    source : str
        Where it came from (the URDF's path, or ``name``), for messages.
    joint_names : tuple of str
        The joints that move the measured point, base first.
    joint_types : tuple of str
        ``"revolute"`` or ``"prismatic"`` for each (a continuous joint is revolute).
    tip_frame : str
        The link frame the measured point is attached to.
    tip_offset_mm : ndarray, shape (3,)
        The measured point in that frame, mm.
    lower, upper : ndarray, shape (n,)
        Joint limits (rad or mm; -inf / inf where the URDF gives none).
    """

    def __init__(
        self, model: pin.Model, frame_id: int, *, name: str, source: str, tip_frame: str, tip_offset_mm
    ):
        self._model = model
        self._data = model.createData()
        self._fid = int(frame_id)
        self.name = name
        self.source = source
        self.tip_frame = tip_frame
        self.tip_offset_mm = np.asarray(tip_offset_mm, dtype=float).copy()
        self.tip_offset_mm.setflags(write=False)
        names, types, lower, upper = [], [], [], []
        for jid in range(1, model.njoints):
            j = model.joints[jid]
            names.append(model.names[jid])
            short = j.shortname()
            types.append("prismatic" if short.startswith("JointModelP") else "revolute")
            if j.nq == 1:
                lower.append(float(model.lowerPositionLimit[j.idx_q]))
                upper.append(float(model.upperPositionLimit[j.idx_q]))
            else:  # continuous: no limit
                lower.append(-math.inf)
                upper.append(math.inf)
        big = 1e300
        self.joint_names = tuple(names)
        self.joint_types = tuple(types)
        self.lower = np.where(np.asarray(lower) < -big, -math.inf, lower)
        self.upper = np.where(np.asarray(upper) > big, math.inf, upper)
        self._plain = model.nq == model.nv  # no continuous joint: q is the joint coordinates
        self._neutral = pin.neutral(model)

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_urdf(cls, path: str | os.PathLike, tip_frame: str, tip_offset_mm=(0.0, 0.0, 0.0)) -> Chain:
        """Read a URDF and attach the measured point to one of its frames.

        Parameters
        ----------
        path : path-like
            The URDF file (lengths in metres).
        tip_frame : str
            A link (or other frame) of the URDF that carries the measured point.
        tip_offset_mm : array_like, shape (3,), mm
            The measured point in that frame.

        Raises
        ------
        InputError
            Naming the file: not XML, not a URDF, a joint type stiffmap does not
            take, an unknown tip frame (the links are listed), no joint moving it.
        """
        src = str(path)
        text = read_text_file(path, "URDF file")
        try:
            root = ET.fromstring(text)
        except ET.ParseError as e:
            raise InputError(f"not a valid XML file ({e})", source=src) from None
        if root.tag != "robot":
            raise InputError(f"not a URDF: the root element is <{root.tag}>, expected <robot>", source=src)
        for j in root.iter("joint"):
            jt = j.get("type", "")
            if jt not in JOINT_TYPES + ("fixed",):
                raise InputError(
                    f"joint {j.get('name')!r} is of type {jt!r}; stiffmap takes revolute, continuous, "
                    "prismatic and fixed joints",
                    source=src,
                )
        with _captured_stderr() as err:
            try:
                model = pin.buildModelFromXML(text)
            except (ValueError, RuntimeError) as e:
                model = None
                reason = str(e)
        if model is None:
            said = _parser_message(err[0] if err else "")
            raise InputError(f"not a URDF Pinocchio can read: {said or reason}", source=src) from None
        return cls._attach(model, tip_frame, tip_offset_mm, name=root.get("name", "robot"), source=src)

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
        model = pin.Model()
        model.name = name
        parent = 0
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
            axis = axis / nrm
            if j.type in ("revolute", "continuous"):
                jm = pin.JointModelRevoluteUnaligned(axis)
            elif j.type == "prismatic":
                jm = pin.JointModelPrismaticUnaligned(axis)
            else:
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
            parent = model.addJoint(parent, jm, pin.SE3(_rpy_matrix(rpy), xyz), j.name)
            model.addJointFrame(parent)
        last = model.frames[-1].name
        return cls._attach(model, last, tip_offset_mm, name=name, source=name, scale=1.0)

    @classmethod
    def _attach(
        cls,
        model: pin.Model,
        tip_frame: str,
        tip_offset_mm,
        *,
        name: str,
        source: str,
        scale: float = M_TO_MM,
    ) -> Chain:
        off = np.asarray(tip_offset_mm, dtype=float)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise InputError(
                f"tip offset must be three finite numbers (mm), got {tip_offset_mm!r}", source=source
            )
        if not model.existFrame(tip_frame):
            links = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
            raise InputError(
                f"no frame {tip_frame!r} for the measured point; the links are: "
                f"{', '.join(links) or '(none)'}",
                source=source,
            )
        for jid in range(1, model.njoints):
            if model.joints[jid].nv != 1:
                raise InputError(
                    f"joint {model.names[jid]!r} has {model.joints[jid].nv} degrees of freedom; "
                    "stiffmap takes one-degree-of-freedom joints (revolute, continuous, prismatic)",
                    source=source,
                )
        fid = model.getFrameId(tip_frame)
        parent = model.frames[fid].parentJoint
        keep = set(int(j) for j in model.supports[parent]) - {0}
        lock = [jid for jid in range(1, model.njoints) if jid not in keep]
        if lock:
            model = pin.buildReducedModel(model, lock, pin.neutral(model))
            fid = model.getFrameId(tip_frame)
        if model.njoints < 2:
            raise InputError(
                f"no joint moves frame {tip_frame!r}: its stiffness cannot be modelled", source=source
            )
        if scale != 1.0:  # metres to mm, once
            for jid in range(1, model.njoints):
                pl = model.jointPlacements[jid]
                pl.translation = pl.translation * scale
                if model.joints[jid].shortname().startswith("JointModelP"):
                    iq = model.joints[jid].idx_q
                    for lim in (model.lowerPositionLimit, model.upperPositionLimit):
                        if abs(lim[iq]) < 1e300:
                            lim[iq] *= scale
            for f in model.frames:
                f.placement.translation = f.placement.translation * scale
        base = model.frames[fid]
        tip = pin.Frame(
            _TIP, base.parentJoint, fid, base.placement * pin.SE3(np.eye(3), off), pin.FrameType.OP_FRAME
        )
        tid = model.addFrame(tip)
        return cls(model, tid, name=name, source=source, tip_frame=tip_frame, tip_offset_mm=off)

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

    def _config(self, q: np.ndarray) -> np.ndarray:
        return q if self._plain else pin.integrate(self._model, self._neutral, q)

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
        qq = self._config(self.check_q(q))
        pin.framesForwardKinematics(self._model, self._data, qq)
        M = self._data.oMf[self._fid]
        return np.array(M.translation), np.array(M.rotation)

    def jacobian(self, q) -> np.ndarray:
        """The 6 x n Jacobian of the measured point, base frame.

        Parameters
        ----------
        q : array_like, shape (n,)

        Returns
        -------
        ndarray, shape (6, n)
            Rows vx, vy, vz (mm per rad or mm per mm) then wx, wy, wz (rad per joint unit).
        """
        qq = self._config(self.check_q(q))
        J = pin.computeFrameJacobian(self._model, self._data, qq, self._fid, pin.LOCAL_WORLD_ALIGNED)
        return np.array(J).reshape(6, self.n)  # Pinocchio gives a one-joint chain's as a vector

    def forward_many(self, Q) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`forward` of many configurations: positions (N, 3) mm, rotations (N, 3, 3)."""
        Q = np.asarray(Q, dtype=float).reshape(-1, self.n)
        out = [self.forward(q) for q in Q]
        return np.array([p for p, _ in out]).reshape(-1, 3), np.array([R for _, R in out]).reshape(-1, 3, 3)

    def jacobian_many(self, Q) -> np.ndarray:
        """:meth:`jacobian` of many configurations, shape (N, 6, n)."""
        Q = np.asarray(Q, dtype=float).reshape(-1, self.n)
        return np.array([self.jacobian(q) for q in Q]).reshape(-1, 6, self.n)

    def beyond_limits(self, q) -> list[str]:
        """The joints of ``q`` outside their limits, in words (empty when none)."""
        a = np.asarray(q, dtype=float)
        out = []
        for k, (v, lo, hi) in enumerate(zip(a, self.lower, self.upper, strict=True)):
            if v < lo - 1e-12 or v > hi + 1e-12:
                unit, f = ("mm", 1.0) if self.joint_types[k] == "prismatic" else ("deg", 180 / math.pi)
                out.append(
                    f"joint {self.joint_names[k]} at {v * f:.6g} {unit} beyond its limits "
                    f"[{lo * f:.6g}, {hi * f:.6g}] {unit}"
                )
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
        p, R = self.forward(q)
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
            ep, er = float(np.linalg.norm(e_p)), float(np.linalg.norm(e_r)) if e_r.size else 0.0
            if ep < tol_mm and er < tol_rad:
                return IKResult(self._near(q, q_start), True, ep, er, it - 1)
            J = self.jacobian(q)
            A = J[:3] if Rt is None else np.vstack([J[:3], L * J[3:]])
            e = e_p if Rt is None else np.concatenate([e_p, L * e_r])
            cost = float(e @ e)
            while True:
                H = A @ A.T
                step = A.T @ np.linalg.solve(
                    H + lam * (np.trace(H) / H.shape[0] + 1e-30) * np.eye(H.shape[0]), e
                )
                qn = q + step
                pn, Rn = self.forward(qn)
                n_p, n_r = error(pn, Rn)
                en = n_p if Rt is None else np.concatenate([n_p, L * n_r])
                if float(en @ en) < cost or lam > 1e6:
                    break
                lam *= 10.0
            if float(en @ en) >= cost:
                break
            q, e_p, e_r = qn, n_p, n_r
            lam = max(lam / 10.0, 1e-12)
        ep, er = float(np.linalg.norm(e_p)), float(np.linalg.norm(e_r)) if e_r.size else 0.0
        # The steps stalled (round-off) or ran out: converged when within a thousand times the
        # tolerances (1e-6 mm and 1e-9 rad by default), not reached otherwise.
        return IKResult(self._near(q, q_start), ep < tol_mm * 1e3 and er < tol_rad * 1e3, ep, er, it)

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
