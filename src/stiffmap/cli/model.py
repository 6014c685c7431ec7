"""``stiffmap model`` (a model's stiffness and static error per point) and ``stiffmap fit``.

Both take any robot kind of the registry (:mod:`stiffmap.kinds`: ``delta``, ``3prr``,
``urdf``, ``legs``...): its name, its description file when it has one (``urdf ROBOT.urdf``,
``legs ROBOT.toml``), ``--param NAME=VALUE`` and the kind's own options (``--tip`` ...),
turned into the model by :func:`stiffmap.kinds.robot_from_command`.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from ..errors import InputError
from ..io import atomic_write_text, dumps_json
from ..kinds import CONFIGS_OPTION, grid_from_text, kind_names, robot_from_command, robot_kind
from ..kinds.options import command_names
from ..loads import MAX_FORCE_N, MAX_MOMENT_NMM
from ..models.base import POSE_DIM
from ..models.chunked import CHUNK_POSES, evaluate_in_chunks
from ..models.io import configuration_file_records, fit_measurements_file, map_csv, map_records, read_points
from ..models.mobility import held_as_given, nearest_pose_note
from ..models.poses import orientations_from_text, poses_from
from ..models.presets import force_direction
from ..stiffness import stiffness_indices
from ..textfmt import fmt, fmt_pm
from .common import (
    EXIT_PARTIAL,
    fail,
    from_option,
    note,
    options_named,
    out,
    print_json,
    three_numbers,
    warn,
    work_progress,
)

_KINDS_HELP = (
    "The robot kind: "
    + ", ".join(kind_names())
    + " (docs/models.md). urdf and legs take their file (ROBOT) after it."
)
_TIP_HELP = "urdf: the link (frame) of the URDF that carries the measured point."
_OFFSET_HELP = "urdf: the measured point in the tip frame, X,Y,Z in mm (default 0,0,0)."
_CONFIGS_HELP = (
    "urdf: CSV of joint configurations, one row each, columns q1_deg..qn_deg in the URDF's joint "
    "order (qk_mm for a prismatic joint)."
)


_BASE_HELP = (
    "urdf: the link the measurements are expressed in, when it is not the URDF's root (a two-armed "
    "robot's torso, a mobile manipulator's arm base); the joints above it are held, not fitted."
)
_XACRO_ARG_HELP = "urdf: an argument NAME=VALUE of a .xacro description (repeatable)."
_PACKAGE_PATH_HELP = (
    "urdf: a folder where a .xacro description's $(find PKG) looks (repeatable; then "
    "ROS_PACKAGE_PATH, then the workspace the file lies in: its own package's siblings)."
)
_LINKS_HELP = (
    "urdf: TOML of flexible links (a links table per link: beam data or a 6x6 compliance, "
    "docs/models.md); their parameters E_<name>, G_<name>, f_<name> join the joints'."
)


def _robot(cmd: str, mechanism: str, robot, param, configs, options: dict):
    """The model of the command line's kind and options (InputError in the options' terms)."""
    given = {k: (v or None) if isinstance(v, list) else v for k, v in options.items()}
    return robot_from_command(mechanism, robot, param or [], given, configs=configs, command=cmd)


def _options(tip, tip_offset, base, xacro_arg, package_path, links) -> dict:
    """The kind-specific options of the command line, by their names."""
    return {
        "--tip": tip,
        "--tip-offset-mm": tip_offset,
        "--base": base,
        "--xacro-arg": xacro_arg,
        "--package-path": package_path,
        "--links": None if links is None else str(links),
    }


# The options of `model` (declared here so that the command's signature reads at once).
_OPT_MECHANISM = typer.Argument(..., metavar="KIND", help=_KINDS_HELP)
_OPT_ROBOT = typer.Argument(
    None,
    metavar="[ROBOT]",
    help="urdf: the robot's URDF file, or arm6 (stiffmap's six-joint test arm); legs: the TOML "
    "file describing a parallel robot's legs (docs/models.md). Required for those two only.",
)
_OPT_GRID = typer.Option(
    None,
    "--grid",
    help="Positions: a preset (paper48 for delta, points22 for 3prr: the defaults) or a regular "
    "grid 'X0:X1:NX,Y0:Y1:NY[,Z0:Z1:NZ]' (mm; a single value fixes an axis). A platform of lower "
    "mobility (a 3-RPS: z, roll, pitch) takes only grid poses it holds as given (x, y, yaw follow).",
)
_OPT_POINTS = typer.Option(
    None, "--points", help="CSV of positions with columns x,y (3prr) or x,y,z (delta), mm."
)
_OPT_LOAD_N = typer.Option(
    None, "--load-n", help="Force magnitude, N (default 490.5 for 3prr: 50 kgf; 4.905 for delta: 0.5 kg)."
)
_OPT_DIRECTION = typer.Option(
    None,
    "--direction",
    help="Force direction: x, y, z, -x, ... or comma-separated components (default y for 3prr, "
    "-z for delta).",
)
_OPT_PARAM = typer.Option(
    None,
    "--param",
    help="Model parameter NAME=VALUE (repeatable; see docs/models.md for the names). urdf: "
    "k1=K1,...,kn=Kn, the joint stiffnesses in N*mm/rad (N/mm for prismatic joints; required), "
    "or k_theta=K for every joint.",
)
_OPT_TIP = typer.Option(None, "--tip", help=_TIP_HELP)
_OPT_TIP_OFFSET = typer.Option(None, "--tip-offset-mm", help=_OFFSET_HELP)
_OPT_BASE = typer.Option(None, "--base", help=_BASE_HELP)
_OPT_XACRO_ARG = typer.Option(None, "--xacro-arg", help=_XACRO_ARG_HELP)
_OPT_PACKAGE_PATH = typer.Option(None, "--package-path", help=_PACKAGE_PATH_HELP)
_OPT_LINKS = typer.Option(None, "--links", help=_LINKS_HELP)
_OPT_CONFIGS = typer.Option(None, CONFIGS_OPTION, help=_CONFIGS_HELP)
_OPT_ORIENTATION = typer.Option(
    None,
    "--orientation",
    help="A platform that turns (a legs TOML with dim = 6): the platform's orientation at the "
    "--grid positions, ROLL,PITCH,YAW in degrees (default 0,0,0; R = Rz(yaw) Ry(pitch) Rx(roll)); "
    "each angle a value or START:STOP:N, e.g. -10:10:5,-10:10:5,0 maps 25 tilts of the tool.",
)
_OPT_MOMENT = typer.Option(
    None,
    "--moment-nmm",
    help="A platform that turns: a moment MX,MY,MZ (N*mm) at the tool point with the force; the "
    "static error is then the wrench's, the platform's translation u (mm) and rotation (rad).",
)
_OPT_AS_JSON = typer.Option(False, "--json", help="Print a JSON list, one object per point.")
_OPT_AS_CSV = typer.Option(
    False, "--csv", help="Print CSV, one row per point (delta, 3prr, legs; urdf prints --json)."
)
_OPT_OUTPUT = typer.Option(None, "--output", "-o", help="Write the JSON or CSV to this file instead.")


def model(
    mechanism: str = _OPT_MECHANISM,
    robot: Path = _OPT_ROBOT,
    grid: str = _OPT_GRID,
    points: Path = _OPT_POINTS,
    load_n: float = _OPT_LOAD_N,
    direction: str = _OPT_DIRECTION,
    param: list[str] = _OPT_PARAM,
    tip: str = _OPT_TIP,
    tip_offset: str = _OPT_TIP_OFFSET,
    base: str = _OPT_BASE,
    xacro_arg: list[str] = _OPT_XACRO_ARG,
    package_path: list[str] = _OPT_PACKAGE_PATH,
    links: Path = _OPT_LINKS,
    configs: Path = _OPT_CONFIGS,
    orientation: str = _OPT_ORIENTATION,
    moment: str = _OPT_MOMENT,
    as_json: bool = _OPT_AS_JSON,
    as_csv: bool = _OPT_AS_CSV,
    output: Path = _OPT_OUTPUT,
) -> None:
    """A model's stiffness K (N/mm) and static error u = K^-1 F (mm) at each position.

    Points that cannot be evaluated (outside the workspace, or at a singularity) are
    named with the reason, the others are printed; the exit status is then 1 (2 when no
    point can be evaluated).

    urdf (a serial robot): 'stiffmap model urdf ROBOT.urdf --tip FRAME --configs CONFIGS.csv
    --param k1=K1,...,kn=Kn' prints, per configuration, the measured point's position (mm,
    base frame) and K (N/mm, the stiffness a pure force sees); --json adds K6 (6x6). At a
    joint singularity alone (a wrist singularity: the point still moves every way) K is
    printed with the reason as a note, K6 is null, and the status stays 0.

    legs with a dim = 6 TOML (a hexapod, a 3-RPS: robots/hexapod.toml): points are poses,
    --points with x, y, z and roll_deg, pitch_deg, yaw_deg, or --grid positions at
    --orientation; K is what a pure force sees (the platform free to turn), K_rot a pure
    moment's (N*mm/rad); --json adds K6 (6x6 at the tool point, base frame) and K_rot.
    """
    kind = robot_kind_option(mechanism)
    _refuse_option_conflicts(kind, grid, points, load_n, direction, as_json, as_csv)
    own = _options(tip, tip_offset, base, xacro_arg, package_path, links)
    m = _robot("model", mechanism, robot, param, configs, own)
    six = m.dim == POSE_DIM
    _turning_only(six, kind.name, orientation, moment, points)
    if kind.configurations:
        _model_configurations(m, configs, as_json, output)
        return
    P = _positions(kind, m.dim, grid, points, orientation)
    if grid is not None and six:
        P = from_option("--grid:", _held_grid, m, P)
    F = _force(kind, 3 if six else m.dim, load_n, direction)
    M = None if moment is None else _moment(moment)
    mp = _evaluate(m, P)
    if as_json or as_csv:
        _write_map(mp, F, M, as_json, output)
    elif output is not None:
        raise InputError("--output needs --json or --csv")
    elif six:
        _print_map6(m, mp, F, M)
    else:
        _print_map(m, mp, F)
    nbad = len(mp) - mp.n_valid
    if six and nbad:
        _note_nearest(m, P, mp.valid)
    of = f"; points from {points}" if points is not None else ""
    if nbad == len(mp):
        raise fail(
            f"none of the {len(mp)} point(s) can be evaluated by the {kind.name} model (see 'error'){of}"
        )
    if nbad:
        warn(f"{nbad} of {len(mp)} point(s) cannot be evaluated (see 'error'){of}")
        raise typer.Exit(EXIT_PARTIAL)


def _held_grid(m, P: np.ndarray) -> np.ndarray:
    """``--grid`` poses a platform of lower mobility holds as given (:func:`held_as_given`), else
    its ValueError with how to give the poses it reaches."""
    try:
        return held_as_given(m, P)
    except ValueError as e:
        raise ValueError(
            f"{e}; give the poses it reaches, --points POSES.csv with x, y, z, roll_deg, pitch_deg, "
            "yaw_deg (models.mobility.reachable_poses solves them)"
        ) from None


def _note_nearest(m, P: np.ndarray, valid: np.ndarray) -> None:
    """A platform of lower mobility (a 3-RPS): the nearest pose it holds to the first it cannot."""
    i = int(np.flatnonzero(~np.asarray(valid))[0])
    text = nearest_pose_note(m, P[i])
    if text:
        note(f"pose {i + 1}: {text}")


def _refuse_option_conflicts(kind, grid, points, load_n, direction, as_json: bool, as_csv: bool) -> None:
    """Options that do not go together, or not with this kind (positions vs configurations)."""
    if kind.configurations:
        for opt, v in (
            ("--grid", grid),
            ("--points", points),
            ("--load-n", load_n),
            ("--direction", direction),
        ):
            if v is not None:
                raise InputError(
                    f"{opt} is for robots given by positions; {kind.name} evaluates the configurations "
                    f"of {CONFIGS_OPTION}"
                )
        if as_csv:
            raise InputError(f"--csv is for robots given by positions; {kind.name} prints --json")
    elif as_json and as_csv:
        raise InputError("--json and --csv are exclusive")
    elif grid is not None and points is not None:
        raise InputError("--grid and --points are exclusive")


def _positions(kind, dim: int, grid: str | None, points: Path | None, orientation=None) -> np.ndarray:
    """The positions of --points, --grid or the kind's default ones, shape (m, dim), mm; for a
    platform that turns (dim = 6) poses, --grid's positions at each --orientation."""
    if points is not None:
        return read_points(points, dim)
    if grid is not None and dim == POSE_DIM:
        at = from_option("--orientation", orientations_from_text, orientation or "0,0,0")
        P = from_option("--grid", grid_from_text, grid, kind.name, 3)
        return from_option("--grid with --orientation", poses_from, P, at)
    if grid is not None:
        return from_option("--grid", grid_from_text, grid, kind.name, dim)
    if kind.default_positions() is None:
        raise InputError(
            f"{kind.name}: give the positions, --points FILE.csv or --grid X0:X1:NX,Y0:Y1:NY[,Z0:Z1:NZ]"
        )
    return kind.default_positions()


def _evaluate(m, P: np.ndarray):
    """``m.evaluate(P)``, with progress on stderr over more than one chunk of poses
    (:func:`~stiffmap.cli.common.work_progress`: a bar on a terminal, else a line every 10 s)."""
    if len(P) <= CHUNK_POSES:
        return m.evaluate(P)
    with work_progress("poses", len(P)) as hook:
        return evaluate_in_chunks(m, P, hook, chunk=CHUNK_POSES)


def robot_kind_option(name: str):
    """The registry's kind of the KIND argument (InputError listing the kinds)."""
    with options_named({"kind": "KIND"}):
        return robot_kind(name)


def _model_configurations(robot, configs: Path, as_json: bool, output: Path | None) -> None:
    """A serial robot: position and stiffness per configuration; exit 1 or 2 when some fail."""
    mp, recs, lines = configuration_file_records(robot, configs)
    if as_json:
        if output is not None:
            atomic_write_text(output, dumps_json(recs) + "\n")
        else:
            print_json(recs)
    elif output is not None:
        raise InputError("--output needs --json")
    else:
        _print_configurations(robot, mp, recs, lines)
    noted = [r["note"] for r in recs if "note" in r]
    if noted:
        note(
            f"{len(noted)} of {len(recs)} configuration(s) at a joint singularity: K given, K6 not "
            f"(see 'note'); the first: {noted[0]}"
        )
    bad = [r["error"] for r in recs if "error" in r]
    if len(bad) == len(recs):
        if len(bad) == 1:
            raise fail(bad[0])
        raise fail(
            f"none of the {len(recs)} configuration(s) can be evaluated (see 'error'); the first: {bad[0]}"
        )
    if bad:
        warn(f"{len(bad)} of {len(recs)} configuration(s) of {configs} cannot be evaluated (see 'error')")
        raise typer.Exit(EXIT_PARTIAL)


def _print_configurations(robot, mp, recs, lines) -> None:
    out.print(robot.describe(), markup=False)  # '[leg1 (3 joints), ...]' is text
    out.print(
        "K: the stiffness a pure force at the measured point sees (N/mm, base frame); "
        "k_min <= k_mid <= k_max its principal stiffnesses; q in deg (mm for prismatic joints)"
    )
    t = Table()
    for c in ("#", "line", "q", "x (mm)", "y (mm)", "z (mm)", "k_min", "k_mid", "k_max"):
        t.add_column(c, justify="left" if c == "q" else "right")
    t.add_column("status")
    for i, r in enumerate(recs):
        q = ", ".join(fmt(v, 5) for v in r["q_deg"])
        head = [str(i + 1), str(int(lines[i])), q]
        if "error" in r:
            xyz = [fmt(_mm(v), 6) for v in r["position"]] if "position" in r else [""] * 3
            t.add_row(*head, *xyz, *([""] * 3), mp.reasons[i])
        elif "note" in r:  # a joint singularity: K, not the map's (it flags the configuration)
            w = stiffness_indices(r["K"]).eigenvalues
            xyz = (fmt(_mm(v), 6) for v in r["position"])
            t.add_row(*head, *xyz, *(fmt(v, 4) for v in w), "K only: " + mp.reasons[i])
        else:
            t.add_row(
                *head, *(fmt(_mm(v), 6) for v in mp.points[i]), *(fmt(v, 4) for v in mp.eigenvalues[i]), "ok"
            )
    out.print(t)


def _mm(v: float) -> float:
    """A position coordinate for the table: round-off below a nanometre shown as 0 (the JSON
    keeps every digit)."""
    return 0.0 if abs(v) < 1e-6 else v


def _force(kind, dim: int, load_n: float | None, direction: str | None) -> np.ndarray:
    """The force (N) of ``--load-n`` along ``--direction``, each defaulting to the kind's
    (10 N along -z, or y in the plane, for a kind without a default load)."""
    mag, dname = kind.default_load or (10.0, "-z" if dim == 3 else "y")
    if load_n is not None:
        if not np.isfinite(load_n):
            raise InputError(f"--load-n must be a finite number of N, got {load_n}")
        if abs(load_n) > MAX_FORCE_N:
            raise InputError(f"--load-n {load_n:g} N is beyond +-{MAX_FORCE_N:g} N: not a plausible load")
        mag = load_n
    return mag * from_option(
        "--direction", force_direction, direction if direction is not None else dname, dim
    )


def _turning_only(six: bool, kind: str, orientation, moment, points) -> None:
    """Refuse ``--orientation`` and ``--moment-nmm`` for a platform that only translates, and
    ``--orientation`` with ``--points`` (the file's poses give their orientations)."""
    if not six:
        for opt, v in (("--orientation", orientation), ("--moment-nmm", moment)):
            if v is not None:
                raise InputError(f"{opt} is for a platform that turns (a legs TOML with dim = 6), not {kind}")
    elif orientation is not None and points is not None:
        raise InputError(
            "--orientation goes with --grid; the poses of --points give their own (columns roll_deg, "
            "pitch_deg, yaw_deg)"
        )


def _moment(text: str) -> np.ndarray:
    """``--moment-nmm MX,MY,MZ`` (N*mm)."""
    M = three_numbers(text)
    if M is None or not all(np.isfinite(M)):
        raise InputError(f"--moment-nmm: expected MX,MY,MZ in N*mm (three numbers), got {text!r}")
    if max(abs(v) for v in M) > MAX_MOMENT_NMM:
        raise InputError(f"--moment-nmm {text}: beyond +-{MAX_MOMENT_NMM:g} N*mm, not a plausible load")
    return np.array(M, dtype=float)


def _write_map(mp, F: np.ndarray, M, as_json: bool, output: Path | None) -> None:
    """The map as JSON or CSV, on stdout or into ``output``."""
    text = dumps_json(map_records(mp, F, M)) + "\n" if as_json else map_csv(mp, F, M)
    if output is not None:
        atomic_write_text(output, text)
    elif as_json:
        print_json(map_records(mp, F, M))
    else:
        sys.stdout.write(text)
        sys.stdout.flush()


def _print_map(m, mp, F) -> None:
    dim = m.dim
    ax = "xyz"[:dim]
    out.print(m.describe(), markup=False)  # '[leg1 (3 joints), ...]' is text
    out.print(
        f"force F = ({', '.join(fmt(v, 5) for v in F)}) N; static error u = K^-1 F (mm); "
        "det K in (N/mm)^" + str(dim) + "; k_min: smallest principal stiffness"
    )
    t = Table()
    t.add_column("#", justify="right")
    for a in ax:
        t.add_column(f"{a} (mm)", justify="right")
    for a in ax:
        t.add_column(f"u{a} (mm)", justify="right")
    t.add_column("det K", justify="right")
    t.add_column("k_min (N/mm)", justify="right")
    t.add_column("status")
    uu = mp.static_error(F)
    for i in range(len(mp)):
        pos = [fmt(v, 6) for v in mp.points[i]]
        if mp.valid[i]:
            t.add_row(
                str(i + 1),
                *pos,
                *(f"{v + 0.0:.4f}" if abs(v) >= 5e-5 else "0.0000" for v in uu[i]),
                fmt(mp.det[i], 4),
                fmt(mp.min_principal[i], 4),
                "ok",
            )
        else:
            t.add_row(str(i + 1), *pos, *([""] * (dim + 2)), mp.reasons[i])
    out.print(t)
    if mp.n_valid:
        v = mp.valid
        out.print(
            f"{mp.n_valid} point(s): |u| {fmt(np.min(np.linalg.norm(uu[v], axis=1)), 4)} to "
            f"{fmt(np.max(np.linalg.norm(uu[v], axis=1)), 4)} mm; det K {fmt(np.min(mp.det[v]), 4)} to "
            f"{fmt(np.max(mp.det[v]), 4)}"
        )


def _print_map6(m, mp, F, M) -> None:
    """The map of a platform that turns: pose, the wrench's static error, K's and K_rot's softest."""
    out.print(m.describe(), markup=False)  # '[leg1 (3 joints), ...]' is text
    w = np.concatenate([F, np.zeros(3) if M is None else M])
    out.print(
        f"wrench at the tool point F = ({', '.join(fmt(v, 5) for v in w[:3])}) N, M = "
        f"({', '.join(fmt(v, 5) for v in w[3:])}) N*mm; static error: translation u (mm) and rotation "
        "(mrad) = K6^-1 w; k_min: smallest principal stiffness of K (a pure force's, N/mm), "
        "kr_min: of K_rot (a pure moment's, N*mm/rad)"
    )
    t = Table()
    for c in ("#", "x (mm)", "y (mm)", "z (mm)", "roll", "pitch", "yaw (deg)", "ux", "uy", "uz (mm)"):
        t.add_column(c, justify="right")
    for c in ("rx", "ry", "rz (mrad)", "k_min", "kr_min"):
        t.add_column(c, justify="right")
    t.add_column("status")
    d = mp.static_error6(w)
    for i in range(len(mp)):
        p = mp.points[i]
        pose = [fmt(v, 6) for v in p[:3]] + [fmt(float(np.degrees(v)), 5) for v in p[3:]]
        if mp.valid[i]:
            u = [f"{v + 0.0:.4f}" if abs(v) >= 5e-5 else "0.0000" for v in d[i, :3]]
            r = [f"{1e3 * v + 0.0:.4f}" if abs(v) >= 5e-8 else "0.0000" for v in d[i, 3:]]
            k = [fmt(mp.min_principal[i], 4), fmt(mp.min_principal_rot[i], 4)]
            t.add_row(str(i + 1), *pose, *u, *r, *k, "ok")
        else:
            t.add_row(str(i + 1), *pose, *([""] * 8), mp.reasons[i])
    out.print(t)
    if mp.n_valid:
        v = mp.valid
        un = np.linalg.norm(d[v, :3], axis=1)
        k, kr = mp.min_principal[v], mp.min_principal_rot[v]
        out.print(
            f"{mp.n_valid} pose(s): |u| {fmt(un.min(), 4)} to {fmt(un.max(), 4)} mm; k_min {fmt(k.min(), 4)} "
            f"to {fmt(k.max(), 4)} N/mm; kr_min {fmt(kr.min(), 4)} to {fmt(kr.max(), 4)} N*mm/rad"
        )


def fit(
    mechanism: str = typer.Argument(..., metavar="KIND", help=_KINDS_HELP),
    files: list[Path] = typer.Argument(
        ...,
        metavar="[ROBOT] MEASUREMENTS",
        help="urdf, legs: the robot's file, then the measurements; delta, 3prr: the measurements. "
        "MEASUREMENTS: CSV of static errors (x,y[,z], fx,fy[,fz], [nx,ny[,nz],] value_mm[, std_mm]) or "
        "of stiffness matrices (x,y[,z], k11..kdd[, k11_std..]); see docs/models.md.",
    ),
    param_to_fit: list[str] = typer.Option(
        None,
        "--param-to-fit",
        help="Parameter to estimate (repeatable; default kj for 3prr, k_theta for delta, every joint "
        "k1..kn for urdf, every stiffness for legs).",
    ),
    param: list[str] = typer.Option(
        None,
        "--param",
        help="Fixed model parameter or starting value NAME=VALUE (repeatable; a fitted "
        "parameter's value is only where the fit starts, docs/models.md 'Fitting'). urdf: "
        "k1=K1,...,kn=Kn (required; N*mm/rad, N/mm for prismatic joints) or k_theta=K for all.",
    ),
    tip: str = _OPT_TIP,
    tip_offset: str = _OPT_TIP_OFFSET,
    base: str = _OPT_BASE,
    xacro_arg: list[str] = _OPT_XACRO_ARG,
    package_path: list[str] = _OPT_PACKAGE_PATH,
    links: Path = _OPT_LINKS,
    configs: Path = typer.Option(
        None,
        CONFIGS_OPTION,
        help=_CONFIGS_HELP + " The measurements' positions are matched to their measured points.",
    ),
    absolute_sigma: bool = typer.Option(
        False,
        "--absolute-sigma",
        help="Take the files' standard errors as exact (default: scale by the reduced chi-square).",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Fit model parameters to measured static errors or stiffness matrices (least squares).

    Prints each estimate with its standard error, the fit's condition, chi-square and the
    residual RMS per pose. Refuses parameters the data cannot determine; warns (exit 1) of
    those whose standard error exceeds their value, with those they are correlated with.

    urdf: 'stiffmap fit urdf ROBOT.urdf MEASUREMENTS --tip FRAME --configs CONFIGS.csv --param
    k1=K1,...,kn=Kn [--param-to-fit k1 ...]' fits joint stiffnesses; each measured position is
    one of the configurations' measured points (or solved by inverse kinematics).
    """
    kind = robot_kind_option(mechanism)
    if kind.file:
        if len(files) != 2:
            raise InputError(
                f"{kind.name} takes two files, the robot's {kind.file} then the measurements: stiffmap fit "
                f"{kind.name} {kind.file_example} MEASUREMENTS ..."
            )
        robot_file, measurements = files
    else:
        if len(files) != 1:
            raise InputError(
                f"{kind.name} takes one file, the measurements; a robot file is only for kinds described "
                f"by one ('stiffmap fit urdf ROBOT.urdf MEASUREMENTS'; got {', '.join(map(str, files))})"
            )
        robot_file, (measurements,) = None, files
    own = _options(tip, tip_offset, base, xacro_arg, package_path, links)
    m = _robot("fit", mechanism, robot_file, param, configs, own)
    with options_named(command_names(kind)):
        names = kind.fitted_names(m, param_to_fit)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        f, _ = fit_measurements_file(m, measurements, names, absolute_sigma=absolute_sigma)
    for w in caught:
        warn(str(w.message))
    _report_fit(f, kind.name, measurements, m.dim, as_json)


def _report_fit(f, mech: str, measurements: Path, dim: int, as_json: bool) -> None:
    """The fit as JSON or tables, then its warnings (with --json too: the exit status says there
    is something to look at) and notes."""
    if as_json:
        print_json({**f.to_dict(), "file": str(measurements)})
    else:
        _print_fit(f, mech, measurements, dim)
    for n in f.notes:
        warn(f"{measurements}: {n}")
    for n in f.info:
        note(n)


def _print_fit(f, mech: str, measurements: Path, dim: int) -> None:
    """The estimates, the fit's quality and the residual RMS per pose."""
    unit = {"static_error": "mm", "stiffness6": "N/mm, N, N*mm/rad: K6's entries"}.get(f.kind, "N/mm")
    what = "static-error readings" if f.kind == "static_error" else "stiffness entries"
    line = f"{mech}: {f.observed.size} {what} at {f.poses.shape[0]} pose(s) from {measurements}"
    out.print(line, markup=False)
    t = Table("parameter", "initial", "estimate ± standard error", "relative")
    for k, e, s, i in zip(f.names, f.estimate, f.std, f.initial, strict=True):
        t.add_row(k, fmt(i), fmt_pm(e, s), f"{100 * s / e:.2g} %" if e else "")
    out.print(t)
    s = Table(show_header=False, box=None)
    s.add_row("dof", str(f.dof))
    s.add_row("chi2 / dof", fmt(f.reduced_chi2, 4) + ("" if f.absolute_sigma else " (std scaled by it)"))
    s.add_row("condition", fmt(f.condition, 3))
    if len(f.names) > 1:
        for a in range(len(f.names)):
            for b in range(a + 1, len(f.names)):
                s.add_row(f"corr({f.names[a]}, {f.names[b]})", fmt(f.correlation[a, b], 3))
    out.print(s)
    r = Table(title=f"residual RMS per pose ({unit})")
    for a in "xyz"[: min(dim, 3)]:
        r.add_column(f"{a} (mm)", justify="right")
    if dim == POSE_DIM:  # a platform that turns: the poses' orientations
        for a in ("roll", "pitch", "yaw"):
            r.add_column(f"{a} (deg)", justify="right")
    r.add_column("RMS", justify="right")
    for p, v in zip(f.poses, f.residual_rms_per_pose, strict=True):
        cells = [*p[:3], *np.degrees(p[3:])]
        r.add_row(*(fmt(float(x), 6) for x in cells), fmt(v, 3))
    out.print(r)


def register(app: typer.Typer) -> None:
    app.command("model")(model)
    app.command("fit")(fit)
