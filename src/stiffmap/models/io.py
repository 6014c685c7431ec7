"""Files of the model commands: points to evaluate, measurements to fit, map tables.

Formats (CSV with a header; column names case-insensitive; ``#`` lines are comments):

**Points** (``stiffmap model --points``): columns ``x, y`` (3PRR) or ``x, y, z``
(Delta), mm, in the mechanism's base frame; for a robot whose platform turns (a legs TOML
with ``dim = 6``) also ``roll_deg, pitch_deg, yaw_deg`` (all three or none: 0), degrees.

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

For a robot whose platform turns (``dim = 6``) the pose of a row is ``x, y, z`` (mm) and,
all three or none (0), ``roll_deg, pitch_deg, yaw_deg``; forces ``fx, fy, fz`` act at the
tool point; stiffness rows hold K6 (``k11..k66``: N/mm, N and N*mm/rad blocks, over the
displacement (u mm, rotation vector rad)) or K of a pure force (``k11..k33``). A file with
those columns given to a robot whose platform only translates is refused. The map CSV of
such a robot (:func:`map_csv`) is a K6 file ``stiffmap fit`` reads back.

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
from .base import POSE_DIM, Mechanism, ModelMap, PoseError, format_pose
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
    "ORIENTATION_COLUMNS",
    "configuration_columns",
    "joint_name_columns",
    "read_configurations",
    "read_configuration_rows",
    "configuration_records",
    "configuration_file_records",
    "MAX_JOINT_ANGLE_DEG",
]

AXIS_NAMES = ("x", "y", "z")
#: A pose's orientation columns (degrees): roll about x, pitch about y, yaw about z.
ORIENTATION_COLUMNS = ("roll_deg", "pitch_deg", "yaw_deg")
#: Largest joint angle a configurations file may hold (ten turns), degrees.
MAX_JOINT_ANGLE_DEG = 3600.0
_JOINT_COLUMN = re.compile(r"q(\d+)(_.*)?$")


def read_points(path: str | os.PathLike, dim: int) -> np.ndarray:
    """Positions (mm) from a CSV with columns ``x, y`` (dim 2) or ``x, y, z`` (dim 3).

    For ``dim = 6`` (a robot whose platform turns) poses: ``x, y, z`` (mm) and, all three or
    none (then 0), ``roll_deg, pitch_deg, yaw_deg`` (degrees within +-180; R = Rz(yaw)
    Ry(pitch) Rx(roll), URDF's convention), returned in rad.

    Returns
    -------
    ndarray, shape (N, dim)
        mm (and rad for the orientation of a pose).

    Raises
    ------
    InputError
        Naming the file, line and column of a bad cell; for poses, an orientation column
        without the others; for positions (dim 2 or 3), an orientation that is not 0 (it
        would be left out: the robot's platform does not turn).
    """
    if dim == POSE_DIM:
        return _read_poses(path)
    t = read_csv_columns(path, AXIS_NAMES[:dim], ORIENTATION_COLUMNS)
    for c in ORIENTATION_COLUMNS:  # poses given for a robot whose platform keeps its orientation
        turned = np.flatnonzero(t.columns.get(c, np.zeros(0)) != 0)
        if turned.size:
            i = int(turned[0])
            raise InputError(
                f"line {t.lines[i]}, column {c!r}: {t.columns[c][i]:g} deg, but this robot's platform keeps "
                "its orientation (only a platform that turns, as a dim = 6 legs TOML's, is held turned): "
                "leave the orientation columns out",
                source=str(path),
            )
    t.check_magnitude(AXIS_NAMES[:dim], MAX_POSITION_MM, "mm", "position")
    return t.stack(AXIS_NAMES[:dim]).T.copy()


def _read_poses(path: str | os.PathLike) -> np.ndarray:
    """Poses (N, 6): x, y, z mm and roll, pitch, yaw rad, from a CSV (:func:`read_points`)."""
    t = read_csv_columns(path, AXIS_NAMES, ORIENTATION_COLUMNS)
    return _table_points(t, POSE_DIM, str(path))


def _table_points(t, dim: int, source: str) -> np.ndarray:
    """The positions (N, dim) mm of a table, or for ``dim = 6`` its poses (N, 6), rad for the
    orientation (all three columns or none: 0), checked."""
    ax = AXIS_NAMES[: min(dim, 3)]
    t.check_magnitude(ax, MAX_POSITION_MM, "mm", "position")
    if dim != POSE_DIM:
        return t.stack(ax).T.copy()
    given = [c for c in ORIENTATION_COLUMNS if t.has(c)]
    if given and len(given) < 3:
        missing = [c for c in ORIENTATION_COLUMNS if c not in given]
        raise InputError(
            f"has {', '.join(given)} but not {', '.join(missing)}: give the orientation's three columns "
            f"({', '.join(ORIENTATION_COLUMNS)}, degrees) or none (0)",
            source=source,
        )
    t.check_magnitude(given, 180.0, "deg", "roll, pitch or yaw")
    out = np.zeros((len(t), POSE_DIM))
    out[:, :3] = t.stack(AXIS_NAMES).T
    if given:
        out[:, 3:] = np.radians(t.stack(ORIENTATION_COLUMNS).T)
    return out


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
        The mechanism's dimension (2 for the 3PRR, 3 for the Delta, 6 for a robot whose
        platform turns: poses with ``roll_deg, pitch_deg, yaw_deg``, forces ``fx, fy, fz``,
        stiffness ``k11..k66`` (K6) or ``k11..k33`` (K of a pure force)).

    Raises
    ------
    InputError
        Naming the file, line and column of the first problem.
    """
    src = str(path)
    header = _header(path)
    _check_measurement_dim(header, dim, src)
    if "value_mm" in header:
        return _read_static_errors(path, header, dim)
    if "k11" in header:
        return _read_stiffness(path, header, dim)
    ax = AXIS_NAMES[: min(dim, 3)]
    kd = 3 if dim == POSE_DIM else dim
    six = " (or k11..k66: K6)" if dim == POSE_DIM else ""
    raise InputError(
        "cannot tell the kind of measurements: expected a 'value_mm' column (static errors: "
        f"{', '.join(ax)}, {', '.join('f' + a for a in ax)}, value_mm[, std_mm]) or 'k11' "
        f"(stiffness matrices: {', '.join(ax)}, k11..k{kd}{kd}{six}); header has "
        f"{', '.join(repr(h) for h in header)}",
        source=src,
    )


def _check_measurement_dim(header: list[str], dim: int, src: str) -> None:
    """Refuse a file made for a mechanism of another dimension (its extra columns named)."""
    # 3-D columns (z, fz, nz, k13..) in a planar file; a pose's or K6's in a translational one.
    extra = [c for c in header if c in ("z", "fz", "nz") or (len(c) == 3 and c[0] == "k" and "3" in c[1:])]
    if dim == 2 and extra:
        raise InputError(
            f"columns {', '.join(repr(c) for c in extra)} are 3-D, but this model is planar (x, y); "
            "a 3-D file is for the delta model",
            source=src,
        )
    six = [c for c in header if c in ORIENTATION_COLUMNS or c in ("k44", "k55", "k66")]
    if dim != POSE_DIM and six:
        raise InputError(
            f"columns {', '.join(repr(c) for c in six)} are a turning platform's (poses, K6), but this "
            f"model's platform only translates (dim = {dim})",
            source=src,
        )
    if dim != 2 and "value_mm" not in header and "k11" in header and "k33" not in header:
        raise InputError(
            "stiffness columns stop at k22 (a planar 2x2 K); this model needs k11..k33"
            + (" (or k11..k66: K6)" if dim == POSE_DIM else ""),
            source=src,
        )


def _read_static_errors(path, header: list[str], dim: int) -> StaticErrorMeasurements:
    """Static-error readings (module docstring); for ``dim = 6`` at poses, forces 3-D."""
    src = str(path)
    ax = AXIS_NAMES[: min(dim, 3)]
    fcols = [f"f{a}" for a in ax]
    ncols = [f"n{a}" for a in ax]
    has_n = any(c in header for c in ncols)
    more = ORIENTATION_COLUMNS if dim == POSE_DIM else ()
    t = read_csv_columns(path, [*ax, *fcols, "value_mm"] + (ncols if has_n else []), ["std_mm", *more])
    P = _table_points(t, dim, src)
    t.check_magnitude(fcols, MAX_FORCE_N, "N", "force")
    t.check_magnitude(("value_mm", "std_mm"), MAX_DISPLACEMENT_MM, "mm", "static error")
    F = t.stack(fcols).T.copy()
    fn = np.linalg.norm(F, axis=1)
    if has_n:
        U = t.stack(ncols).T.copy()
        un = np.linalg.norm(U, axis=1)
        bad = np.flatnonzero(un == 0)
        if bad.size:
            raise InputError(
                f"line {t.lines[bad[0]]}: the direction ({', '.join(ncols)}) is zero", source=src
            )
        far = np.flatnonzero(np.abs(un - 1) > 0.01)
        if far.size:
            i = far[0]
            raise InputError(
                f"line {t.lines[i]}: the direction ({', '.join(ncols)}) has length {un[i]:.4g}; "
                "expected a unit vector",
                source=src,
            )
        U = U / un[:, None]
    else:
        bad = np.flatnonzero(fn == 0)
        if bad.size:
            raise InputError(
                f"line {t.lines[bad[0]]}: zero force and no nx, ny columns: the measured direction "
                "is unknown",
                source=src,
            )
        U = F / fn[:, None]
    std = t.columns.get("std_mm")
    if std is not None:
        bad = np.flatnonzero(~(std > 0))
        if bad.size:
            raise InputError(
                f"line {t.lines[bad[0]]}, column 'std_mm': {std[bad[0]]:g} is not a positive number",
                source=src,
            )
    values = t.columns["value_mm"].copy()
    return StaticErrorMeasurements(P, F, U, values, None if std is None else std.copy(), t.lines, src)


def _read_stiffness(path, header: list[str], dim: int) -> StiffnessMeasurements:
    """Stiffness matrices (module docstring); for ``dim = 6`` K6 (k11..k66) or K (k11..k33)."""
    src = str(path)
    ax = AXIS_NAMES[: min(dim, 3)]
    m = 6 if dim == POSE_DIM and "k66" in header else min(dim, 3)
    kcols = [f"k{i + 1}{j + 1}" for i in range(m) for j in range(m)]
    scols = [f"{c}_std" for c in kcols]
    has_s = any(c in header for c in scols)
    more = ORIENTATION_COLUMNS if dim == POSE_DIM else ()
    t = read_csv_columns(path, [*ax, *kcols] + (scols if has_s else []), more)
    P = _table_points(t, dim, src)
    force = [c for c in kcols if int(c[1]) <= 3 and int(c[2]) <= 3]
    t.check_magnitude(force + [f"{c}_std" for c in force], MAX_STIFFNESS_N_PER_MM, "N/mm", "stiffness")
    # K6's coupling (N) and rotation (N*mm/rad) blocks: N/mm times a metre of lever (squared).
    rot = [c for c in kcols if c not in force]
    t.check_magnitude(
        rot + [f"{c}_std" for c in rot], MAX_STIFFNESS_N_PER_MM * 1e6, "N or N*mm/rad", "stiffness"
    )
    n = len(t)
    K = t.stack(kcols).T.reshape(n, m, m).copy()
    zero = np.flatnonzero(~np.any(K.reshape(n, -1), axis=1))
    if zero.size:
        raise InputError(
            f"line {t.lines[zero[0]]}: every entry of K is zero: not a measured stiffness "
            "(a failed identification written as zeros?)",
            source=src,
        )
    S = None
    if has_s:
        S = t.stack(scols).T.reshape(n, m, m).copy()
        bad = np.argwhere(~(S > 0))
        if bad.size:
            i, a, b = bad[0]
            raise InputError(
                f"line {t.lines[i]}, column 'k{a + 1}{b + 1}_std': {S[i, a, b]:g} is not a positive number",
                source=src,
            )
    return StiffnessMeasurements(P, K, S, t.lines, src)


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


def _map_errors(m: ModelMap, force, moment) -> np.ndarray:
    """Static errors of a map: u (N, dim) mm; with K6, (u mm, rotation rad) (N, 6) under the
    wrench (force, moment) at the tool point."""
    if m.K6 is None:
        if moment is not None:
            raise ValueError(f"{m.mechanism}: a moment needs a platform that turns (dim = 6, K6)")
        return m.static_error(force)
    M = np.zeros(3) if moment is None else np.asarray(moment, dtype=np.float64)
    return m.static_error6(np.concatenate([np.asarray(force, dtype=np.float64), M]))


def _pose_cells(p: np.ndarray) -> dict[str, float]:
    """A point's columns: x, y[, z] mm; a pose's also roll_deg, pitch_deg, yaw_deg."""
    rec = {AXIS_NAMES[k]: float(p[k]) for k in range(min(p.size, 3))}
    if p.size == POSE_DIM:
        rec.update({c: float(np.degrees(v)) for c, v in zip(ORIENTATION_COLUMNS, p[3:], strict=True)})
    return rec


def map_records(m: ModelMap, force, moment=None) -> list[dict]:
    """One JSON-able dict per point of a map: position, static error under ``force``, K, indices.

    Parameters
    ----------
    m : ModelMap
    force : array_like, shape (dim,) (3 for a platform that turns), N
    moment : array_like, shape (3,), N*mm, optional
        Only for a map with K6: the wrench (force, moment) at the tool point.

    Returns
    -------
    list of dict
        Keys ``x, y[, z]`` (mm), ``ux, uy[, uz]`` (static error, mm), ``K`` (N/mm,
        nested lists), ``det``, ``min_principal`` (N/mm), ``condition``; or ``x, y[, z]``
        and ``error`` (the reason) for a point that cannot be evaluated. With K6 (a
        platform that turns): also ``roll_deg, pitch_deg, yaw_deg`` (the pose), ``rx_rad,
        ry_rad, rz_rad`` (the platform's rotation vector under the wrench), ``K6`` (N/mm,
        N, N*mm/rad blocks), ``K_rot`` and ``min_principal_rot`` (N*mm/rad).
    """
    dim = m.dim
    u = _map_errors(m, force, moment)
    out = []
    for i in range(len(m)):
        rec: dict = _pose_cells(m.points[i])
        if m.valid[i]:
            for k in range(dim):
                rec["u" + AXIS_NAMES[k]] = float(u[i, k])
            if m.K6 is not None:
                for k in range(3):
                    rec[f"r{AXIS_NAMES[k]}_rad"] = float(u[i, 3 + k])
            rec["K"] = m.K[i].tolist()
            if m.K6 is not None:
                rec["K6"] = m.K6[i].tolist()
                rec["K_rot"] = m.K_rot[i].tolist()
                rec["min_principal_rot"] = float(m.min_principal_rot[i])
            rec["det"] = float(m.det[i])
            rec["min_principal"] = float(m.min_principal[i])
            rec["condition"] = float(m.condition[i])
        else:
            rec["error"] = m.reasons[i]
        out.append(rec)
    return out


def map_csv(m: ModelMap, force, moment=None) -> str:
    """CSV text of a map: ``x, y[, z], ux, uy[, uz], k11..kdd, det, min_principal, condition, error``.

    With K6 (a platform that turns; ``moment`` N*mm as in :func:`map_records`): ``x, y, z,
    roll_deg, pitch_deg, yaw_deg, ux, uy, uz, rx_rad, ry_rad, rz_rad, k11..k66`` (K6, the
    columns ``stiffmap fit`` reads back), ``det, min_principal, min_principal_rot,
    condition, error`` (det and min_principal of K, the stiffness a pure force sees).
    Invalid points have empty numeric cells and the reason in ``error``.
    """
    six = m.K6 is not None
    dim = m.dim
    ax = AXIS_NAMES[:dim]
    kd = 6 if six else dim
    kcols = [f"k{i + 1}{j + 1}" for i in range(kd) for j in range(kd)]
    pose = [*ax, *ORIENTATION_COLUMNS] if six else list(ax)
    errs = [*("u" + a for a in ax), *(f"r{a}_rad" for a in ax)] if six else ["u" + a for a in ax]
    idx = ["det", "min_principal", *(["min_principal_rot"] if six else []), "condition"]
    cols = [*pose, *errs, *kcols, *idx, "error"]
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    u = _map_errors(m, force, moment)
    for i in range(len(m)):
        pos = [f"{v:.6g}" for v in _pose_cells(m.points[i]).values()]
        if m.valid[i]:
            Ki = m.K6[i] if six else m.K[i]
            rot = [m.min_principal_rot[i]] if six else []
            nums = [*u[i], *Ki.ravel(), m.det[i], m.min_principal[i], *rot, m.condition[i]]
            w.writerow(pos + [f"{v:.9g}" for v in nums] + [""])
        else:
            w.writerow(pos + [""] * (len(cols) - len(pose) - 1) + [m.reasons[i]])
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
    reader = csv.reader(lines, delimiter=sniff_delimiter(lines))
    try:
        for row in reader:
            if row and not row[0].lstrip().startswith("#"):
                return [h.strip().lower() for h in row]
    except csv.Error as e:  # a field longer than the csv module's limit (131072 characters)
        raise InputError(f"line {reader.line_num}: not a table of numbers ({e})", source=src) from None
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
        rad, or None when the robot has fewer than six compliant joints); at a joint singularity
        where the point still moves every way (a wrist singularity) also ``note`` (the reason),
        K given, K6 None (:meth:`SerialRobot.past_joint_singularity`); or ``q_deg``, ``error``
        (the reason, after ``FILE line L:`` when given) and,
        where the configuration has a point (a singular one), ``position``.
    """
    m = robot.evaluate_configurations(Q)
    six = robot.has_k6
    K6 = np.full((len(m), 6, 6), np.nan)
    if six and m.n_valid:
        K6[m.valid] = robot.stiffness6(m.q[m.valid])
    out = []
    for i in range(len(m)):
        rec: dict = {"q_deg": _q_display(robot, m.q[i])}
        where = " ".join(x for x in (source or "", "" if lines is None else f"line {int(lines[i])}") if x)
        reason = f"{where}: {m.reasons[i]}" if where else m.reasons[i]
        if m.valid[i]:
            rec["position"] = m.points[i].tolist()
            rec["K"] = m.K[i].tolist()
            rec["K6"] = K6[i].tolist() if six else None
        elif (past := _past_joint_singularity(robot, m, i)) is not None:
            rec["position"] = m.points[i].tolist()
            rec["K"], rec["K6"] = past.tolist(), None
            rec["note"] = f"{reason} (K given: the point still moves every way; K6 not)"
        else:
            if np.all(np.isfinite(m.points[i])):  # a singular configuration still has its point
                rec["position"] = m.points[i].tolist()
            rec["error"] = reason
        out.append(rec)
    return m, out


def _past_joint_singularity(robot: SerialRobot, m: ModelMap, i: int):
    """K of configuration i when the map flags it for a joint singularity only
    (:meth:`SerialRobot.past_joint_singularity`), else None."""
    if not m.reasons[i].startswith("singular: ") or not np.all(np.isfinite(m.points[i])):
        return None
    return robot.past_joint_singularity(m.q[i])
