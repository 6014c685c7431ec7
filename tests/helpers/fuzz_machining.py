"""Fuzz classes of ``stiffmap compensate`` (issue 31): G-code programs, CSVs of points, force files,
the command's options, the six-joint arm's options and ``--from-campaign`` folders.

Every class starts from valid inputs a shop would feed the command: the G-code fixtures of
``tests/data/gcode`` (a Fanuc-style CAM program with line numbers, an O-word line, G28 G91, IJK
and R arcs and a G91 section; an inch program of R arcs in G17, G18 and G19 in lower case
without spaces; a CRLF program of line numbers, G20 and four IJK quarter arcs), a CSV of
points around a square, and the force file of a program's feed moves. The robots are cheap:
the milling study's 3PRR with its paper parameters (``stiffmap compensate 3prr``, placed at
380, 200 mm) and the Delta (placed at -40, -30, -300 mm); for the arm's options, ``urdf arm6``
placed at 480, -30, 380 mm; for ``--from-campaign``, a measured test-bed campaign (the sensor
seed of ``helpers.fuzz_safety``: the 3PRR with its fitted kj, and the vision seed's Delta).

Then one thing is made wrong: the generic mutations of :mod:`helpers.fuzz` (truncation, byte
corruption, extreme and non-finite numbers, UTF-16, empty...) and, per format, what a program
can hold that cannot be compensated or that is degenerate (O-words, ``#``, ``[]``, G41/G42, G93,
canned cycles, repeated or unknown words, zero-length moves, zero-radius and impossible R arcs,
full circles, enormous arcs, 1e300, NaN, -0, binary garbage); the arm's options given values a
user may give (some out of reach) or wrong ones; a campaign folder damaged (its database missing,
corrupted, another program's, a link out; its fit failed, missing or edited; no model).

Every case checks more than the exit status (:func:`check_compensation`, the case's ``check``):
the input files are unchanged (bytes) after the run; on an exit of 2 or more, no output and no
temporary file is left; on a run that gives results (exit 0 or 1), the corrected program is
re-checked by the independent solvers of :mod:`helpers.machining_checks`: deflected under the
force, it lies on the programmed path within the tolerance and covers all of it (the arm by
``arm_deflection``: its own inverse kinematics and central-difference Jacobians, the tool held as
the options say; a campaign's 3PRR by the truss with the parameters of its campaign.toml and its
fit, read here with tomllib and sqlite3). A failing check makes the outcome ``wrong``.

:data:`FUZZ_CLASSES` lists them for ``tests/test_fuzz_machining.py`` and
``benchmarks/bench_fuzz.py``.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import functools
import io
import json
import math
import re
import sqlite3
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from helpers.fuzz import EXTREME_NUMBERS, FuzzCase, FuzzClass, Outcome, mutated_bytes, mutated_text
from helpers.fuzz_safety import measured_seed
from helpers.machining_checks import (
    arm_deflection,
    delta_deflection,
    distance_to_path,
    output_samples,
    truss_3prr,
)
from stiffmap.geometry import matrix_from_euler
from stiffmap.kinds import robot_from_command
from stiffmap.machining.io import read_program
from stiffmap.machining.path import toolpath_from_moves, toolpath_from_points
from stiffmap.models import PRR3, DeltaRobot

__all__ = ["FUZZ_CLASSES", "check_compensation", "compensate_case", "PROGRAMS", "campaign_files", "edited_db"]

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
#: The seed programs (fixtures of tests/data/gcode, README.md there for their source).
PROGRAMS = ("own_cam_mm.nc", "own_inch_r_planes.nc", "cncjs_circle-inch.gcode")
#: Where each robot takes the program's origin, and a force it cuts with (N, base frame).
PLACES = {"3prr": "380,200", "delta": "-40,-30,-300", "urdf arm6": "480,-30,380"}
FORCES = {"3prr": "0,-490.5", "delta": "4,3,-2", "urdf arm6": "20,-15,10"}
FEED_FORCES = {"3prr": "300,200", "delta": "4,3,1"}
#: Runs deflected by more than this (a force of 1e3 N on the Delta, 1e5 N on the 3PRR: far beyond
#: what a linear stiffness model describes) are not re-checked: the oracle's fixed-point landing of
#: a piece on its move is not trusted there (it found a Delta output under 1000 N, deflected by
#: 151 mm, 221 mm off; stiffmap claimed 0.7 um).
MAX_CHECKED_DEFLECTION_MM = 10.0
#: Files a successful run may write beside the inputs (OUT and its figures).
OUT = "o.nc"


def compensate_case(
    files: dict[str, bytes],
    robot: str,
    path: str,
    *options: str,
    blamed: str | None = None,
    note: str = "",
    out: str = OUT,
    expect: str | None = None,
    must_refuse: bool = False,
) -> FuzzCase:
    """``stiffmap compensate ROBOT --path {dir}/PATH --out {dir}/OUT --json -q --no-figures OPTIONS``
    (ROBOT: the words before --path: ``3prr``, ``urdf arm6``, ``--from-campaign {dir}/c``),
    its outcome re-checked by :func:`check_compensation`; ``expect``: what an error or warning must
    say when the run gives results (``FuzzCase.expect``); ``must_refuse``: a value no run may take
    (``FuzzCase.must_refuse``: a run that takes it is ``late``)."""
    argv = (
        "compensate",
        *robot.split(),
        "--path",
        f"{{dir}}/{path}",
        "--out",
        f"{{dir}}/{out}",
        "--json",
        "-q",
    )
    if "--figures" not in options:
        argv += ("--no-figures",)
    argv += tuple(o for o in options if o != "--figures")
    case = FuzzCase(files=files, argv=argv, blamed=blamed, note=note, expect=expect, must_refuse=must_refuse)
    return FuzzCase(
        files=files,
        argv=argv,
        blamed=blamed,
        note=note,
        expect=expect,
        must_refuse=must_refuse,
        check=functools.partial(check_compensation, case),
    )


# ------------------------------------------------------------------------------ the oracle
def _option(argv, name: str) -> str | None:
    return argv[argv.index(name) + 1] if name in argv else None


def check_compensation(case: FuzzCase, directory: Path, o: Outcome) -> str:
    """What is wrong with what a run left in ``directory`` ("" when nothing): an input changed,
    an output or a temporary file left by a failed run, or an output the independent solvers
    find off the programmed path or short of it."""
    for name, data in case.files.items():
        p = directory / name
        if not p.is_file() or p.read_bytes() != data:
            return f"the input {name} changed"
    argv = [a.replace("{dir}", str(directory)) for a in case.argv]
    out = Path(_option(argv, "--out"))
    extra = sorted(
        p.relative_to(directory).as_posix()
        for p in directory.rglob("*")
        if p.is_file()
        and p.relative_to(directory).as_posix() not in case.files
        and not _linked(p, directory)
        and not p.name.endswith(_SQLITE_COMPANIONS)
    )
    if o.code not in (0, 1):
        return f"exit {o.code} left {', '.join(extra)}" if extra else ""
    rel = (
        out.resolve().relative_to(directory.resolve()).as_posix()
        if out.is_relative_to(directory)
        else out.name
    )
    allowed = {rel + s for s in ("", ".deflection.png", ".html", ".spin.csv")}
    stray = [e for e in extra if e not in allowed]
    if stray:
        return f"temporary or unexpected files left: {', '.join(stray)}"
    if not out.is_file():
        return "" if o.code == 1 and not o.stdout.strip() else "exit 0 but no output written"
    try:
        return _off_path(argv, out, o)
    except _Unchecked:
        return ""


#: What SQLite leaves beside a database in WAL mode that a connection read (stiffmap.db-wal and
#: -shm: a read-only connection cannot remove them; the database itself is unchanged, checked above).
_SQLITE_COMPANIONS = (".db-wal", ".db-shm")


def _linked(p: Path, directory: Path) -> bool:
    """Whether p is, or is reached through, a symbolic link of the case (``FuzzCase.links``)."""
    return any(q.is_symlink() for q in (p, *p.parents) if q != directory and q.is_relative_to(directory))


class _Unchecked(Exception):
    """The run cannot be re-checked (a force file this check cannot read): not a finding."""


def _solver(argv, lead_in=None):
    """The robot of a command line for :func:`_deflection`: "3prr" or "delta" (their paper and
    default parameters), or a solver of the arm (:func:`_arm_solver`, ``lead_in`` its programmed
    points before the first cut) or of a campaign's fitted 3PRR (its parameters read here from
    campaign.toml and stiffmap.db: :func:`_campaign_params`)."""
    if argv[1] == "--from-campaign":
        return functools.partial(_truss, _campaign_params(Path(argv[2])))
    if argv[1] == "urdf":
        return _arm_solver(argv, lead_in)
    return argv[1]


def _truss(params: dict, X: np.ndarray, F: np.ndarray) -> np.ndarray:
    d = np.zeros_like(X)
    m = params
    d[:, :2] = truss_3prr(
        X[:, :2], F[:, :2], h=m["h"], L=m["L"], EA=m["E"] * m["area"], kj=m["kj"], kb=m["kb"]
    )
    return d


def _campaign_params(root: Path) -> dict:
    """A 3PRR campaign's parameters: the paper's, campaign.toml's [robot] params, then the model
    fit's (the first that succeeded, stiffness then static_error), read with tomllib and sqlite3."""
    try:
        spec = tomllib.loads((root / "campaign.toml").read_text(encoding="utf-8"))
        if spec["robot"]["model"] != "3prr":
            raise _Unchecked("not a 3PRR campaign")
        params = {**PRR3().params(), **spec["robot"].get("params", {})}
        with contextlib.closing(sqlite3.connect(f"file:{root / 'stiffmap.db'}?mode=ro", uri=True)) as c:
            rows = dict(c.execute("SELECT name, params FROM model_fit WHERE status = 'ok'").fetchall())
        fit = next(json.loads(rows[n]) for n in ("stiffness", "static_error") if n in rows)
        params = {**params, **{k: float(v) for k, v in fit.items()}}
    except (
        OSError,
        KeyError,
        TypeError,
        ValueError,
        StopIteration,
        sqlite3.Error,
        tomllib.TOMLDecodeError,
    ) as e:
        raise _Unchecked(f"the campaign's parameters: {e}") from None
    if not all(1e-6 < float(params[k]) < 1e12 for k in ("kj", "kb", "E", "area")):
        # the truss's direct solve loses every digit with a spring of 1e308 N/mm beside one of 1e3
        raise _Unchecked("a stiffness the check's direct solve cannot resolve")
    return params


def _arm_solver(argv, lead_in=None):
    """The arm of ``compensate urdf arm6 OPTIONS`` (built as the command builds it), deflected by
    :func:`helpers.machining_checks.arm_deflection` (its own inverse kinematics in order from the
    seed, central-difference Jacobians) holding the tool orientation of --tool-rpy-deg (else the
    arm's). ``lead_in``: the program's points (base frame, mm) before its first cut, the arm walked
    through them from the seed first (the cut then starts on the branch the program reaches it on,
    not the one the seed gives there: it may put a joint beyond its limits). A run that chose the
    tool's spin is not re-checked (the spins between the knots)."""
    if "--free-tool-spin" in argv:
        raise _Unchecked("the tool spin chosen along the path")
    params = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--param"]
    options = {"--tip": _option(argv, "--tip"), "--tip-offset-mm": _option(argv, "--tip-offset-mm")}
    robot = robot_from_command(
        "urdf", argv[2], params, options, command="compensate", builtin_defaults=True, configs_required=False
    )
    seed, rpy = _option(argv, "--q-seed-deg"), _option(argv, "--tool-rpy-deg")
    q0 = np.radians([float(v) for v in seed.split(",")]) if seed else robot.q_seed
    if rpy:
        R = matrix_from_euler(np.radians([float(v) for v in rpy.split(",")]))
    else:
        R = robot.tool_rotation if robot.tool_rotation is not None else robot.chain.forward(q0)[1]

    if lead_in is not None and len(lead_in):
        try:
            q0 = arm_deflection(robot.chain, robot.k_theta, R, lead_in, np.zeros_like(lead_in), q0)[1]
        except AssertionError as e:  # a rapid's point the check's inverse kinematics does not reach
            raise _Unchecked(str(e)) from None

    def solve(X, F):
        return arm_deflection(robot.chain, robot.k_theta, R, X, F, q0)[0]

    return solve


def _off_path(argv, out: Path, o: Outcome) -> str:
    """The independent re-check of a written program (module docstring)."""
    src = Path(_option(argv, "--path"))
    summary = json.loads(o.stdout)
    if summary["deflection_before_um"]["worst"] > MAX_CHECKED_DEFLECTION_MM * 1e3:
        raise _Unchecked("a deflection beyond the small deflections the oracle's landing follows")
    place = np.asarray(summary["place_mm"], dtype=float)
    tol_mm = float(_option(argv, "--tolerance-um") or 1.0) * 1e-3
    if src.suffix.lower() == ".csv":
        P, F = _points(src)
        prog = toolpath_from_points(P)
        done = toolpath_from_points(_points(out)[0])
        forces = _per_point(F) if F is not None else None
    else:
        prog = toolpath_from_moves(read_program(src)[0].moves)
        done = toolpath_from_moves(read_program(out)[0].moves)
        forces = _per_move_file(argv, prog)
    force = forces or _force_of_options(argv)
    robot = _solver(argv, _lead_in(prog) + place)
    L = float(np.sum(prog.length()[prog.feed])) if np.any(prog.feed) else 0.0
    if not np.any(prog.feed) or L == 0:
        return ""
    per_mm = min(2.0, 4000.0 / L)
    if not np.any(done.feed):
        return "the output has no feed move"
    dm, ds, C = output_samples(done, per_mm=per_mm)
    pm, ps, P = output_samples(prog, per_mm=min(20.0, 20000.0 / L))
    D = _deflected(robot, prog, dm, ds, C, place, pm, ps, P, force, tol_mm, ~done.is_arc[np.unique(dm)])
    far = distance_to_path(prog, D) if len(D) else np.zeros(0)
    slack = tol_mm * 1e-6 + 1e-9
    if far.size and np.max(far) > tol_mm + slack:
        i = int(np.argmax(far))
        off, tol = 1e3 * far[i], 1e3 * tol_mm
        return f"a deflected point of the output is {off:.3f} um off the path (tolerance {tol:g} um)"
    _, _, Q = output_samples(prog, per_mm=per_mm)
    gap = _to_polyline(Q, D, dm)
    if np.max(gap) > tol_mm + 0.01:  # 10 um: the chords between the samples of an arc
        return f"the output misses part of the programmed path ({np.max(gap):.3f} mm from it)"
    return ""


def _lead_in(prog) -> np.ndarray:
    """The programmed points (program frame, mm) before the first feed move, in order: each move's
    start and end where the program knows them (not after G28), the first cut's start last."""
    first = int(np.argmax(prog.feed)) if np.any(prog.feed) else len(prog)
    pts = []
    for i in range(min(first + 1, len(prog))):
        if np.all(prog.known_start[i]):
            pts.append(prog.start[i])
        if i < first and np.all(prog.known[i]):
            pts.append(prog.end[i])
    return np.array(pts, dtype=float).reshape(-1, 3)


def _to_polyline(Q: np.ndarray, D: np.ndarray, dm: np.ndarray) -> np.ndarray:
    """For each row of Q, the distance to the nearest chord between consecutive points of D that
    belong to the same output move (``dm``): how far the deflected output passes from it."""
    same = dm[1:] == dm[:-1]
    A, B = D[:-1][same], D[1:][same]
    if not len(A):
        A = B = D
    out = np.empty(len(Q))
    AB = B - A
    L2 = np.maximum(np.einsum("ij,ij->i", AB, AB), 1e-300)
    for k in range(0, len(Q), 256):
        q = Q[k : k + 256, None, :]
        t = np.clip(np.einsum("nij,ij->ni", q - A[None], AB) / L2, 0.0, 1.0)
        out[k : k + 256] = np.min(np.linalg.norm(q - (A[None] + t[..., None] * AB[None]), axis=2), axis=1)
    return out


def _project(prog, m, s0, h, X) -> np.ndarray:
    """The parameter s in [s0 - h, s0 + h] (clipped to [0, 1]) of the point of moves m nearest X
    (a ternary search: the distance is unimodal over so short a stretch)."""
    lo, hi = np.clip(s0 - h, 0.0, 1.0), np.clip(s0 + h, 0.0, 1.0)
    for _ in range(25):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        fa = np.linalg.norm(prog.point(m, a) - X, axis=1)
        fb = np.linalg.norm(prog.point(m, b) - X, axis=1)
        lo, hi = np.where(fa < fb, lo, a), np.where(fa < fb, b, hi)
    return 0.5 * (lo + hi)


def _landing(robot, prog, C, place, m, P, pm, ps, force, s_out):
    """Output points C (N, 3) deflected under the force of moves m (N,) where they land on them (the
    force varies along an arc: fixed-point iteration from the nearest programmed sample); on a
    move of no length (a point where the force changes) at the output's own parameter ``s_out``."""
    still = prog.length()[m] == 0
    h = np.array([1.0 / max(np.count_nonzero(pm == v) - 1, 1) for v in m])
    X = C
    for _ in range(4):
        k = np.empty(len(C), dtype=int)
        for a in range(0, len(C), 256):
            d = np.linalg.norm(X[a : a + 256, None, :] - P[None, :, :], axis=2)
            d[pm[None, :] != m[a : a + 256, None]] = np.inf
            k[a : a + 256] = np.argmin(d, axis=1)
        Fk = force(prog, m, np.where(still, s_out, _project(prog, m, ps[k], h, X)))
        X = C + _deflection(robot, C + place, Fk)
    return X, Fk


def _deflected(robot: str, prog, dm, ds, C, place, pm, ps, P, force, tol_mm: float, straight) -> np.ndarray:
    """The output's points deflected under the force, one output move at a time: the output's
    pieces of a programmed move m carry m's force (of the programmed moves near all of the piece's
    points, the one it lands on best); a short move the compensation adds at a corner where the
    force changes must start and end at the corner under the two moves' forces (how the force
    turns between them is not known: its points are taken at the corner)."""
    feed = np.unique(pm)
    starts = np.flatnonzero(np.r_[True, dm[1:] != dm[:-1]])
    far = np.stack([np.maximum.reduceat(prog.distance(np.full(len(C), m), C), starts) for m in feed], axis=1)
    # (output moves, feed moves): the moves within 3 mm and twice the deflection under the largest
    # force of the nearest one (a deflection of centimetres puts a piece nearer another move)
    FP = force(prog, pm, ps)
    Fmax = np.tile(FP[np.argmax(np.linalg.norm(FP, axis=1))], (starts.size, 1))
    reach = 3.0 + 2.0 * np.linalg.norm(_deflection(robot, C[starts] + place, Fmax), axis=1)
    reach = np.nan_to_num(reach, nan=np.inf)  # out of the model's reach: every move
    cand = far <= far.min(axis=1, keepdims=True) + reach[:, None]
    sizes = np.diff(np.r_[starts, len(C)])
    piece = np.repeat(np.arange(starts.size), sizes)
    rows, mi = np.nonzero(cand[piece])
    X, F = _landing(robot, prog, C[rows], place, feed[mi], P, pm, ps, force, ds[rows])
    err = prog.distance(feed[mi], X)
    worst = np.zeros(cand.shape)
    np.maximum.at(worst, (piece[rows], mi), err)
    worst[~cand] = np.inf
    choice = np.argmin(worst, axis=1)
    pick = mi == choice[piece[rows]]
    D = C.copy()
    D[rows[pick]] = X[pick]
    for k in np.flatnonzero(worst[np.arange(starts.size), choice] > tol_mm):
        D[piece == k] = _corner(
            robot, prog, C, place, piece, rows, mi, F, k, feed, worst, tol_mm, ds, D, straight
        )
    return D


def _corner(robot, prog, C, place, piece, rows, mi, F, k, feed, worst, tol_mm, ds, D, straight):
    """The points of output move k if it is a short move at a corner (see :func:`_deflected`)."""
    mine = piece[rows] == k
    r, js, Fk = rows[mine], mi[mine], F[mine]
    first, last = r.min(), r.max()
    best, out = worst[k].min(), D[piece == k]
    for ja in np.unique(js):
        for jb in np.unique(js):
            Fa = Fk[(js == ja) & (r == first)][0]
            Fb = Fk[(js == jb) & (r == last)][0]
            ends = C[[first, last]] + _deflection(robot, C[[first, last]] + place, np.stack([Fa, Fb]))
            e = np.minimum(
                prog.distance(np.full(2, feed[ja]), ends), prog.distance(np.full(2, feed[jb]), ends)
            ).max()
            corner = np.linalg.norm(ends[1] - ends[0]) <= 2 * tol_mm + 1e-9 and straight[k]
            if corner and e < best:  # its ends at the corner; between them the force is not known
                best = e
                out = ends[0] + ds[piece == k, None] * (ends[1] - ends[0])
    return out


def _deflection(robot, X: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Tool deflections (N, 3) mm at base-frame points X under forces F, by the independent solvers
    (``robot``: "3prr", "delta", or a solver ``f(X, F)`` of its own: :func:`_solver`)."""
    if callable(robot):
        return robot(X, F)
    d = np.zeros_like(X)
    if robot == "3prr":
        m = PRR3().params()
        d[:, :2] = truss_3prr(
            X[:, :2], F[:, :2], h=m["h"], L=m["L"], EA=m["E"] * m["area"], kj=m["kj"], kb=m["kb"]
        )
    else:
        d = delta_deflection(DeltaRobot(), X, F)
    return d


def _force_of_options(argv):
    """The force of --force-n (base frame) or --force-feed-n (the feed's frame), per sample."""
    base, feed = _option(argv, "--force-n"), _option(argv, "--force-feed-n")
    if base is None and feed is None:
        raise _Unchecked("no force this check can read (force columns it does not find)")
    v = np.array([float(x) for x in (base or feed).split(",")] + [0.0])[:3]

    def at(prog, m, s):
        if base is not None:
            return np.tile(v, (len(m), 1))
        h = 1e-6
        t = prog.point(m, np.minimum(s + h, 1.0)) - prog.point(m, np.maximum(s - h, 0.0))
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        hz = t.copy()
        hz[:, 2] = 0.0
        across = np.column_stack([-hz[:, 1], hz[:, 0], np.zeros(len(m))])
        return v[0] * hz + v[1] * across + np.outer(np.ones(len(m)), [0.0, 0.0, v[2]])

    return at


def _per_move_file(argv, prog):
    """The force file's rows (read here with the csv module) as the force of each feed move."""
    name = _option(argv, "--force-file")
    if name is None:
        return None
    try:
        rows = list(csv.DictReader(io.StringIO(Path(name).read_text(encoding="utf-8-sig"))))
        F = np.array([[float(r["fx"]), float(r["fy"]), float(r.get("fz") or 0.0)] for r in rows])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
        raise _Unchecked(str(e)) from None
    feed = np.flatnonzero(prog.feed)
    if F.shape != (feed.size, 3):
        raise _Unchecked("rows")
    per = np.zeros((len(prog), 3))
    per[feed] = F
    return lambda prog_, m, s: per[m]


def _per_point(F: np.ndarray):
    """The CSV's forces, linear from each point to the next."""
    return lambda prog, m, s: F[m] + s[:, None] * (F[m + 1] - F[m])


def _points(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """x, y, z (and fx, fy, fz) of a CSV of points, read here with the csv module (a comma, a tab
    or a semicolon between the cells, as the header shows)."""
    try:
        lines = [
            ln for ln in io.StringIO(path.read_text(encoding="utf-8-sig")) if ln.strip() and ln[0] != "#"
        ]
        sep = max(",;\t", key=lines[0].count)
        rows = [
            {k.strip().lower(): v for k, v in r.items() if k} for r in csv.DictReader(lines, delimiter=sep)
        ]
        P = np.array([[float(r[c]) if r.get(c) not in (None, "") else 0.0 for c in "xyz"] for r in rows])
        F = None
        if rows and "fx" in rows[0]:
            F = np.array([[float(r.get(c) or 0.0) for c in ("fx", "fy", "fz")] for r in rows])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError, IndexError) as e:
        raise _Unchecked(str(e)) from None
    return P, F


# ------------------------------------------------------------------------------ G-code
#: Lines a program may hold that cannot be compensated, or that are degenerate.
GCODE_LINES = (
    "O100 WHILE [#1 LT 3]",
    "O100 ENDWHILE",
    "#1=5",
    "G1 X#1",
    "G1 X[1+2]",
    "G41 D1",
    "G42 D1",
    "G41",
    "G40",
    "G93 G1 X5 F2",
    "G81 X5 Y5 Z-2 R1",
    "G83 X5 Y5 Z-2 R1 Q0.5",
    "G80 X5",
    "G92 X0 Y0",
    "G10 L2 P1 X0",
    "M98 P100",
    "G1 X10 X20",
    "G1 G2 X1 Y1",
    "G0 G1",
    "G1",
    "G1 F0",
    "G1 X-0 Y-0",
    "G1 X0 Y0 Z0",
    "G2 X0 Y0 R0",
    "G2 X100 Y0 R1",
    "G2 X0 Y0 I5 J0",
    "G3 X0 Y0 I0 J-5",
    "G2 X0 Y0 I0 J0",
    "G2 X1 Y0 I100000 J0",
    "G2 X0 Y0 I50000",
    "G18 G2 X5 Z0 I2.5 J1",
    "G19 G3 Y0 Z0 R-0.5",
    "G2 X1 Y1 P3 I1",
    "G1 X1e300",
    "G1 X" + "9" * 400,
    "G1 X1" + "0" * 320,
    "G1 Y" + "1" * 30,
    "G1 Xnan",
    "G1 Xinf",
    "G1 X-",
    "G1 X.",
    "G1 X1.2.3",
    "G1 X1,5",
    "G1 Q5 W3",
    "G1 A30 B5",
    "G1 E5",
    "$H",
    "G1 X5 *57",
    "/G1 X5",
    "G20",
    "G21",
    "G91",
    "G90",
    "G90.1",
    "G17",
    "G18",
    "G19",
    "G28",
    "G53 G0 Z0",
    "G55",
    "M30",
    "M2",
    "%",
    "(unclosed comment",
    "G1 X5 (comment) Y5 ; more",
    "N99999999999999999999 G1 X5",
    "G1 X 1 Y - 2",
    "G4 P1",
    "G1 Z-1000000",
    "G0 X1e5 Y1e5",
    "G1 X5 Y5 Z5 X6",
    "\x00\x01\x02",
    "\ufeffG1 X5",
    "G1 X５",
    "G１ X5",
)


@st.composite
def gcode_text(draw, valid: str) -> bytes:
    """A program made wrong: the generic mutations, or one line of :data:`GCODE_LINES` inserted or
    put in place of a line (or a move's number replaced), or binary garbage."""
    kind = draw(st.sampled_from(("generic", "generic", "insert", "insert", "replace", "number", "binary")))
    lines = valid.splitlines(keepends=True)
    nl = "\r\n" if "\r\n" in valid else "\n"
    if kind == "generic":
        return draw(mutated_text(valid))
    if kind == "binary":
        return draw(st.binary(min_size=1, max_size=300))
    if kind == "number":
        from helpers.fuzz import _replace_number

        k = draw(st.integers(0, 200))
        new = draw(st.sampled_from((*EXTREME_NUMBERS, "1e300", "-0.", "0.", "100000.", "1e-9")))
        return _replace_number(valid, k, new).encode("utf-8", errors="surrogateescape")
    extra = draw(st.lists(st.sampled_from(GCODE_LINES), min_size=1, max_size=3))
    i = draw(st.integers(0, len(lines)))
    add = [e + nl for e in extra]
    if kind == "replace" and i < len(lines):
        lines = lines[:i] + add + lines[i + 1 :]
    else:
        lines = lines[:i] + add + lines[i:]
    return "".join(lines).encode("utf-8")


@st.composite
def gcode_cases(draw) -> FuzzCase:
    """``compensate`` of a mutated seed program by the 3PRR or the Delta, a constant force."""
    name = draw(st.sampled_from(PROGRAMS))
    robot = draw(st.sampled_from(("3prr", "3prr", "delta")))
    text = (DATA / name).read_bytes().decode("utf-8")
    data = draw(gcode_text(text))
    p = "p" + Path(name).suffix
    return compensate_case(
        {p: data},
        robot,
        p,
        "--place",
        PLACES[robot],
        "--force-n",
        FORCES[robot],
        blamed=p,
        note=f"{name} x {robot}",
    )


# ------------------------------------------------------------------------------ CSV of points
def points_seed(forces: bool, planar: bool) -> str:
    """A square of side 20 mm cut around the origin, its last point its first; with a force per point
    (N: the 3PRR's about 400, the Delta's about 4, as compliant under 4 N as the 3PRR under 400)."""
    pts = [(-10, -10), (10, -10), (10, 10), (-10, 10), (-10, -10)]
    head = (
        ["x", "y"] + ([] if planar else ["z"]) + (["fx", "fy"] + ([] if planar else ["fz"]) if forces else [])
    )
    rows = []
    for k, (x, y) in enumerate(pts):
        r = [f"{x:g}", f"{y:g}"] + ([] if planar else ["-2"])
        if forces:
            r += ["0", f"{-400 - 20 * k:g}"] if planar else ["0", f"{-4 - 0.2 * k:g}", "-1"]
        rows.append(",".join(r))
    return ",".join(head) + "\n" + "\n".join(rows) + "\n"


@st.composite
def _special_or_generic(draw, valid: str, generic: int, specials: tuple[str, ...]):
    """None (the caller applies the generic mutations) with odds ``generic`` to 1, else the valid
    table's header, its rows and one of ``specials`` to make of it."""
    if draw(st.integers(0, generic)) < generic:
        return None
    lines = valid.splitlines()
    return lines[0], lines[1:], draw(st.sampled_from(specials))


@st.composite
def points_text(draw, valid: str) -> bytes:
    """A CSV of points made wrong: the generic mutations, or a degenerate table."""
    pick = draw(
        _special_or_generic(
            valid,
            3,
            (
                "repeat point",
                "one point",
                "all the same",
                "units header",
                "nan force",
                "1e12 force",
                "swapped columns",
                "extra column",
                "missing cell",
                "comment",
                "semicolons",
                "far away",
            ),
        )
    )
    if pick is None:
        return draw(mutated_text(valid))
    head, rows, special = pick
    if special == "repeat point":
        rows = rows[:2] + rows[1:]
    elif special == "one point":
        rows = rows[:1]
    elif special == "all the same":
        rows = [rows[0]] * len(rows)
    elif special == "units header":
        head = ",".join(f"{c} ({'N' if c.startswith('f') else 'mm'})" for c in head.split(","))
    elif special == "nan force" and "fx" in head:
        rows[1] = ",".join(rows[1].split(",")[:-1] + ["nan"])
    elif special == "1e12 force" and "fx" in head:
        rows[2] = ",".join(rows[2].split(",")[:-1] + ["1e12"])
    elif special == "swapped columns":
        cols = head.split(",")
        cols[0], cols[1] = cols[1], cols[0]
        head = ",".join(cols)
    elif special == "extra column":
        head += ",w"
        rows = [r + ",1" for r in rows]
    elif special == "missing cell":
        rows[1] = ",".join(rows[1].split(",")[:-1])
    elif special == "comment":
        rows.insert(1, "# a comment")
    elif special == "semicolons":
        head, rows = head.replace(",", ";"), [r.replace(",", ";") for r in rows]
    elif special == "far away":
        rows[2] = ",".join(["1e5"] + rows[2].split(",")[1:])
    return ("\n".join([head, *rows]) + "\n").encode()


@st.composite
def points_cases(draw) -> FuzzCase:
    """``compensate`` of a mutated CSV of points: with its force columns, or with --force-n."""
    robot = draw(st.sampled_from(("3prr", "3prr", "delta")))
    forces = draw(st.booleans())
    data = draw(points_text(points_seed(forces, planar=robot == "3prr")))
    opts = ("--place", PLACES[robot]) + (() if forces else ("--force-n", FORCES[robot]))
    return compensate_case(
        {"p.csv": data},
        robot,
        "p.csv",
        *opts,
        blamed="p.csv",
        note=f"points{' with forces' if forces else ''} x {robot}",
        out="o.csv",
    )


# ------------------------------------------------------------------------------ force file
@functools.cache
def _feed_lines(name: str) -> tuple[int, ...]:
    prog, _ = read_program(DATA / name)
    path = toolpath_from_moves(prog.moves)
    return tuple(int(v) for v in path.line[np.flatnonzero(path.feed)])


def force_seed(name: str, planar: bool) -> str:
    """One row per feed move of the program: its line and a force turning slowly (N)."""
    rows = ["line,fx,fy" + ("" if planar else ",fz")]
    for k, n in enumerate(_feed_lines(name)):
        a, f = 0.3 * k, 400.0 if planar else 5.0  # N: the Delta's arms bend by a millimetre under 100
        fx, fy = f * math.cos(a), f * math.sin(a)
        rows.append(f"{n},{fx:.3f},{fy:.3f}" + ("" if planar else ",-2"))
    return "\n".join(rows) + "\n"


@st.composite
def force_text(draw, valid: str) -> bytes:
    """A force file made wrong: the generic mutations, or rows that do not match the program."""
    pick = draw(
        _special_or_generic(
            valid,
            2,
            (
                "row dropped",
                "row added",
                "rows swapped",
                "line shifted",
                "nan",
                "kN header",
                "header only",
                "fz added",
                "fz dropped",
                "line as float",
                "line negative",
                "huge force",
            ),
        )
    )
    if pick is None:
        return draw(mutated_text(valid))
    head, rows, special = pick
    i = draw(st.integers(0, len(rows) - 1))
    if special == "huge force":  # within the 1e9 N plausibility limit, beyond the linear model
        c = rows[i].split(",")
        c[draw(st.integers(1, 2))] = draw(st.sampled_from(("1e4", "-1e5", "1e6", "3e8")))
        rows[i] = ",".join(c)
    if special == "row dropped":
        rows = rows[:i] + rows[i + 1 :]
    elif special == "row added":
        rows = rows[: i + 1] + rows[i:]
    elif special == "rows swapped" and len(rows) > 1:
        j = (i + 1) % len(rows)
        rows[i], rows[j] = rows[j], rows[i]
    elif special == "line shifted":
        c = rows[i].split(",")
        rows[i] = ",".join([str(int(c[0]) + 1), *c[1:]])
    elif special == "nan":
        c = rows[i].split(",")
        c[draw(st.integers(1, len(c) - 1))] = draw(st.sampled_from(("nan", "inf", "-inf", "", "1e400")))
        rows[i] = ",".join(c)
    elif special == "kN header":
        head = head.replace("fx", "fx_kN").replace("fy", "fy_kN")
    elif special == "header only":
        rows = []
    elif special == "fz added" and "fz" not in head:
        head += ",fz"
        rows = [r + ",5" for r in rows]
    elif special == "fz dropped" and "fz" in head:
        head = "line,fx,fy"
        rows = [",".join(r.split(",")[:3]) for r in rows]
    elif special == "line as float":
        c = rows[i].split(",")
        rows[i] = ",".join([c[0] + ".5", *c[1:]])
    elif special == "line negative":
        c = rows[i].split(",")
        rows[i] = ",".join(["-" + c[0], *c[1:]])
    return ("\n".join([head, *rows]) + "\n").encode()


@st.composite
def force_cases(draw) -> FuzzCase:
    """``compensate`` of a seed program with a mutated --force-file."""
    name = draw(st.sampled_from(PROGRAMS[:2]))
    robot = draw(st.sampled_from(("3prr", "3prr", "delta")))
    data = draw(force_text(force_seed(name, planar=robot == "3prr")))
    p = "p" + Path(name).suffix
    out = draw(st.sampled_from((OUT,) * 9 + ("f.csv",)))  # the output onto the force file
    return compensate_case(
        {p: (DATA / name).read_bytes(), "f.csv": data},
        robot,
        p,
        "--place",
        PLACES[robot],
        "--force-file",
        "{dir}/f.csv",
        blamed="f.csv",
        note=f"force file of {name} x {robot}" + (", --out f.csv" if out != OUT else ""),
        out=out,
    )


# ------------------------------------------------------------------------------ options
_NUMBERS = ("0", "-1", "nan", "inf", "1e-9", "1e9", "1e12", "-0", "abc", "", "1,2", "1e400")
_VECTORS = ("0,-490.5", "1", "1,2,3,4", "nan,0", "0,inf", "1e12,0", "1e12,1e12,1e12", "0,0", "a,b", "", ",,")
_VECTORS += ("0,100000", "-1e6,0,0", "3e8,0")  # within the 1e9 N limit, far beyond the linear model
_PLACES = ("auto", "AUTO", " auto ", "380,200", "0,0", "1e9,1e9", "nan,0", "380", "380,200,0,0", "x,y", "")
_REGIONS = (
    "300:460,150:250",
    "0:1,0:1",
    "460:300,0:1",
    "a:b,c:d",
    "nan:1,0:1",
    "-1e9:1e9,-1e9:1e9",
    "1:2",
    "",
)
_RPY = ("0,180,0", "0,0", "nan,0,0", "1e9,0,0", "")
_SEEDS = ("0,0,0", "1,2", "nan", "0," * 13 + "0", "1e9,0,0", "")


@st.composite
def option_cases(draw) -> FuzzCase:
    """``compensate`` of a valid program with one to three options made wrong."""
    robot = draw(st.sampled_from(("3prr", "3prr", "delta")))
    name = draw(st.sampled_from(PROGRAMS[:2]))
    p = "p" + Path(name).suffix
    opts: dict[str, str | None] = {"--place": PLACES[robot], "--force-n": FORCES[robot]}
    notes = []
    out = OUT
    for _ in range(draw(st.integers(1, 3))):
        what = draw(
            st.sampled_from(
                (
                    "--tolerance-um",
                    "--force-n",
                    "--force-feed-n",
                    "--place",
                    "--place-region",
                    "--objective",
                    "--tool-rpy-deg",
                    "--q-seed-deg",
                    "--free-tool-spin",
                    "--figures",
                    "--out",
                )
            )
        )
        if what == "--tolerance-um":
            opts[what] = draw(st.sampled_from(_NUMBERS + ("0.5", "5", "1e-3", "0.01")))
        elif what in ("--force-n", "--force-feed-n"):
            opts.pop("--force-n", None)
            opts[what] = draw(st.sampled_from(_VECTORS + (FORCES[robot],)))
        elif what == "--place":
            opts[what] = draw(st.sampled_from((*_PLACES, PLACES[robot])))
        elif what == "--place-region":
            opts["--place"] = "auto"
            opts[what] = draw(st.sampled_from(_REGIONS))
        elif what == "--objective":
            opts[what] = draw(st.sampled_from(("worst", "rms", "RMS", "best", "")))
        elif what == "--tool-rpy-deg":
            opts[what] = draw(st.sampled_from(_RPY))
        elif what == "--q-seed-deg":
            opts[what] = draw(st.sampled_from(_SEEDS))
        elif what in ("--free-tool-spin", "--figures"):
            opts[what] = None
        elif what == "--out":
            out = draw(st.sampled_from((p, "sub/dir/o.nc", "o.nc/", ".", "p.nc.html")))
        notes.append(f"{what} {opts.get(what, out)!r}")
    args: list[str] = []
    for k, v in opts.items():
        args += [k] if v is None else [k, v]
    return compensate_case(
        {p: (DATA / name).read_bytes()},
        robot,
        p,
        *args,
        blamed=None,
        note=f"{name} x {robot}: " + ", ".join(notes),
        out=out,
        expect=_ignored(opts),
    )


def _ignored(opts: dict) -> str | None:
    """An option the run would ignore (the 3PRR and the Delta have no tool to turn, a placement
    given leaves nothing to search): a message must name it, or the run is silently wrong."""
    auto = (opts.get("--place") or "").strip().lower() == "auto"
    for name in ("--tool-rpy-deg", "--q-seed-deg", "--free-tool-spin"):
        if name in opts:
            return name
    if not auto and "--place-region" in opts:
        return "--place-region"
    if not auto and opts.get("--objective", "worst") != "worst":
        return "--objective"
    return None


# ------------------------------------------------------------------------------ the arm
#: The six-joint arm (``urdf arm6``): where its program's origin goes and a force (N, base frame)
#: that deflects it by about 0.5 mm on the seed program (docs/machining.md).
ARM = "urdf arm6"
ARM_PLACE, ARM_FORCE = PLACES[ARM], FORCES[ARM]
#: The arm's options: values a user may give (a program then compensated or refused as out of
#: reach, naming its line), and values that are wrong whatever the program (refused naming the option).
ARM_VALUES = {
    "--tool-rpy-deg": (
        ("0,180,0", "180,0,0", "0,180,90", "5,175,0", "720,180,0", "0,0,0", "0,90,0", "1e9,0,0"),
        ("nan,0,0", "0,0", "1,2,3,4", "inf,0,0", "", "a,b,c", "1_0,180,0"),
    ),
    "--q-seed-deg": (
        ("0,40,-10,0,60,0", "0,0,0,0,0,0", "10,30,-20,5,70,-5", "180,40,-10,0,60,0", "0,40,-10,0,-60,180"),
        ("0,0", "0,0,0,0,0,0,0", "400,0,0,0,0,0", "1e9,0,0,0,0,0", "nan", "0,-91,0,0,0,0", ""),
    ),
    "--tip-offset-mm": (
        ("0,0,100", "0,0,0", "0,0,150", "20,-10,120", "0,0,-50", "0,0,1e5"),
        ("0,0", "nan,0,0", "1e9,0,0", "0,0,1e7", "", "x,0,0"),
    ),
    # link_5: the five joints to the wrist take arm6's seed and springs of those joints (its own
    # six-value seed was refused, naming q_seed_deg, which the user did not give)
    "--tip": (("tool0", "link_6", "link_5"), ("nope", "", "TOOL0", "base_link")),
    "--param": (
        ("k_theta=1e7", "k_theta=1e12", "k_theta=1e3", "k_theta=1e-3"),
        ("k_theta=-5", "k_theta=0", "k_theta=nan", "k_theta=inf", "nope=1", "k1", "k_theta=1e300", "k1=5e6"),
    ),
    "--place": (
        (
            "480,-30,380",
            "480,-30,300",
            "400,100,380",
            "600,-30,380",
            "700,0,380",
            "300,0,600",
            "0,0,0",
            "480,-30",
            "2000,0,380",
        ),
        ("nan,0,0", "480,-30,380,1", "480;-30;380", "4_80,-30,380"),
    ),
    "--free-tool-spin": ((None,), ()),
}


#: The arm's links a user may give as --tip (base_link is not one: no joint before it).
ARM_LINKS = ("link_1", "link_2", "link_3", "link_4", "link_5", "link_6", "tool0")
#: arm6's own seed (deg, joint_1..joint_6): the first n of it are a chain of n joints' seed.
ARM_SEED = (0.0, 40.0, -10.0, 0.0, 60.0, 0.0)
#: Placements beyond the arm's reach (1264 mm from joint_1: Chain.reach_mm) and within it.
ARM_FAR_PLACES = ("1300,0,380", "0,0,1500", "-900,-900,380", "1e6,0,0")
ARM_NEAR_PLACES = ("480,-30,380", "300,0,600")


@st.composite
def arm_tip_cases(draw) -> FuzzCase:
    """``compensate urdf arm6 --tip LINK`` (any link from link_1 to tool0) with or without
    --q-seed-deg (the chain's joints, or arm6's six), --tool-rpy-deg and --tip-offset-mm, placed
    within or beyond the arm's reach: compensated (re-checked by the independent solver on the
    chain to that link) or refused in one line naming the option or the program's line."""
    tip = draw(st.sampled_from(ARM_LINKS))
    n = ARM_LINKS.index(tip) + 1 if tip != "tool0" else 6
    place = draw(st.sampled_from(ARM_NEAR_PLACES + ARM_FAR_PLACES))
    opts: dict[str, str] = {"--place": place, "--force-n": ARM_FORCE, "--tip": tip}
    if draw(st.booleans()):
        opts["--q-seed-deg"] = ",".join(f"{v:g}" for v in (ARM_SEED[:n] if draw(st.booleans()) else ARM_SEED))
    if draw(st.booleans()):
        opts["--tool-rpy-deg"] = draw(st.sampled_from(ARM_VALUES["--tool-rpy-deg"][0][:4]))
    if draw(st.booleans()):
        opts["--tip-offset-mm"] = draw(st.sampled_from(("0,0,100", "0,0,0", "20,-10,120")))
    args = [a for kv in opts.items() for a in kv]
    return compensate_case(
        {"p.nc": (DATA / "own_cam_mm.nc").read_bytes()},
        ARM,
        "p.nc",
        *args,
        note="arm6: " + " ".join(args[4:]),
    )


@st.composite
def arm_cases(draw) -> FuzzCase:
    """``compensate urdf arm6`` of the seed program (own_cam_mm.nc) with one to three of the arm's
    options set: values a user may give, or wrong ones. When exactly one is wrong, the message must
    name that option; the outputs of the others are re-checked by the arm's independent solver.
    One case in three: :func:`arm_tip_cases`."""
    if draw(st.integers(0, 2)) == 0:
        return draw(arm_tip_cases())
    opts: dict[str, str | None] = {"--place": ARM_PLACE, "--force-n": ARM_FORCE}
    wrong, notes = [], []
    for name in draw(st.lists(st.sampled_from(sorted(ARM_VALUES)), min_size=1, max_size=3, unique=True)):
        good, bad = ARM_VALUES[name]
        is_bad = bool(bad) and draw(st.booleans())
        opts[name] = draw(st.sampled_from(bad if is_bad else good))
        if is_bad:
            wrong.append(name)
        notes.append(f"{name} {opts[name]!r}" + (" (wrong)" if is_bad else ""))
    args: list[str] = []
    for k, v in opts.items():
        args += [k] if v is None else [k, v]
    return compensate_case(
        {"p.nc": (DATA / "own_cam_mm.nc").read_bytes()},
        ARM,
        "p.nc",
        *args,
        blamed=wrong[0] if len(wrong) == 1 else None,
        note="arm6: " + ", ".join(notes),
        must_refuse=bool(wrong),  # a wrong value is refused before anything is done, whatever the rest
    )


# ------------------------------------------------------------------------------ --from-campaign
#: A program the sensor seed's 3PRR cuts placed at CAMPAIGN_PLACE (mm), and the force (N).
CAMPAIGN_PROGRAM = b"G21 G90 G17\nG0 X0 Y0 Z0\nG1 X10 Y0 F100\nG1 X10 Y5\nG1 X0 Y5\n"
CAMPAIGN_PLACE, CAMPAIGN_FORCE = "400,300", "100,-50"
#: What is done to the campaign folder (``c``), and the file a refusal must name (None: any).
CAMPAIGN_DAMAGE = {
    "none": None,
    "folder reached through a link": None,
    "stiffmap.db a link out to a copy": None,
    "stiffmap.db a link out to another campaign's": "campaign.toml",
    "stiffmap.db a dangling link": "stiffmap.db",
    "campaign.toml a link out to another campaign's": "campaign.toml",
    "no stiffmap.db": "stiffmap.db",
    "stiffmap.db empty": "stiffmap.db",
    "stiffmap.db text": "stiffmap.db",
    "stiffmap.db damaged": None,  # a few bytes changed may leave it readable (and its fit changed)
    "stiffmap.db another program's": "stiffmap.db",
    "stiffmap.db a folder": "stiffmap.db",
    "the fit failed": "stiffmap.db",
    "no fit": "stiffmap.db",
    "a value of the fit": None,
    "no campaign.toml": "campaign.toml",
    "campaign.toml damaged": None,
    "a vision campaign without a model": "campaign.toml",
    "DIR a file": "p.ngc",
    "DIR missing": "nowhere",
}
#: Values of a model_fit column (params, std, cov, status...), and what a run given them must say.
FIT_VALUES = (
    ('{"kj": -5}', None),
    ('{"kj": 0}', None),
    ('{"nope": 5}', None),
    ('{"kj": "abc"}', None),
    ('{"kj": 1e308}', None),
    ("{}", None),
    ("[[-1]]", "covariance"),
    ("[[NaN]]", None),
    ("[[1e308]]", None),
    ("[[1, 2], [3, 4]]", None),
    ("failed", None),
    (None, None),
    ("NaN", None),
    ("not json", None),
    (-1, None),
)


def campaign_files(seed: str) -> dict[str, bytes]:
    """A measured test-bed campaign (``helpers.fuzz_safety.measured_seed``) in ``c/``: what
    --from-campaign reads (its campaign.toml, stiffmap.db and the files beside them, not its
    recordings or images)."""
    return {
        f"c/{k}": v
        for k, v in measured_seed(seed).items()
        if not k.startswith(("recordings/", "images/")) and not k.endswith(".gz")
    }


def edited_db(db: bytes, *sql: tuple) -> bytes:
    """The database with statements (SQL, parameters) run on it (one a constraint refuses: not run)."""
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "stiffmap.db"
        f.write_bytes(db)
        with contextlib.closing(sqlite3.connect(f)) as c:
            for stmt in sql:
                with contextlib.suppress(sqlite3.IntegrityError):  # NOT NULL: the value stays
                    c.execute(*stmt)
            c.commit()
        return f.read_bytes()


@st.composite
def campaign_cases(draw) -> FuzzCase:
    """``compensate --from-campaign DIR`` on the sensor seed (3PRR, its fit of kj) with its folder
    damaged (:data:`CAMPAIGN_DAMAGE`); the outputs re-checked by the truss with the campaign's
    parameters read here."""
    damage = draw(st.sampled_from(sorted(CAMPAIGN_DAMAGE) + ["a value of the fit"] * 5))  # the most kinds
    files = {**campaign_files("sensor"), "p.ngc": CAMPAIGN_PROGRAM}
    links: dict[str, str] = {}
    camp, expect, note = "c", None, damage
    db = files["c/stiffmap.db"]
    if damage == "folder reached through a link":
        links["cl"], camp = "c", "cl"
    elif damage.startswith("stiffmap.db a link out") or damage == "stiffmap.db a dangling link":
        other = {"copy": db, "campaign's": campaign_files("vision")["c/stiffmap.db"]}
        del files["c/stiffmap.db"]
        if "dangling" not in damage:
            files["elsewhere/stiffmap.db"] = other["copy" if damage.endswith("copy") else "campaign's"]
        links["c/stiffmap.db"] = "elsewhere/stiffmap.db"
    elif damage == "campaign.toml a link out to another campaign's":
        files["elsewhere/campaign.toml"] = campaign_files("vision")["c/campaign.toml"]
        del files["c/campaign.toml"]
        links["c/campaign.toml"] = "elsewhere/campaign.toml"
    elif damage == "no stiffmap.db":
        del files["c/stiffmap.db"]
    elif damage == "stiffmap.db empty":
        files["c/stiffmap.db"] = b""
    elif damage == "stiffmap.db text":
        files["c/stiffmap.db"] = b"fit = ok\n"
    elif damage == "stiffmap.db damaged":
        files["c/stiffmap.db"] = draw(mutated_bytes(db))
    elif damage == "stiffmap.db another program's":
        files["c/stiffmap.db"] = edited_db(b"", ("CREATE TABLE users (name TEXT)",))
    elif damage == "stiffmap.db a folder":
        del files["c/stiffmap.db"]
        files["c/stiffmap.db/model_fit"] = b"kj = 600\n"
    elif damage == "the fit failed":
        files["c/stiffmap.db"] = edited_db(
            db, ("UPDATE model_fit SET status = 'failed', error = 'singular'",)
        )
    elif damage == "no fit":
        files["c/stiffmap.db"] = edited_db(db, ("DELETE FROM model_fit",))
    elif damage == "a value of the fit":
        col = draw(st.sampled_from(("params", "params", "cov", "cov", "std", "status", "robot", "name")))
        value, expect = draw(st.sampled_from(FIT_VALUES))
        expect = expect if col == "cov" else None
        files["c/stiffmap.db"] = edited_db(db, (f"UPDATE model_fit SET {col} = ?", (value,)))
        note = f"model_fit.{col} = {value!r}"
    elif damage == "no campaign.toml":
        del files["c/campaign.toml"]
    elif damage == "campaign.toml damaged":
        files["c/campaign.toml"] = draw(mutated_text(files["c/campaign.toml"].decode()))
    elif damage == "a vision campaign without a model":
        files = {**campaign_files("vision"), "p.ngc": CAMPAIGN_PROGRAM}
        files["c/campaign.toml"] = re.sub(
            r"\[robot\]\n(?:.*\n)*?(?=\n\[)",
            '[robot]\nmodel = "none"\n',
            files["c/campaign.toml"].decode(),
            count=1,
        ).encode()
    elif damage == "DIR a file":
        camp = "p.ngc"
    elif damage == "DIR missing":
        camp = "nowhere"
    case = compensate_case(
        files,
        f"--from-campaign {{dir}}/{camp}",
        "p.ngc",
        "--place",
        CAMPAIGN_PLACE,
        "--force-n",
        CAMPAIGN_FORCE,
        blamed=CAMPAIGN_DAMAGE[damage],
        note=note,
        out="o.ngc",
        expect=expect,
    )
    return dataclasses.replace(case, links=links) if links else case


FUZZ_CLASSES = [
    FuzzClass(
        "G-code program x compensate",
        gcode_cases(),
        "the G-code fixtures (a Fanuc-style CAM program, inch R arcs in G17/G18/G19, a CRLF program "
        "with line numbers and G20) made wrong: truncated, corrupted, 1e300, NaN, -0, UTF-16, binary, "
        "lines that cannot be compensated (O-words, #, [], G41/G42, G93, canned cycles, G92) or are "
        "degenerate (repeated or unknown words, zero-length moves, zero-radius, impossible and "
        "enormous arcs, full circles); the 3PRR and the Delta; outputs re-checked",
    ),
    FuzzClass(
        "points CSV x compensate",
        points_cases(),
        "a CSV of points x,y[,z][,fx,fy[,fz]] made wrong: the generic mutations, repeated points, one "
        "point, unit headers, NaN and 1e12 forces, swapped or extra columns, a point 100 m away",
    ),
    FuzzClass(
        "force CSV x compensate",
        force_cases(),
        "a --force-file made wrong: rows dropped, added, swapped, lines shifted, NaN, kN headers, "
        "header only, fz added or dropped, and the generic mutations",
    ),
    FuzzClass(
        "compensate urdf arm6 options",
        arm_cases(),
        "the six-joint arm's --tool-rpy-deg, --q-seed-deg, --tip, --tip-offset-mm, --param, --free-tool-spin "
        "and --place: values a user may give (some out of reach) and wrong ones (NaN, the wrong count, "
        "beyond the joint limits, an unknown frame, rigid or negative springs, 1_0); outputs re-checked "
        "by the arm's independent solver",
    ),
    FuzzClass(
        "compensate --from-campaign folder",
        campaign_cases(),
        "compensate --from-campaign on a measured campaign (the 3PRR's sensor seed) whose folder is damaged: "
        "stiffmap.db missing, empty, text, corrupted, another program's, a folder, a link out (to a copy, to "
        "another campaign's, dangling); the fit failed or missing or one of its values changed (params, std, "
        "cov, status); campaign.toml missing, damaged or a link to another campaign's; a vision campaign "
        "without a model; DIR a file or missing; outputs re-checked by the truss with the fitted kj",
    ),
    FuzzClass(
        "compensate options",
        option_cases(),
        "--tolerance-um, --force-n/--force-feed-n, --place (X,Y, auto, nonsense, far outside), "
        "--place-region, --objective, --tool-rpy-deg, --q-seed-deg, --free-tool-spin on a non-arm, "
        "--figures, --out onto the program or a folder",
    ),
]
