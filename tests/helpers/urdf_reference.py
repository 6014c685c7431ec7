"""An independent reading of a URDF for the tests: forward kinematics in NumPy from the file's
numbers (origin xyz/rpy, axis, mimic), Jacobian by central differences, C = J K^-1 J^T.

Written from the URDF specification, sharing no code with stiffmap (no Pinocchio, no
stiffmap.models): it is what the models' results are checked against.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MOVING = ("revolute", "continuous", "prismatic")


@dataclass
class RefJoint:
    name: str
    type: str
    parent: str
    child: str
    xyz: np.ndarray  # m
    rpy: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    mimic: tuple[str, float, float] | None


def _vec(el, attr, default):
    if el is None or el.get(attr) is None:
        return np.array(default, dtype=float)
    return np.array([float(v) for v in el.get(attr).split()], dtype=float)


def read_joints(text: str) -> tuple[list[str], dict[str, RefJoint]]:
    """The links and the joints directly under <robot> (the file's units)."""
    root = ET.fromstring(text)
    links = [el.get("name") for el in root.findall("link")]
    joints = {}
    for el in root.findall("joint"):
        t = el.get("type")
        lim = el.find("limit")
        lo, hi = -math.inf, math.inf
        if lim is not None and t in ("revolute", "prismatic"):
            lo, hi = float(lim.get("lower", 0)), float(lim.get("upper", 0))
        m = el.find("mimic")
        mimic = None
        if m is not None:
            mimic = (m.get("joint"), float(m.get("multiplier", 1)), float(m.get("offset", 0)))
        joints[el.get("name")] = RefJoint(
            el.get("name"),
            t,
            el.find("parent").get("link"),
            el.find("child").get("link"),
            _vec(el.find("origin"), "xyz", (0, 0, 0)),
            _vec(el.find("origin"), "rpy", (0, 0, 0)),
            _vec(el.find("axis"), "xyz", (1, 0, 0)),
            lo,
            hi,
            mimic,
        )
    return links, joints


def rot(axis, angle) -> np.ndarray:
    """Rodrigues' formula."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    return rot((0, 0, 1), y) @ rot((0, 1, 0), p) @ rot((1, 0, 0), r)


def path(joints: dict[str, RefJoint], tip: str, base: str | None = None) -> list[str]:
    """Joint names from ``base`` (default the root) down to ``tip``."""
    by_child = {j.child: j for j in joints.values()}
    out = []
    at = tip
    while at in by_child and at != base:
        out.append(by_child[at].name)
        at = by_child[at].parent
    return out[::-1]


def leader(joints, name) -> tuple[str, float, float]:
    """The joint a mimic joint ultimately follows, with the composed multiplier and offset (file units)."""
    mult, off = 1.0, 0.0
    j = joints[name]
    while j.mimic is not None:
        ln, m, o = j.mimic
        off += mult * o
        mult *= m
        j = joints[ln]
    return j.name, mult, off


def coordinates(joints, chain: list[str]) -> list[str]:
    """The chain's coordinates by the documented rule: path order, a mimic's leader in its place."""
    out = []
    pos = {}
    for k, jn in enumerate(chain):
        j = joints[jn]
        if j.type not in MOVING:
            continue
        name = leader(joints, jn)[0]
        key = chain.index(name) if name in chain else k
        pos[name] = min(pos.get(name, key), key)
    out = sorted(pos, key=pos.__getitem__)
    return out


def transform(joints, chain: list[str], values: dict[str, float]) -> np.ndarray:
    """4x4 base-to-tip transform (metres), every joint's value given in the file's units."""
    T = np.eye(4)
    for jn in chain:
        j = joints[jn]
        O = np.eye(4)
        O[:3, :3] = rpy_matrix(j.rpy)
        O[:3, 3] = j.xyz
        Mo = np.eye(4)
        if j.type in ("revolute", "continuous"):
            Mo[:3, :3] = rot(j.axis, values[jn])
        elif j.type == "prismatic":
            Mo[:3, 3] = j.axis / np.linalg.norm(j.axis) * values[jn]
        T = T @ O @ Mo
    return T


def values_of(joints, chain, coords, q_file) -> dict[str, float]:
    """Every moving joint's value on the chain from the coordinates (file units)."""
    v = dict(zip(coords, q_file, strict=True))
    out = {}
    for jn in chain:
        if joints[jn].type in MOVING:
            ln, m, o = leader(joints, jn)
            out[jn] = m * v.get(ln, 0.0) + o
    return out


def tip_pose_mm(joints, chain, coords, q, offset_mm) -> tuple[np.ndarray, np.ndarray]:
    """Measured point (mm) and tip rotation at coordinates q (rad, or mm for prismatic)."""
    q_file = [qi / 1000.0 if joints[c].type == "prismatic" else qi for c, qi in zip(coords, q, strict=True)]
    T = transform(joints, chain, values_of(joints, chain, coords, q_file))
    p = T[:3, 3] * 1000.0 + T[:3, :3] @ np.asarray(offset_mm, dtype=float)
    return p, T[:3, :3]


def rotvec(R: np.ndarray) -> np.ndarray:
    c = max(-1.0, min(1.0, (np.trace(R) - 1) / 2))
    a = math.acos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w / 2 if a < 1e-12 else w * a / (2 * math.sin(a))


def jacobian_fd(joints, chain, coords, q, offset_mm, h: float = 1e-6) -> np.ndarray:
    """6 x n Jacobian by central differences (mm and rad per coordinate unit), base frame."""
    n = len(coords)
    J = np.zeros((6, n))
    for k in range(n):
        step = h * (1000.0 if joints[coords[k]].type == "prismatic" else 1.0)
        dq = np.zeros(n)
        dq[k] = step
        pp, Rp = tip_pose_mm(joints, chain, coords, q + dq, offset_mm)
        pm, Rm = tip_pose_mm(joints, chain, coords, q - dq, offset_mm)
        J[:3, k] = (pp - pm) / (2 * step)
        J[3:, k] = rotvec(Rp @ Rm.T) / (2 * step)
    return J


def joint_column_fd(joints, chain, coords, q, offset_mm, joint: str, h: float = 1e-6) -> np.ndarray:
    """The measured point's motion (mm, rad; base frame) per unit of one joint's own value
    (rad or mm) with every other joint held: a mimic joint's spring of its own."""
    q_file = [qi / 1000.0 if joints[c].type == "prismatic" else qi for c, qi in zip(coords, q, strict=True)]
    vals = values_of(joints, chain, coords, q_file)
    step = h * (1000.0 if joints[joint].type == "prismatic" else 1.0)
    unit = 1000.0 if joints[joint].type == "prismatic" else 1.0  # file units per stiffmap unit

    def pose(d):
        v = dict(vals)
        v[joint] += d / unit
        T = transform(joints, chain, v)
        return T[:3, 3] * 1000.0 + T[:3, :3] @ np.asarray(offset_mm, dtype=float), T[:3, :3]

    pp, Rp = pose(step)
    pm, Rm = pose(-step)
    return np.concatenate([(pp - pm) / (2 * step), rotvec(Rp @ Rm.T) / (2 * step)])


def stiffness(
    joints, chain, coords, q, k, offset_mm
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, float]:
    """Measured point (mm), K, K6 and the translation rank measure at coordinates q, from
    C = J diag(1/k) J^T with J by central differences: K = C[:3, :3]^-1 where the translational
    rows have rank 3 (their inverse condition above 1e-6, else None), K6 = C^-1 where J has
    rank 6 (else None)."""
    p, _ = tip_pose_mm(joints, chain, coords, q, offset_mm)
    J = jacobian_fd(joints, chain, coords, q, offset_mm)
    C = J @ np.diag(1.0 / np.asarray(k, dtype=float)) @ J.T
    s = np.linalg.svd(J[:3], compute_uv=False)
    trans = s[-1] / s[0] if s.size >= 3 and s[0] > 0 else 0.0
    K = np.linalg.inv(C[:3, :3]) if trans > 1e-6 else None
    rank6 = len(coords) >= 6 and np.linalg.matrix_rank(J, tol=1e-9 * np.abs(J).max()) == 6
    return p, K, np.linalg.inv(C) if rank6 else None, trans


def write_configs(path: Path, joints, coords, Q) -> None:
    """Configurations Q (rows over ``coords``, rad or mm for a prismatic joint, as
    :func:`tip_pose_mm` takes them) as the CSV ``stiffmap model urdf --configs`` reads: a
    ``label`` column, then ``NAME_deg`` (``NAME_mm`` for a prismatic joint), full precision."""
    cols = [f"{c}_{'mm' if joints[c].type == 'prismatic' else 'deg'}" for c in coords]
    rows = [",".join(["label", *cols])]
    for i, q in enumerate(Q):
        vals = [
            v if joints[c].type == "prismatic" else math.degrees(v) for c, v in zip(coords, q, strict=True)
        ]
        rows.append(",".join([f"c{i + 1}", *(repr(float(v)) for v in vals)]))
    path.write_text("\n".join(rows) + "\n")
