"""The chains of a leg for its inverse kinematics: its spring joints (at rest) folded away.

A leg given by joints becomes :class:`~stiffmap.models.chain.JointSpec` rows without its
springs (:func:`without_springs`); a leg given by a URDF is read again with its spring joints
made fixed (:func:`urdf_without_springs`, through a temporary copy of the URDF).
"""

from __future__ import annotations

import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..geometry import euler_from_matrix, matrix_from_euler
from ..io import read_text_file
from .chain import Chain, JointSpec
from .legs_file import LegJoint

__all__ = ["without_springs", "urdf_without_springs"]


def _placement(xyz, rpy) -> tuple[np.ndarray, np.ndarray]:
    return matrix_from_euler(np.asarray(rpy, dtype=float)), np.asarray(xyz, dtype=float)


def without_springs(joints: tuple[LegJoint, ...], tip) -> tuple[list[JointSpec], np.ndarray]:
    """The leg's joints with its springs at rest folded into the next joint's origin (or the tip)."""
    Rp, tp = np.eye(3), np.zeros(3)
    out = []
    for jt in joints:
        R, t = _placement(jt.xyz_mm or (0.0, 0.0, 0.0), jt.rpy or (0.0, 0.0, 0.0))
        R, t = Rp @ R, Rp @ t + tp
        if jt.role == "spring":
            Rp, tp = R, t
            continue
        out.append(JointSpec(jt.name, jt.type, jt.axis, tuple(t), tuple(euler_from_matrix(R))))
        Rp, tp = np.eye(3), np.zeros(3)
    return out, Rp @ np.asarray(tip, dtype=float) + tp


def urdf_without_springs(path: Path, springs: set[str], tip_frame: str, tip) -> Chain:
    """The URDF's chain with its spring joints turned fixed (at rest), read through a temporary copy."""
    root = ET.fromstring(read_text_file(path, "URDF file"))
    for j in root.iter("joint"):
        if j.get("name") in springs:
            j.set("type", "fixed")
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / path.name
        p.write_text(ET.tostring(root, encoding="unicode"), encoding="utf-8")
        return Chain.from_urdf(p, tip_frame, tip)
