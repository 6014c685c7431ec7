"""Real public G-code through ``stiffmap compensate``, checked independently.

Every program of a folder (default ``/tmp/gcode_real``: public programs collected from
LinuxCNC's ``nc_files``, cncjs, Universal-G-Code-Sender and others, with an ``INDEX.md``
naming each one's source and licence; the folder is not part of the repository, and the
sweep skips with a message when it is absent) is run through the real command, as a user
would (a subprocess, ``--tolerance-um 2``), for:

- ``3prr/F``: the milling study's 3PRR (kj 525, kb 9 800 N/mm, rods E A 7e6 N) under its
  50 kgf load, constant (``--force-n 0,-490.5``);
- ``3prr/feed``: the same robot under a force turning with the feed
  (``--force-feed-n 300,200``);
- ``arm6``: the six-joint test arm (``urdf arm6``), ``--force-feed-n 20,15,10``;
- ``delta``: the Delta, ``--force-n 4,3,-2``.

Each program is placed (``--place``) with the centre of its bounding box at the middle of
the robot's workspace; one that does not fit is tried with ``--place auto``. A compensated
output is then checked by code that is not the code under test
(``tests/helpers/machining_checks.py``: a direct-stiffness truss for the 3PRR,
``C = J K^-1 J^T`` with central-difference Jacobians for the arm, ``K = k_theta J^T J`` for
the Delta): the output read back, sampled every half millimetre along every feed move,
deflected under the force of the nearest programmed feed move that puts it on its path
(turning with the feed: the programmed tangent where the deflected point lands; on the short
piece that joins two cuts whose force differs, the best blend of the two forces), and

- every deflected sample within 2 um of the programmed path ("worst residual"),
- every programmed point within 2 um (and the sag of the chords between samples on the
  tightest arc) of the polylines through the deflected samples (the output covers the path),
- every line that is not a move identical and in the same order, with only move lines
  between them (at least as many as the input had there), arcs written with R staying R and
  with I/J/K staying I/J/K.

Outcomes: ``verified``, ``refused`` (exit 2, the one-line message; a refusal that offers
``--pass-through`` is run again with it, as a user would, and both are reported),
``CHECK FAILED`` (what), ``ERROR`` (another exit status or a traceback), ``TIMEOUT``. The
seconds are the wall time of one command (a fresh process, figures off) on a machine shared
with other jobs.

Run:  nice .venv/bin/python benchmarks/bench_gcode_sweep.py [FOLDER] [--robots 3prr/F,arm6]
Saves benchmarks/results/gcode_sweep.md.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from _table import save  # noqa: E402
from helpers.machining_checks import (  # noqa: E402
    arm_deflection,
    delta_deflection,
    truss_3prr,
)

from stiffmap.errors import InputError  # noqa: E402
from stiffmap.machining.forces import ForceSpec, force_at  # noqa: E402
from stiffmap.machining.io import read_program  # noqa: E402
from stiffmap.machining.path import toolpath_from_moves  # noqa: E402
from stiffmap.models import arm6  # noqa: E402
from stiffmap.models.delta import DeltaRobot  # noqa: E402

TOL_UM = 2.0
PER_MM = 2.0
EXTS = {".nc", ".ngc", ".gcode", ".tap", ".cnc", ".txt", ".g", ".gc", ".nci", ".mpf", ".eia"}
LOAD_N = 50 * 9.81
#: name -> (command-line robot, force option, force value, workspace middle for --place (mm), planar)
ROBOTS = {
    "3prr/F": (["3prr", "--param", "area=100"], "--force-n", (0.0, -LOAD_N, 0.0), (380.0, 200.0, 0.0), True),
    "3prr/feed": (
        ["3prr", "--param", "area=100"],
        "--force-feed-n",
        (300.0, 200.0, 0.0),
        (380.0, 200.0, 0.0),
        True,
    ),
    "arm6": (["urdf", "arm6"], "--force-feed-n", (20.0, 15.0, 10.0), (480.0, -30.0, 380.0), False),
    "delta": (["delta"], "--force-n", (4.0, 3.0, -2.0), (0.0, 0.0, -300.0), False),
}


def _deflect(robot: str, points: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """Independent deflections (N, 3) mm at commanded points (base frame) under forces (N, 3)."""
    if robot.startswith("3prr"):
        d = np.zeros_like(points)
        kw = {"h": 800.0, "L": 250.0, "EA": 7e6, "kj": 525.0, "kb": 9800.0}
        for i in range(points.shape[0]):  # the truss takes one force per call when it varies
            d[i, :2] = truss_3prr(points[i : i + 1, :2], forces[i, :2], **kw)[0]
        return d
    if robot == "arm6":
        chain = arm6.model().chain
        d, _ = arm_deflection(
            chain, arm6.K_THETA, arm6.TOOL_ROTATION, points, forces, np.radians(arm6.Q_SEED_DEG)
        )
        return d
    return delta_deflection(DeltaRobot(), points, forces)


def _placement(prog, middle, planar) -> tuple[float, float, float]:
    P = np.array([m.end for m in prog.moves] + [m.start for m in prog.moves[:1]])
    c = 0.5 * (P.min(axis=0) + P.max(axis=0))
    place = np.asarray(middle) - c
    if planar:
        place[2] = 0.0
    return tuple(float(v) for v in place)


def _segments(prog) -> list[tuple[str | None, list[str]]]:
    """The program as (line that is not a move, the move lines before it) pairs; the last pair's
    line is None (the moves after the last such line)."""
    out, moves = [], []
    for n, line in enumerate(prog.lines, start=1):
        if n in prog.move_at_line:
            moves.append(line)
        else:
            out.append((line, moves))
            moves = []
    return [*out, (None, moves)]


def text_problems(prog_in, prog_out) -> list[str]:
    """The lines that are not moves must come out identical and in the same order, with move
    lines only between them (at least as many as the input had there); an arc written with R
    stays R, with I/J/K stays I/J/K."""
    a, b = _segments(prog_in), _segments(prog_out)
    if len(a) != len(b):
        return [f"{len(a) - 1} lines that are not moves in the input, {len(b) - 1} in the output"]
    for (la, ma), (lb, mb) in zip(a, b, strict=True):
        if la != lb:
            return [f"a line that is not a move changed: {la!r} -> {lb!r}"]
        if len(mb) < len(ma):
            return [f"{len(ma)} move lines before {la!r} in the input, {len(mb)} in the output"]
        fa = {_arc_format(x) for x in ma} - {""}
        fb = {_arc_format(x) for x in mb} - {""}
        if not fb <= fa:
            return [f"arc format changed before {la!r}: {sorted(fa)} -> {sorted(fb)}"]
    return []


def _arc_format(line: str) -> str:
    code = _code(line)
    return "R" if "R" in code else ("IJK" if re.search(r"[IJK]", code) else "")


def _code(line: str) -> str:
    return re.sub(r"\(.*?\)|;.*", "", line).upper()


def _nearest_s(path, m: int, Q: np.ndarray) -> np.ndarray:
    """Parameter of the nearest point of programmed move m to points Q: a dense search, then exact
    (the projection on a line; on an arc, the point's angle about the centre, the turn nearest
    the dense search's)."""
    k = max(64, int(path.length()[m] * 40) + 1)
    s = np.linspace(0.0, 1.0, k)
    P = path.point(np.full(k, m), s)
    s0 = s[np.argmin(np.linalg.norm(Q[:, None, :] - P[None, :, :], axis=2), axis=1)]
    if not path.is_arc[m]:
        d = path.end[m] - path.start[m]
        dd = float(d @ d)
        return np.clip((Q - path.start[m]) @ d / dd, 0.0, 1.0) if dd > 0 else s0
    a, b, _ = path.axes[m]
    phi = np.arctan2(Q[:, b] - path.centre[m, 1], Q[:, a] - path.centre[m, 0])
    cand = (phi[:, None] + 2 * math.pi * np.arange(-2, 3)[None, :] - path.theta0[m]) / path.sweep[m]
    best = cand[np.arange(Q.shape[0]), np.argmin(np.abs(cand - s0[:, None]), axis=1)]
    return np.clip(best, 0.0, 1.0)


def _candidates(pin, feed_in: np.ndarray, C: np.ndarray) -> list[int]:
    """Programmed feed moves within 2 mm of a piece's commanded points (the deflection is < 2 mm),
    nearest first."""
    mid = C[[0, C.shape[0] // 2, -1]]
    d = np.array([pin.distance(np.full(3, m), mid).max() for m in feed_in])
    order = np.argsort(d)
    return [int(feed_in[i]) for i in order[:64] if d[i] < 2.0]


def _deflected_on(robot, pin, spec, m: int, C, off) -> tuple[np.ndarray, np.ndarray]:
    """Deflected samples under programmed move m's force, and their distance to that move. The
    force is that of the programmed point the sample is deflected onto (a fixed point: the force
    turns along the move); on the piece joining two cuts whose force differs, the best blend."""
    k = C.shape[0]
    sm = _nearest_s(pin, m, C)
    for _ in range(4):
        X = C + _deflect(robot, C + off, force_at(pin, spec, np.full(k, m), sm))
        sm = _nearest_s(pin, m, X)
    dist = pin.distance(np.full(k, m), X)
    for end, other in ((1.0, m + 1), (0.0, m - 1)):
        bad = dist > TOL_UM * 1e-3
        if not np.any(bad) or not 0 <= other < len(pin) or not pin.feed[other]:
            continue
        nb = int(bad.sum())
        D1 = _deflect(robot, C[bad] + off, force_at(pin, spec, np.full(nb, m), np.full(nb, end)))
        D2 = _deflect(robot, C[bad] + off, force_at(pin, spec, np.full(nb, other), np.full(nb, 1.0 - end)))
        corner = pin.end[m] if end == 1.0 else pin.start[m]
        X1, dd = C[bad] + D1, D2 - D1
        t = np.einsum("ij,ij->i", corner - X1, dd) / np.maximum(np.einsum("ij,ij->i", dd, dd), 1e-30)
        Xb = X1 + np.clip(t, 0, 1)[:, None] * dd
        db = np.linalg.norm(Xb - corner, axis=1)
        better = db < dist[bad]
        idx = np.flatnonzero(bad)[better]
        X[idx], dist[idx] = Xb[better], db[better]
    return X, dist


def verify(robot, force_opt, force, place, prog_in, prog_out) -> tuple[float, str]:
    """Worst distance (um) of the deflected output from the programmed path, and a problem ("" if none)."""
    problems = text_problems(prog_in, prog_out)
    if problems:
        return math.nan, problems[0]
    pin, pout = toolpath_from_moves(prog_in.moves), toolpath_from_moves(prog_out.moves)
    spec = ForceSpec.constant(force) if force_opt == "--force-n" else ForceSpec.feed_frame(force)
    feed_in = np.flatnonzero(pin.feed)
    L = pout.length()
    worst = 0.0
    deflected = []
    off = np.asarray(place)
    for mo in np.flatnonzero(pout.feed):
        k = max(9, int(math.ceil(L[mo] * PER_MM)) + 1)
        C = pout.point(np.full(k, mo), np.linspace(0.0, 1.0, k))
        best = None
        for m in _candidates(pin, feed_in, C) if feed_in.size else []:
            X, dist = _deflected_on(robot, pin, spec, m, C, off)
            if best is None or dist.max() < best[1].max():
                best = (X, dist)
            if dist.max() <= TOL_UM * 1e-3:
                break
        if best is None:
            return (
                math.nan,
                f"output feed move at line {pout.line[mo]} is far from every programmed feed move",
            )
        worst = max(worst, float(best[1].max()))
        deflected.append(best[0])
    if not deflected:
        return math.nan, "no feed move in the output"
    gap = _coverage(pin, deflected)
    # the chords between deflected samples sag below an arc of radius r by at most step^2 / (8 r)
    step = max(float(np.linalg.norm(np.diff(X, axis=0), axis=1).max(initial=0.0)) for X in deflected)
    r = pin.r0[pin.is_arc & pin.feed]
    sag = step**2 / (8 * r.min()) if r.size else 0.0
    if gap > TOL_UM * 1e-3 + sag + 1e-9:
        return 1e3 * worst, f"a programmed point is {1e3 * gap:.1f} um from the deflected output"
    if worst > TOL_UM * 1e-3 + 1e-9:
        return 1e3 * worst, f"a deflected point is {1e3 * worst:.2f} um off the programmed path"
    return 1e3 * worst, ""


def _coverage(path, pieces: list[np.ndarray]) -> float:
    """Largest distance (mm) from a point of the programmed feed moves to the polylines through
    the deflected samples of each output piece (the deflected output covers the path)."""
    A = np.concatenate([X[:-1] for X in pieces])
    B = np.concatenate([X[1:] for X in pieces])
    D = B - A
    dd = np.maximum(np.einsum("ij,ij->i", D, D), 1e-30)
    L = path.length()
    worst = 0.0
    for m in np.flatnonzero(path.feed):
        k = max(9, int(math.ceil(L[m] * PER_MM)) + 1)
        P = path.point(np.full(k, m), np.linspace(0, 1, k))
        for i in range(0, k, 64):
            Q = P[i : i + 64, None, :]
            t = np.clip(np.einsum("qsj,sj->qs", Q - A[None], D) / dd[None], 0.0, 1.0)
            d = np.linalg.norm(Q - (A[None] + t[..., None] * D[None]), axis=2).min(axis=1)
            worst = max(worst, float(d.max()))
    return worst


def _read(path: Path, pass_through: bool):
    try:
        return read_program(path, pass_through=pass_through)[0]
    except InputError:
        return None


def run_one(path: Path, robot: str, timeout: float) -> dict:
    """One program through ``stiffmap compensate`` for one robot, and its check. A refusal that
    offers ``--pass-through`` is retried with it (as a user would), and both are reported."""
    row = {"file": path.name, "robot": robot, "lines": len(path.read_bytes().splitlines())}
    row.update(feed="", outcome="", worst="", seconds="")
    prog = _read(path, False) or _read(path, True)
    if prog is not None:
        row["feed"] = sum(m.feed for m in prog.moves)
        if prog.moves and not any(m.feed for m in prog.moves):
            row["outcome"] = "no feed move (rapids only): nothing to compensate"
            return row
    outcome, extra = _attempt(path, robot, timeout, prog, False)
    row.update(extra)
    if outcome.startswith("refused") and "--pass-through" in outcome:
        second, extra2 = _attempt(path, robot, timeout, prog, True)
        row.update(extra2)
        outcome = f"{outcome.split('; use --pass-through')[0]}; with --pass-through: {second}"
    row["outcome"] = outcome
    return row


def _attempt(path: Path, robot: str, timeout: float, prog, pass_through: bool) -> tuple[str, dict]:
    """Run the command (at the workspace's middle, then ``--place auto`` if that does not fit)."""
    args, force_opt, force, middle, planar = ROBOTS[robot]
    fv = ",".join(f"{v:g}" for v in force)
    extra: dict = {}
    places = ([_placement(prog, middle, planar)] if prog is not None and prog.moves else []) + ["auto"]
    msg = ""
    for place in places:
        ptxt = place if isinstance(place, str) else ",".join(f"{v:.3f}" for v in place)
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / ("out" + path.suffix)
            cmd = [sys.executable, "-m", "stiffmap", "compensate", *args, "--path", str(path)]
            cmd += ["--out", str(out), "--place", ptxt, force_opt, fv, "--tolerance-um", str(TOL_UM)]
            cmd += ["--json", "--no-figures"] + (["--pass-through"] if pass_through else [])
            t0 = time.perf_counter()
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
            except subprocess.TimeoutExpired:
                return "TIMEOUT" + (" (place auto)" if place == "auto" else ""), {
                    "seconds": f">{timeout:.0f}"
                }
            extra["seconds"] = f"{time.perf_counter() - t0:.1f}"
            err = proc.stderr.strip()
            if proc.returncode == 2 and "Traceback" not in err:
                lines = err.splitlines()
                msg = (lines[-1] if lines else "(no message)").replace(str(path), path.name)
                if len(lines) != 1:
                    msg += f" (a message of {len(lines)} lines)"
                if place != "auto" and any(
                    w in msg for w in ("reach", "singular", "workspace", "conditioning")
                ):
                    continue  # does not fit at the middle: let --place auto choose
                return "refused: " + msg, extra
            if proc.returncode not in (0, 1) or "Traceback" in err or not out.exists():
                return f"ERROR exit {proc.returncode}: " + (err.splitlines()[-1] if err else ""), extra
            summary = json.loads(proc.stdout)  # exit 1: done, with warnings (printed on stderr)
            prog_in, prog_out = (read_program(p, pass_through=pass_through)[0] for p in (path, out))
            worst, problem = verify(robot, force_opt, force, tuple(summary["place_mm"]), prog_in, prog_out)
            extra["worst"] = f"{worst:.3f}"
            extra["before"] = f"{summary['deflection_before_um']['worst']:.0f}"
            kept = sum("kept unchanged" in w for w in summary["warnings"])
            outcome = "verified" if not problem else f"CHECK FAILED: {problem}"
            outcome += " (place auto)" if place == "auto" else ""
            return outcome + (f" ({kept} lines kept)" if pass_through else ""), extra
    return "refused: " + msg + " (also with --place auto)", extra


def _kind(outcome: str) -> str:
    """The class of an outcome, for the counts."""
    if "with --pass-through: verified" in outcome:
        return "refused, verified with --pass-through"
    if "with --pass-through" in outcome:
        return "refused, also with --pass-through"
    return outcome.split(":")[0].split(" (")[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default="/tmp/gcode_real")
    ap.add_argument("--robots", default=",".join(ROBOTS))
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--only", default="", help="run only files whose name contains this")
    ap.add_argument("--no-save", action="store_true")
    a = ap.parse_args()
    folder = Path(a.folder)
    if not folder.is_dir():
        print(f"skipped: no folder {folder} (collect public G-code there first; see the docstring)")
        return
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in EXTS and a.only in p.name)
    rows = []
    for f in files:
        for robot in a.robots.split(","):
            r = run_one(f, robot, a.timeout)
            print(
                " | ".join(
                    str(r.get(k, ""))
                    for k in ("file", "robot", "lines", "feed", "outcome", "worst", "seconds")
                ),
                flush=True,
            )
            rows.append(r)
    if a.no_save:
        return
    heads = [
        "file",
        "lines",
        "feed moves",
        "robot",
        "outcome",
        "worst deflection (um)",
        "worst residual (um)",
        "s",
    ]
    table = [
        [
            r["file"],
            r["lines"],
            r["feed"],
            r["robot"],
            r["outcome"],
            r.get("before", ""),
            r["worst"],
            r["seconds"],
        ]
        for r in rows
    ]
    counts: dict[str, int] = {}
    for r in rows:
        key = _kind(r["outcome"])
        counts[key] = counts.get(key, 0) + 1
    notes = (__doc__.split("\n\n", 1)[1].rsplit("Run:", 1)[0]).strip()
    notes += "\n\nOutcomes over " + f"{len(files)} programs x {len(a.robots.split(','))} robots: "
    notes += ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    save("gcode_sweep", "Real public G-code through stiffmap compensate", heads, table, notes)


if __name__ == "__main__":
    main()
