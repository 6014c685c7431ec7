"""stiffmap's six-joint test arm (``robots/arm6.urdf``): the virtual test-bed's serial robot.

A small industrial arm in the style of a 6 kg-class six-axis robot (the URDF's
comment gives the dimensions), with the measured point 100 mm beyond the flange
along the tool axis, and the test-bed's choices:

- the tool points down (tool0's z axis along -z of the base, its x axis along -x),
  the same at every position, so the platform's orientation is constant and the
  campaign's tcp frame keeps the base's axes;
- twenty positions of the measured point spread over a 250 x 300 x 200 mm box in
  front of the robot (:func:`positions20`: the box's corners, its face centres,
  its centre and five points inside), each reached by inverse kinematics from
  :data:`Q_SEED_DEG` (elbow up, wrist not flipped);
- joint stiffnesses :data:`K_THETA` (N*mm/rad), from 20 kN*m/rad at the base to
  3 kN*m/rad at the last wrist joint: the order of what is identified on light
  six-axis arms under position control, soft enough that the reference study's
  0.1-0.5 kg loads deflect the tool by tens of micrometres.
"""

from __future__ import annotations

import itertools
from importlib.resources import files

import numpy as np

from .serial import SerialRobot

__all__ = [
    "URDF",
    "TIP_FRAME",
    "TIP_OFFSET_MM",
    "TOOL_ROTATION",
    "Q_SEED_DEG",
    "K_THETA",
    "LOAD_POINT_MM",
    "positions20",
    "model",
]

#: The arm's URDF (package data).
URDF = str(files("stiffmap.models") / "robots" / "arm6.urdf")
#: The link frame that carries the measured point.
TIP_FRAME = "tool0"
#: The measured point in that frame, mm (100 mm along the tool axis).
TIP_OFFSET_MM = (0.0, 0.0, 100.0)
#: The tool frame's orientation at every position (tool0 to base): a half turn about y, the tool
#: pointing down.
TOOL_ROTATION = np.diag([-1.0, 1.0, -1.0])
#: Seed of the inverse kinematics, degrees: elbow up, wrist pitched down.
Q_SEED_DEG = (0.0, 40.0, -10.0, 0.0, 60.0, 0.0)
#: Joint stiffnesses of the test-bed's arm, N*mm/rad (joints 1 to 6).
K_THETA = (2.0e7, 1.6e7, 1.2e7, 5.0e6, 4.0e6, 3.0e6)
#: Where the test-bed's loads act, relative to the measured point, base axes, mm: a bracket on the
#: tool, off its axis, so that the loads also turn the wrist joints (with the loads at 50 mm from
#: the axis the last joint's stiffness has a standard error of 2.4 % from the test-bed's campaign;
#: from here, 0.7 %: the design computed from the measured displacement covariances).
LOAD_POINT_MM = (150.0, 100.0, -150.0)


def positions20() -> np.ndarray:
    """Twenty positions of the measured point (mm, base frame) in the box x 400-650, y -150-150,
    z 300-500 mm: its 8 corners, 6 face centres, centre and 5 points inside.

    Returns
    -------
    ndarray, shape (20, 3), mm
    """
    corners = list(itertools.product((400.0, 650.0), (-150.0, 150.0), (300.0, 500.0)))
    faces = [(525.0, 0.0, 300.0), (525.0, 0.0, 500.0), (400.0, 0.0, 400.0), (650.0, 0.0, 400.0)]
    faces += [(525.0, -150.0, 400.0), (525.0, 150.0, 400.0)]
    inside = [(525.0, 0.0, 400.0), (460.0, -75.0, 350.0), (590.0, 75.0, 450.0), (460.0, 75.0, 450.0)]
    inside += [(590.0, -75.0, 350.0), (525.0, 0.0, 350.0)]
    return np.array(corners + faces + inside)


def model(configurations=None) -> SerialRobot:
    """The arm as a :class:`~stiffmap.models.serial.SerialRobot`: its URDF, measured point, tool
    orientation, inverse-kinematics seed and joint stiffnesses.

    Parameters
    ----------
    configurations : array_like, shape (n, 6), rad, optional
        Joint configurations of the positions (default: inverse kinematics).
    """
    return SerialRobot.from_urdf(
        URDF,
        TIP_FRAME,
        TIP_OFFSET_MM,
        k_theta=K_THETA,
        configurations=configurations,
        tool_rotation=TOOL_ROTATION,
        q_seed=np.radians(Q_SEED_DEG),
    )
