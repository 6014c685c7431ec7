"""Position layouts, grids and load directions from text; joint stiffnesses from text.

These turn what a user writes (``--grid 200:600:9,20:420:9 --direction -x``, or the same
texts from Python) into arrays; errors are ``ValueError`` saying what was expected, without
the option's name (the command line adds it). Which kind of robot a layout belongs to, and
its defaults, are in the registry of robot kinds (:mod:`stiffmap.kinds`).

- :func:`grid_points`: a regular grid ``X0:X1:NX,Y0:Y1:NY[,...]``;
  :func:`positions_from_list`: a list ``x,y,z;x,y,z``, and :func:`select_positions` to keep
  some of them by number; :func:`force_direction`: ``x``, ``-z`` or comma-separated components;
  :func:`joint_stiffnesses_from_text`: a serial robot's ``k1`` .. ``kn``.

Named sets of tool positions, the reference studies' measurement layouts:

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
- The robot kinds' entries (:mod:`stiffmap.kinds`) name these layouts: ``paper48`` (delta),
  ``points22`` (3prr), ``arm20`` (urdf, :func:`stiffmap.models.arm6.positions20`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..stiffness import MAX_POSITION_MM
from .base import check_positive, check_stiffness
from .io import AXIS_NAMES

__all__ = [
    "paper48",
    "prr3_points22",
    "PRR3_MIDDLE_LINE",
    "grid_points",
    "positions_from_list",
    "select_positions",
    "MAX_GRID_POINTS",
    "force_direction",
    "joint_stiffnesses_from_text",
]

#: Most points a grid may hold.
MAX_GRID_POINTS = 1_000_000

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


def grid_points(spec: str, dim: int, presets: str = "") -> np.ndarray:
    """Positions of a regular grid ``X0:X1:NX,Y0:Y1:NY[,Z0:Z1:NZ]``.

    Parameters
    ----------
    spec : str
        ``dim`` comma-separated axes, each ``START:STOP:N`` (N from 1 to 1 000 000) or a
        single value, mm.
    dim : {2, 3}
    presets : str
        The names of layouts that would do instead, for the message.

    Returns
    -------
    ndarray, shape (N, dim), mm
        The grid's points, x varying fastest, then y, then z.

    Raises
    ------
    ValueError
        Naming the spec (as ``'spec': ...``), the bad axis and what is expected, or more
        than :data:`MAX_GRID_POINTS` points.

    Examples
    --------
    >>> grid_points("0:10:3,5", 2).tolist()
    [[0.0, 5.0], [5.0, 5.0], [10.0, 5.0]]
    """
    parts = spec.split(",")
    hint = (
        f"expected {f'a preset ({presets}) or ' if presets else ''}"
        f"{dim} comma-separated axes, each START:STOP:N or a single value in mm "
        f"(e.g. {'-200:200:5,-200:200:5,-310' if dim == 3 else '200:600:9,20:420:9'})"
    )
    if len(parts) != dim:
        raise ValueError(f"{spec!r}: {hint}")
    axes = []
    for p in parts:
        f = p.split(":")
        try:
            if len(f) == 1:
                axes.append(np.array([float(f[0])]))
            elif len(f) == 3:
                n = int(f[2])
                if n < 1 or n > MAX_GRID_POINTS:
                    raise ValueError
                axes.append(np.linspace(float(f[0]), float(f[1]), n))
            else:
                raise ValueError
        except ValueError:
            raise ValueError(f"{spec!r}: bad axis {p!r}; {hint}") from None
        if not np.all(np.isfinite(axes[-1])):
            raise ValueError(f"{spec!r}: axis {p!r} is not finite")
        _check_plausible(axes[-1], f"{spec!r}: axis {p!r}")
    mesh = np.meshgrid(*axes[::-1], indexing="ij")
    pts = np.stack([m.ravel() for m in mesh[::-1]], axis=1)
    if pts.shape[0] > MAX_GRID_POINTS:
        raise ValueError(f"{spec!r}: {pts.shape[0]} points; at most 1 000 000")
    return pts


def positions_from_list(text: str, dim: int, robot: str = "the robot", presets: str = "") -> np.ndarray:
    """Positions from a list ``x,y,z;x,y,z`` (``x,y;x,y`` in 2-D), mm.

    Raises
    ------
    ValueError
        As ``'text': expected a preset (PRESETS), a CSV file with columns x, y, z (mm), or
        positions 'x,y,z;x,y,z' in mm for ROBOT`` (the command line puts its option in front).
    """
    try:
        P = np.array([[float(v) for v in item.split(",")] for item in text.split(";") if item.strip()])
    except ValueError:
        P = np.zeros((0, 0))
    if P.ndim != 2 or P.shape[0] == 0 or P.shape[1] != dim or not np.all(np.isfinite(P)):
        cols = AXIS_NAMES[:dim]
        c = ",".join(cols)
        raise ValueError(
            f"{text!r}: expected {f'a preset ({presets}), ' if presets else ''}a CSV file with columns "
            f"{', '.join(cols)} (mm), or positions '{c};{c}' in mm for {robot}"
        )
    _check_plausible(P, repr(text))
    return P


def _check_plausible(values: np.ndarray, what: str) -> None:
    """Coordinates within +-MAX_POSITION_MM (a position the models can take), else ValueError."""
    far = np.abs(values) > MAX_POSITION_MM
    if far.any():
        raise ValueError(
            f"{what}: {values[far][0]:g} mm is beyond +-{MAX_POSITION_MM:g} mm: not a plausible position"
        )


def select_positions(points: np.ndarray, select: str | None) -> np.ndarray:
    """The positions numbered in ``select`` (1-based, comma-separated, in that order); all when None.

    Raises
    ------
    ValueError
        As ``'select': expected comma-separated position numbers between 1 and N``, or
        naming a number given twice.
    """
    if not select:
        return points
    try:
        idx = [int(v) for v in select.split(",") if v.strip()]
    except ValueError:
        idx = []
    if not idx or min(idx) < 1 or max(idx) > len(points):
        raise ValueError(f"{select!r}: expected comma-separated position numbers between 1 and {len(points)}")
    dup = sorted({i for i in idx if idx.count(i) > 1})
    if dup:
        raise ValueError(f"{select!r}: position {dup[0]} is given more than once")
    return points[[i - 1 for i in idx]]


def force_direction(text: str, dim: int) -> np.ndarray:
    """A unit force direction from ``x``, ``-z``... or ``dim`` comma-separated components.

    Returns
    -------
    ndarray, shape (dim,)

    Raises
    ------
    ValueError
        As ``'text': expected one of x, y, -x, -y or 2 comma-separated components``.
    """
    axes = "xyz"[:dim]
    t = text.strip().lower()
    sign = 1.0
    if t[:1] in "+-" and t[1:] in tuple(axes):
        sign = -1.0 if t[0] == "-" else 1.0
        t = t[1:]
    if t in tuple(axes):
        u = np.zeros(dim)
        u[axes.index(t)] = sign
        return u
    try:
        u = np.array([float(v) for v in text.split(",")])
    except ValueError:
        u = np.zeros(0)
    if u.shape != (dim,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
        names = ", ".join([*axes, *("-" + a for a in axes)])
        raise ValueError(f"{text!r}: expected one of {names} or {dim} comma-separated components")
    return u / np.linalg.norm(u)


def joint_stiffnesses_from_text(items: Sequence[str], chain) -> tuple[float, ...]:
    """A serial robot's joint stiffnesses from ``--param`` texts.

    Parameters
    ----------
    items : sequence of str
        Each ``NAME=VALUE[,NAME=VALUE...]``: ``k<i>=K`` (joint i, the URDF's joint order),
        ``k_theta=K`` (one value for every joint, before the ``k<i>``); N*mm/rad for revolute
        joints, N/mm for prismatic ones, ``inf`` rigid. ``k_theta=K1,K2,...,Kn``, a list in
        the joints' order, is the old form of ``k1`` .. ``kn`` and still read.
    chain : Chain
        The robot (its joints, for the count and the messages).

    Returns
    -------
    tuple of float, length n

    Raises
    ------
    ValueError
        Saying what was expected: an item that is not NAME=VALUE, a value that is not a
        number, an unknown name, k_theta of the wrong length (naming the URDF and its
        joints), a joint without a stiffness (there is no default), a non-positive value.
    """
    n = chain.n
    joints = ", ".join(chain.joint_names)
    units = "N*mm/rad" + (", N/mm for prismatic joints" if "prismatic" in chain.joint_types else "")
    valid = [f"k{i + 1}" for i in range(n)]
    given: dict[str, list[float]] = {}
    key = None
    for item in items:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            if "=" in part:
                key, text = (x.strip() for x in part.split("=", 1))
                if key not in ("k_theta", *valid):
                    raise ValueError(
                        f"unknown urdf parameter {key!r}; valid: {valid[0]}..{valid[-1]} (one joint each: "
                        f"{joints}) or k_theta (one value for all {n})"
                    )
                given[key] = []
            elif key == "k_theta":
                text = part
            else:
                raise ValueError(f"{part!r} should look like NAME=VALUE (k1=K1,k2=K2,...,k{n}=K{n})")
            try:
                given[key].append(float(text))
            except ValueError:
                raise ValueError(f"{key}: {text!r} is not a number ({units})") from None
    k: list[float | None] = [None] * n
    if "k_theta" in given:
        v = given["k_theta"]
        if len(v) not in (1, n):
            raise ValueError(
                f"k_theta has {len(v)} values; {chain.source} ({chain.name}) has {n} joints ({joints}): "
                f"give {n} stiffnesses in that order ({units}), or one for all"
            )
        k = list(v * n if len(v) == 1 else v)
    for i, name in enumerate(valid):
        if name in given:
            k[i] = given[name][0]
    missing = [chain.joint_names[i] for i in range(n) if k[i] is None]
    if missing:
        raise ValueError(
            f"no stiffness for joint(s) {', '.join(missing)} of {chain.source}: a URDF robot has no "
            f"default; give k1=K1,...,k{n}=K{n} for {joints} ({units}), or k_theta=K for all"
        )
    out = []
    for i, v in enumerate(k):
        name, unit = (
            f"k{i + 1} ({chain.joint_names[i]})",
            "N/mm" if chain.joint_types[i] == "prismatic" else "N*mm/rad",
        )
        out.append(check_stiffness(name, check_positive(name, v, unit, allow_inf=True), unit))
    return tuple(out)
