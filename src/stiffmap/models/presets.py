"""Named sets of tool positions: the reference studies' measurement layouts.

- :func:`paper48` (Delta, mm, base frame): the reference vision study's 48
  positions, "three planes at different Z levels -200, -310 and -400; each plane
  contains 16 positions spaced equally" (its Section 4): a 4 x 4 grid with x, y in
  {-200, -66.67, 66.67, 200} mm on each plane. Order: plane by plane from
  z = -200 down, then y ascending, then x ascending (row ``16 k + 4 j + i`` is
  ``(x_i, y_j, z_k)``).
- :func:`prr3_points22` (3PRR, mm, the frame of the milling study's eqs. 1-3):
  a reconstruction of the milling study's 22 points (its Fig. 2, not in the
  published text). What is known: 22 points spread over the workspace; eight of
  them, numbered 2, 5, 8, 22, 15, 19, 20 and 21 in geometric order, lie on the
  vertical middle line of the workspace (its Section 2.4 and Fig. 11). Those
  numbers fit rows numbered left to right, top to bottom, with point 22 added
  on the middle line afterwards. The reconstruction, for the default
  :class:`~stiffmap.models.prr3.PRR3` (h = 800 mm, L = 250 mm; middle line
  x = h/2 = 400 mm), uses nine rows 50 mm apart from y = 420 mm down to
  y = 20 mm::

      y = 420:        1    2    3            x = 300, 400, 500
      y = 370:        4    5    6
      y = 320:        7    8    9
      y = 270:  10   11   22   12   13       x = 200, 300, 400, 500, 600
      y = 220:       14   15   16
      y = 170:     17         18             x = 250, 550
      y = 120:            19
      y =  70:            20
      y =  20:            21

  Row ``k`` of the array is point number ``k + 1``. Every point is reachable by
  the default geometry, with both singularity measures >= 0.25.
- ``POSITION_PRESETS``: name -> (mechanism name, function).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = [
    "paper48",
    "prr3_points22",
    "PRR3_MIDDLE_LINE",
    "POSITION_PRESETS",
    "preset_points",
]

#: Numbers (1-based) of the milling study's points on the workspace's vertical
#: middle line, in geometric order (top to bottom in the reconstruction): the
#: points it measured.
PRR3_MIDDLE_LINE: tuple[int, ...] = (2, 5, 8, 22, 15, 19, 20, 21)


def paper48() -> np.ndarray:
    """The reference vision study's 48 positions (mm, Delta base frame).

    Returns
    -------
    ndarray, shape (48, 3), mm
        Row ``16 k + 4 j + i`` is ``(x_i, y_j, z_k)`` with x, y in
        ``linspace(-200, 200, 4)`` and z in (-200, -310, -400).
    """
    g = np.linspace(-200.0, 200.0, 4)
    return np.array([(x, y, z) for z in (-200.0, -310.0, -400.0) for y in g for x in g])


def prr3_points22() -> np.ndarray:
    """Reconstruction of the milling study's 22-point layout (mm, eqs. 1-3 frame).

    Returns
    -------
    ndarray, shape (22, 2), mm
        Row ``k`` is point number ``k + 1`` (see the module docstring for the layout).
    """
    pts: dict[int, tuple[float, float]] = {}
    rows3 = {420.0: (1, 2, 3), 370.0: (4, 5, 6), 320.0: (7, 8, 9), 220.0: (14, 15, 16)}
    for y, nums in rows3.items():
        for x, k in zip((300.0, 400.0, 500.0), nums, strict=True):
            pts[k] = (x, y)
    for x, k in zip((200.0, 300.0, 400.0, 500.0, 600.0), (10, 11, 22, 12, 13), strict=True):
        pts[k] = (x, 270.0)
    pts[17] = (250.0, 170.0)
    pts[18] = (550.0, 170.0)
    for y, k in ((120.0, 19), (70.0, 20), (20.0, 21)):
        pts[k] = (400.0, y)
    return np.array([pts[k] for k in range(1, 23)])


#: Preset name -> (mechanism name, function returning the points).
POSITION_PRESETS: dict[str, tuple[str, Callable[[], np.ndarray]]] = {
    "paper48": ("delta", paper48),
    "points22": ("3prr", prr3_points22),
}


def preset_points(name: str) -> np.ndarray:
    """Points of a named preset (``POSITION_PRESETS``); unknown names list the valid ones."""
    key = name.strip().lower()
    if key not in POSITION_PRESETS:
        raise ValueError(f"unknown position preset {name!r}; valid: {', '.join(POSITION_PRESETS)}")
    return POSITION_PRESETS[key][1]()
