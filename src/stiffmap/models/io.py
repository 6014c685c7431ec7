"""Files of the model commands: points to evaluate, measurements to fit, map tables.

Formats (CSV with a header; column names case-insensitive; ``#`` lines are comments):

**Points** (``stiffmap model --points``): columns ``x, y`` (3PRR) or ``x, y, z``
(Delta), mm, in the mechanism's base frame.

**Static-error measurements** (``stiffmap fit``; the sensor path): one row per
reading of one displacement component:

- ``x, y[, z]``: pose, mm;
- ``fx, fy[, fz]``: applied force, N;
- ``nx, ny[, nz]`` (optional): unit direction the sensor measures along; when
  absent, the force's direction (the displacement is read along the load);
- ``value_mm``: the measured displacement component, mm;
- ``std_mm`` (optional): its standard error, mm.

**Stiffness measurements** (``stiffmap fit``; the vision path): one row per pose:

- ``x, y[, z]``: pose, mm;
- ``k11, k12, ..., kdd`` (d = 2 or 3): the measured K, N/mm, row-major (the
  reference paper's eq. 9 numbering);
- ``k11_std, ...`` (optional, all or none): standard errors, N/mm.

A file holding ``value_mm`` is read as static errors, one holding ``k11`` as
stiffness matrices.

**Joint configurations** of a serial robot (``stiffmap model urdf --configs``): one row
per configuration, columns ``q1_deg ... qn_deg`` in the chain's joint order
(:attr:`~stiffmap.models.chain.Chain.joint_names`), degrees, a prismatic joint's column
``qk_mm`` (mm); or columns named after those joints, ``shoulder_pan_joint_deg``,
``torso_lift_joint_mm``, in any order. Other columns (a label, the commanded pose) are
ignored; a column named like a joint's (``q7_deg``, ``q2_mm`` for a revolute joint, a
mimic joint's or a joint off the chain) that is not one of the chain's coordinates is
refused, and a missing one named.
"""

from __future__ import annotations

import csv
import io as _io
import math
import os
import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..io import read_csv_columns, read_text_file, sniff_delimiter
from ..loads import MAX_FORCE_N
from ..stiffness import MAX_DISPLACEMENT_MM, MAX_POSITION_MM, MAX_STIFFNESS_N_PER_MM
from .base import Mechanism, ModelMap, PoseError, format_pose
from .fit import ModelFit, fit_static_errors, fit_stiffness
from .serial import SerialRobot

__all__ = [
    "read_points",
    "StaticErrorMeasurements",
    "StiffnessMeasurements",
    "read_measurements",
    "fit_measurements_file",
    "map_records",
    "map_csv",
    "AXIS_NAMES",
    "configuration_columns",
    "joint_name_columns",
    "read_configurations",
    "read_configuration_rows",
    "configuration_records",
    "configuration_file_records",
    "MAX_JOINT_ANGLE_DEG",
]

AXIS_NAMES = ("x", "y", "z")
#: Largest joint angle a configurations file may hold (ten turns), degrees.
MAX_JOINT_ANGLE_DEG = 3600.0
_JOINT_COLUMN = re.compile(r"q(\d+)(_.*)?$")


def read_points(path: str | os.PathLike, dim: int) -> np.ndarray:
    """Positions (mm) from a CSV with columns ``x, y`` (dim 2) or ``x, y, z`` (dim 3).

    Returns
    -------
    ndarray, shape (N, dim), mm

    Raises
    ------
    InputError
        Naming the file, line and column of a bad cell.
    """
    t = read_csv_columns(path, AXIS_NAMES[:dim])
    t.check_magnitude(AXIS_NAMES[:dim], MAX_POSITION_MM, "mm", "position")
    return t.stack(AXIS_NAMES[:dim]).T.copy()


@dataclass(frozen=True)
class StaticErrorMeasurements:
    """Static-error observations read from a file (see module docstring).

    Attributes
    ----------
    points : ndarray, shape (n, dim), mm
    forces : ndarray, shape (n, dim), N
    directions : ndarray, shape (n, dim), unit
    values : ndarray, shape (n,), mm
    std : ndarray, shape (n,), mm, or None
    lines : ndarray of int, shape (n,)
        Line of each row in the file.
    source : str
    """

    points: np.ndarray
    forces: np.ndarray
    directions: np.ndarray
    values: np.ndarray
    std: np.ndarray | None
    lines: np.ndarray
    source: str


@dataclass(frozen=True)
class StiffnessMeasurements:
    """Stiffness matrices read from a file (see module docstring).

    Attributes
    ----------
    points : ndarray, shape (n, dim), mm
    K : ndarray, shape (n, dim, dim), N/mm
    K_std : ndarray, shape (n, dim, dim), N/mm, or None
    lines : ndarray of int, shape (n,)
    source : str
    """

    points: np.ndarray
    K: np.ndarray
    K_std: np.ndarray | None
    lines: np.ndarray
    source: str


def _header(path: str | os.PathLike) -> list[str]:
    # read_csv_columns reports missing files and bad encodings; here only the header is needed.
    t = read_csv_columns(path, ())
    del t
    with open(path, encoding="utf-8-sig") as f:
        lines = f.read().splitlines()
    for row in csv.reader(lines, delimiter=sniff_delimiter(lines)):
        if row and not row[0].lstrip().startswith("#"):
            return [h.strip().lower() for h in row]
    return []


def read_measurements(path: str | os.PathLike, dim: int) -> StaticErrorMeasurements | StiffnessMeasurements:
    """Read a measurements file for ``stiffmap fit`` (format chosen by its columns).

    Parameters
    ----------
    path : path-like
    dim : int
        The mechanism's dimension (2 for the 3PRR, 3 for the Delta).

    Raises
    ------
    InputError
        Naming the file, line and column of the first problem.
    """
    src = str(path)
    header = _header(path)
    _refuse_other_dimension(header, dim, src)
    if "value_mm" in header:
        return _static_error_measurements(path, header, dim)
    if "k11" in header:
        return _stiffness_measurements(path, header, dim)
    ax = AXIS_NAMES[:dim]
    raise InputError(
        "cannot tell the kind of measurements: expected a 'value_mm' column (static errors: "
        f"{', '.join(ax)}, {', '.join('f' + a for a in ax)}, value_mm[, std_mm]) or 'k11' "
        f"(stiffness matrices: {', '.join(ax)}, k11..k{dim}{dim}); header has "
        f"{', '.join(repr(h) for h in header)}",
        source=src,
    )


def _refuse_other_dimension(header: list[str], dim: int, src: str) -> None:
    """A file made for a mechanism of the other dimension (z, fz, nz or k13.. columns)."""
    extra = [c for c in header if c in ("z", "fz", "nz") or (len(c) == 3 and c[0] == "k" and "3" in c[1:])]
    if dim == 2 and extra:
        raise InputError(
            f"columns {', '.join(repr(c) for c in extra)} are 3-D, but this model is planar (x, y); "
            "a 3-D file is for the delta model",
            source=src,
        )
    if dim == 3 and "value_mm" not in header and "k11" in header and "k33" not in header:
        raise InputError(
            "stiffness columns stop at k22 (a planar 2x2 K); this model needs k11..k33", source=src
        )


def _static_error_measurements(path, header: list[str], dim: int) -> StaticErrorMeasurements:
    """Static errors: position, force (N), value_mm[, std_mm][, measured direction n]."""
    src = str(path)
    ax = AXIS_NAMES[:dim]
    fcols = [f"f{a}" for a in ax]
    ncols = [f"n{a}" for a in ax]
    has_n = any(c in header for c in ncols)
    t = read_csv_columns(path, [*ax, *fcols, "value_mm"] + (ncols if has_n else []), ["std_mm"])
    t.check_magnitude(ax, MAX_POSITION_MM, "mm", "position")
    t.check_magnitude(fcols, MAX_FORCE_N, "N", "force")
    t.check_magnitude(("value_mm", "std_mm"), MAX_DISPLACEMENT_MM, "mm", "static error")
    F = t.stack(fcols).T.copy()
    U = _measured_directions(t, ncols, src) if has_n else _force_directions(t, F, src)
    std = t.columns.get("std_mm")
    if std is not None:
        bad = np.flatnonzero(~(std > 0))
        if bad.size:
            raise InputError(
                f"line {t.lines[bad[0]]}, column 'std_mm': {std[bad[0]]:g} is not a positive number",
                source=src,
            )
    return StaticErrorMeasurements(
        points=t.stack(ax).T.copy(),
        forces=F,
        directions=U,
        values=t.columns["value_mm"].copy(),
        std=None if std is None else std.copy(),
        lines=t.lines,
        source=src,
    )


def _measured_directions(t, ncols: list[str], src: str) -> np.ndarray:
    """The unit directions of the n columns (within 1 % of unit length, then normalised)."""
    U = t.stack(ncols).T.copy()
    un = np.linalg.norm(U, axis=1)
    bad = np.flatnonzero(un == 0)
    if bad.size:
        raise InputError(f"line {t.lines[bad[0]]}: the direction ({', '.join(ncols)}) is zero", source=src)
    far = np.flatnonzero(np.abs(un - 1) > 0.01)
    if far.size:
        i = far[0]
        raise InputError(
            f"line {t.lines[i]}: the direction ({', '.join(ncols)}) has length {un[i]:.4g}; "
            "expected a unit vector",
            source=src,
        )
    return U / un[:, None]


def _force_directions(t, F: np.ndarray, src: str) -> np.ndarray:
    """Without n columns the static error is measured along the force: its unit vectors."""
    fn = np.linalg.norm(F, axis=1)
    bad = np.flatnonzero(fn == 0)
    if bad.size:
        raise InputError(
            f"line {t.lines[bad[0]]}: zero force and no nx, ny columns: the measured direction is unknown",
            source=src,
        )
    return F / fn[:, None]


def _stiffness_measurements(path, header: list[str], dim: int) -> StiffnessMeasurements:
    """Stiffness matrices: position, k11..k{dim}{dim} (N/mm)[, their _std columns]."""
    src = str(path)
    ax = AXIS_NAMES[:dim]
    kcols = [f"k{i + 1}{j + 1}" for i in range(dim) for j in range(dim)]
    scols = [f"{c}_std" for c in kcols]
    has_s = any(c in header for c in scols)
    t = read_csv_columns(path, [*ax, *kcols] + (scols if has_s else []))
    t.check_magnitude(ax, MAX_POSITION_MM, "mm", "position")
    t.check_magnitude(kcols + scols, MAX_STIFFNESS_N_PER_MM, "N/mm", "stiffness")
    n = len(t)
    K = t.stack(kcols).T.reshape(n, dim, dim).copy()
    zero = np.flatnonzero(~np.any(K.reshape(n, -1), axis=1))
    if zero.size:
        raise InputError(
            f"line {t.lines[zero[0]]}: every entry of K is zero: not a measured stiffness "
            "(a failed identification written as zeros?)",
            source=src,
        )
    S = None
    if has_s:
        S = t.stack(scols).T.reshape(n, dim, dim).copy()
        bad = np.argwhere(~(S > 0))
        if bad.size:
            i, a, b = bad[0]
            raise InputError(
                f"line {t.lines[i]}, column 'k{a + 1}{b + 1}_std': {S[i, a, b]:g} is not a positive number",
                source=src,
            )
    return StiffnessMeasurements(t.stack(ax).T.copy(), K, S, t.lines, src)


def fit_measurements_file(
    model: Mechanism,
    path: str | os.PathLike,
    params,
    *,
    absolute_sigma: bool = False,
) -> tuple[ModelFit, StaticErrorMeasurements | StiffnessMeasurements]:
    """Read a measurements file and fit ``params`` of ``model`` to it.

    Returns
    -------
    fit : ModelFit
    data : StaticErrorMeasurements or StiffnessMeasurements

    Raises
    ------
    InputError
        Bad file, or a pose the model cannot evaluate (named with its line), or data
        that cannot determine the parameters (:class:`~stiffmap.errors.DesignError`).
    """
    data = read_measurements(path, model.dim)
    try:
        if isinstance(data, StaticErrorMeasurements):
            fit = fit_static_errors(
                model,
                data.points,
                data.forces,
                data.directions,
                data.values,
                params=params,
                std=data.std,
                absolute_sigma=absolute_sigma,
            )
        else:
            fit = fit_stiffness(
                model, data.points, data.K, params=params, K_std=data.K_std, absolute_sigma=absolute_sigma
            )
    except PoseError as e:
        i = e.index if e.index is not None else 0
        raise PoseError(
            f"line {data.lines[i]}: pose {format_pose(data.points[i])} cannot be evaluated by the "
            f"{model.name} model: {e.reason}",
            pose=data.points[i],
            index=i,
            reason=e.reason,
            source=data.source,
        ) from None
    except InputError as e:
        raise e.with_source(data.source) from None
    except ValueError as e:
        raise InputError(str(e), source=data.source) from None
    return fit, data


def map_records(m: ModelMap, force) -> list[dict]:
    """One JSON-able dict per point of a map: position, static error under ``force``, K, indices.

    Parameters
    ----------
    m : ModelMap
    force : array_like, shape (dim,), N

    Returns
    -------
    list of dict
        Keys ``x, y[, z]`` (mm), ``ux, uy[, uz]`` (static error, mm), ``K`` (N/mm,
        nested lists), ``det``, ``min_principal`` (N/mm), ``condition``; or ``x, y[, z]``
        and ``error`` (the reason) for a point that cannot be evaluated.
    """
    dim = m.dim
    u = m.static_error(force)
    out = []
    for i in range(len(m)):
        rec: dict = {AXIS_NAMES[k]: float(m.points[i, k]) for k in range(dim)}
        if m.valid[i]:
            for k in range(dim):
                rec["u" + AXIS_NAMES[k]] = float(u[i, k])
            rec["K"] = m.K[i].tolist()
            rec["det"] = float(m.det[i])
            rec["min_principal"] = float(m.min_principal[i])
            rec["condition"] = float(m.condition[i])
        else:
            rec["error"] = m.reasons[i]
        out.append(rec)
    return out


def map_csv(m: ModelMap, force) -> str:
    """CSV text of a map: ``x, y[, z], ux, uy[, uz], k11..kdd, det, min_principal, condition, error``.

    Invalid points have empty numeric cells and the reason in ``error``.
    """
    dim = m.dim
    ax = AXIS_NAMES[:dim]
    kcols = [f"k{i + 1}{j + 1}" for i in range(dim) for j in range(dim)]
    cols = [*ax, *("u" + a for a in ax), *kcols, "det", "min_principal", "condition", "error"]
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    u = m.static_error(force)
    for i in range(len(m)):
        pos = [f"{v:.6g}" for v in m.points[i]]
        if m.valid[i]:
            nums = [*u[i], *m.K[i].ravel(), m.det[i], m.min_principal[i], m.condition[i]]
            w.writerow(pos + [f"{v:.9g}" for v in nums] + [""])
        else:
            w.writerow(pos + [""] * (len(cols) - dim - 1) + [m.reasons[i]])
    return buf.getvalue()


def configuration_columns(chain) -> list[str]:
    """The columns of a configurations file for ``chain``: ``q1_deg`` ..., ``qk_mm`` for prismatic joints."""
    return [f"q{i + 1}_{'mm' if t == 'prismatic' else 'deg'}" for i, t in enumerate(chain.joint_types)]


def _span(cols: list[str]) -> str:
    """``q1_deg..q5_deg`` for a run of columns of one unit, else the columns listed."""
    if not cols:
        return "no joint columns"
    units = {c.split("_", 1)[-1] for c in cols}
    nums = [int(_JOINT_COLUMN.match(c).group(1)) for c in cols]
    if len(cols) > 2 and len(units) == 1 and nums == list(range(nums[0], nums[0] + len(nums))):
        return f"{cols[0]}..{cols[-1]}"
    return ", ".join(cols)


def _first_header(path: str | os.PathLike, expected: str) -> list[str]:
    """The header row of a CSV (lower case), or InputError for a missing or empty file."""
    src = str(path)
    if not os.path.exists(path):
        raise InputError("file not found", source=src)
    if os.path.isdir(path):
        raise InputError("is a directory, expected a CSV file", source=src)
    lines = read_text_file(path, "CSV file").splitlines()
    for row in csv.reader(lines, delimiter=sniff_delimiter(lines)):
        if row and not row[0].lstrip().startswith("#"):
            return [h.strip().lower() for h in row]
    raise InputError(f"empty file; expected a header with columns {expected}", source=src)


def joint_name_columns(chain) -> list[str]:
    """The named columns of a configurations file: ``<joint>_deg`` (``<joint>_mm`` for prismatic)."""
    return [
        f"{n}_{'mm' if t == 'prismatic' else 'deg'}"
        for n, t in zip(chain.joint_names, chain.joint_types, strict=True)
    ]


def _named_problem(chain, header: list[str]) -> str | None:
    """Why a header naming joints does not give the chain's coordinates (None when it does)."""
    want = [c.lower() for c in joint_name_columns(chain)]
    missing = [c for c in want if c not in header]
    coords = {n.lower() for n in chain.joint_names}
    others = {
        m.name.lower(): f"follows joint {chain.joint_names[m.leader]} (mimic)"
        if m.leader is not None
        else "is held (its leader is above the base frame)"
        for m in chain.mimics
    }
    others |= {h.lower(): "is between the URDF's root and the base frame (held)" for h in chain.held_joints}
    for name in getattr(chain, "urdf_joint_names", ()):
        if name.lower() not in coords and name.lower() not in others:
            others[name.lower()] = f"is not on the chain from {chain.base_frame} to {chain.tip_frame}"
    for c in header:
        stem, _, unit = c.rpartition("_")
        if unit in ("deg", "mm") and stem in others:
            return f"column {c!r}: joint {stem} {others[stem]}: it is not a coordinate of the chain"
        if unit in ("deg", "mm") and stem in coords and c not in want:
            k = [n.lower() for n in chain.joint_names].index(stem)
            right = want[k]
            return (
                f"column {c!r}: joint {chain.joint_names[k]} is {chain.joint_types[k]}: its column is {right}"
            )
    if missing:
        return f"no column for joint(s) {', '.join(missing)} (expected {', '.join(want)})"
    return None


def read_configuration_rows(path: str | os.PathLike, chain) -> tuple[np.ndarray, np.ndarray]:
    """Joint configurations of a serial robot from a CSV, with the line of each row.

    Parameters
    ----------
    path : path-like
        CSV with columns ``q1_deg ... qn_deg`` (``qk_mm`` for a prismatic joint), or named
        after the chain's coordinates (``shoulder_pan_joint_deg``, ``torso_lift_joint_mm``),
        one row per configuration (module docstring).
    chain : Chain
        The robot (its joint names and types; ``n`` columns expected).

    Returns
    -------
    Q : ndarray, shape (N, n)
        rad (revolute), mm (prismatic), in the chain's joint order.
    lines : ndarray of int, shape (N,)
        The line of each row in the file.

    Raises
    ------
    InputError
        Naming the file: missing or extra joint columns (what the robot expects), a column
        naming a joint that is not a coordinate (a mimic joint, a joint off the chain), an
        empty file, a cell that is not a number (line and column), a joint angle beyond ten
        turns.
    """
    src = str(path)
    cols = configuration_columns(chain)
    named = [c.lower() for c in joint_name_columns(chain)]
    header = _first_header(path, f"{_span(cols)} (or {', '.join(named)})")
    found = sorted(
        (c for c in header if _JOINT_COLUMN.match(c)), key=lambda c: int(_JOINT_COLUMN.match(c).group(1))
    )
    if not found and any(c.rpartition("_")[2] in ("deg", "mm") for c in header):
        why = _named_problem(chain, header)
        if why:
            raise InputError(why, source=src)
        cols = named
    elif found != cols:
        extra = [c for c in found if c not in cols]
        hint = ""
        for c in extra:
            k = int(_JOINT_COLUMN.match(c).group(1))
            if 1 <= k <= chain.n and cols[k - 1] != c:
                kind = chain.joint_types[k - 1]
                unit = "mm" if kind == "prismatic" else "degrees"
                name = chain.joint_names[k - 1]
                hint = f" (joint {k}, {name}, is {kind}: its column is {cols[k - 1]}, {unit})"
                break
        raise InputError(
            f"the file has {_span(found)}; {chain.name} has {chain.n} joints "
            f"({', '.join(chain.joint_names)}): expected {_span(cols)}{hint}",
            source=src,
        )
    t = read_csv_columns(path, cols)
    deg = [c for c in cols if c.endswith("_deg")]
    t.check_magnitude(deg, MAX_JOINT_ANGLE_DEG, "deg", "joint angle")
    t.check_magnitude([c for c in cols if c.endswith("_mm")], MAX_POSITION_MM, "mm", "joint position")
    Q = t.stack(cols).T.copy()
    for i, c in enumerate(cols):
        if c.endswith("_deg"):
            Q[:, i] = np.radians(Q[:, i])
    return Q, t.lines


def read_configurations(path: str | os.PathLike, chain) -> np.ndarray:
    """Joint configurations (N, n) in rad (mm for prismatic joints) from a CSV.

    See :func:`read_configuration_rows` (which also gives each row's line).
    """
    return read_configuration_rows(path, chain)[0]


def _q_display(robot: SerialRobot, q: np.ndarray) -> list[float]:
    """Joint coordinates as given in a configurations file: degrees (mm for prismatic joints).

    Rounded to 12 significant digits: the file's 30 comes back as 30, not as the
    29.999999999999996 of its trip through radians.
    """
    return [
        float(f"{float(v) if t == 'prismatic' else math.degrees(float(v)):.12g}")
        for v, t in zip(q, robot.chain.joint_types, strict=True)
    ]


def configuration_file_records(robot: SerialRobot, path) -> tuple[ModelMap, list[dict], np.ndarray]:
    """:func:`configuration_records` of the configurations in a CSV file (their lines kept).

    Returns
    -------
    map : ModelMap
    records : list of dict
    lines : ndarray of int, shape (N,)
        The line of each configuration in the file.
    """
    Q, lines = read_configuration_rows(path, robot.chain)
    mp, recs = configuration_records(robot, Q, lines, str(path))
    return mp, recs, lines


def configuration_records(
    robot: SerialRobot, Q, lines=None, source: str | None = None
) -> tuple[ModelMap, list[dict]]:
    """Evaluate a serial robot at its configurations: one JSON-able dict each.

    Parameters
    ----------
    robot : SerialRobot
    Q : array_like, shape (N, n)
        Configurations, rad or mm.
    lines : array_like of int, shape (N,), optional
        The line of each configuration in its file (for the errors).
    source : str, optional
        That file.

    Returns
    -------
    map : ModelMap
        :meth:`SerialRobot.evaluate_configurations`.
    records : list of dict
        ``q_deg`` (degrees; mm for prismatic joints), ``position`` (mm, base frame), ``K``
        (3 x 3, N/mm: the stiffness a pure force sees), ``K6`` (6 x 6 over u mm and rotation
        rad, or None when the robot has fewer than six compliant joints); or ``q_deg`` and
        ``error``: the reason, after ``FILE line L:`` when given.
    """
    m = robot.evaluate_configurations(Q)
    six = robot.has_k6
    K6 = np.full((len(m), 6, 6), np.nan)
    if six and m.n_valid:
        K6[m.valid] = robot.stiffness6(m.q[m.valid])
    out = []
    for i in range(len(m)):
        rec: dict = {"q_deg": _q_display(robot, m.q[i])}
        if m.valid[i]:
            rec["position"] = m.points[i].tolist()
            rec["K"] = m.K[i].tolist()
            rec["K6"] = K6[i].tolist() if six else None
        else:
            where = " ".join(x for x in (source or "", "" if lines is None else f"line {int(lines[i])}") if x)
            rec["error"] = f"{where}: {m.reasons[i]}" if where else m.reasons[i]
        out.append(rec)
    return m, out
