"""``stiffmap compensate`` as one function: read the program, place it, compensate it, write it.

:func:`compensate_file` is what the command calls (and what a script calls): it reads a
G-code program or a CSV of points, builds the force along it, places it (given, or
:func:`~stiffmap.machining.place.place_program`), chooses a serial arm's tool spin if
asked (:func:`~stiffmap.machining.spin.choose_spin`), compensates every feed move
(:func:`~stiffmap.machining.compensate.compensate_path`), and only then writes the
corrected program (atomically; a failure anywhere writes nothing). The returned
:class:`CompensationResult` holds the summary and the curves the report draws.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FieldError, InputError
from ..models.base import Mechanism
from ..stats import chi2_ppf
from ..stiffness import LARGE_DISPLACEMENT_MM
from .compensate import (
    CHECK_FRACTION,
    FIXED_POINT_TOL_MM,
    Compensation,
    CompensationError,
    check_reach,
    compensate_path,
)
from .field import ArmField, field_for
from .forces import ForceSpec, force_at
from .gcode import render_program, written_resolution_mm
from .io import is_points_file, read_force_file, read_points_path, read_program, write_text
from .output import point_rows, program_pieces
from .path import toolpath_from_moves, toolpath_from_points
from .place import OBJECTIVES, Placement, place_program
from .spin import SpinPlan, choose_spin

__all__ = [
    "CompensateOptions",
    "ModelUncertainty",
    "CompensationResult",
    "compensate_file",
    "residual_band_mm",
]

#: Points (at most) at which the model's uncertainty is propagated.
BAND_POINTS = 2000
#: The finest --tolerance-um (10 nm): the commanded points are solved to 1 nm.
MIN_TOLERANCE_UM = 0.01


@dataclass(frozen=True)
class ModelUncertainty:
    """The covariance of a model's fitted parameters (a campaign's fit).

    Attributes
    ----------
    names : tuple of str
        The parameters, in the covariance's order.
    cov : ndarray, shape (p, p)
        Their covariance (units of the parameters squared).
    """

    names: tuple[str, ...]
    cov: np.ndarray


@dataclass(frozen=True)
class CompensateOptions:
    """What ``stiffmap compensate`` was asked (units in the names).

    Attributes
    ----------
    tolerance_um : float
        Largest distance between the deflected and the programmed path, micrometres.
    place_mm : tuple of 3 float, or None
        The program's origin in the base frame; None with ``place_auto``, else (0, 0, 0).
    place_auto : bool
    place_region_mm : tuple (lo, hi) of 3-tuples, or None
    objective : str
        ``worst`` or ``rms`` (``--place auto``).
    force : ForceSpec or None
        Constant or feed-frame force (None: from ``force_file`` or the CSV's columns).
    force_file : path or None
    pass_through : bool
    free_tool_spin : bool
    tool_rotation : ndarray (3, 3) or None
    q_seed : ndarray (n,) or None, rad or mm
    """

    tolerance_um: float = 1.0
    place_mm: tuple[float, float, float] | None = None
    place_auto: bool = False
    place_region_mm: tuple | None = None
    objective: str = "worst"
    force: ForceSpec | None = None
    force_file: str | os.PathLike | None = None
    pass_through: bool = False
    free_tool_spin: bool = False
    tool_rotation: np.ndarray | None = None
    q_seed: np.ndarray | None = None


@dataclass(frozen=True)
class CompensationResult:
    """What a compensation did: the summary (JSON-able) and the data of its figure."""

    summary: dict
    compensation: Compensation
    placement: Placement | None = None
    spin: SpinPlan | None = None
    written: tuple[str, ...] = ()
    warnings: tuple[str, ...] = field(default=())


def _forces_for_program(prog, path, opts: CompensateOptions) -> ForceSpec:
    if opts.force_file is not None:
        if opts.force is not None:
            raise InputError("--force-file and --force-n/--force-feed-n are exclusive")
        feed = np.flatnonzero(path.feed)
        F = read_force_file(opts.force_file, path.line[feed])
        start = np.zeros((len(path), 3))
        start[feed] = F
        return ForceSpec("per_move", start=start, end=start.copy())
    if opts.force is None:
        raise InputError("no force: give --force-n FX,FY[,FZ], --force-feed-n FT,FN[,FZ] or --force-file")
    return opts.force


def _load(program, dim: int, opts: CompensateOptions):
    """The toolpath, the force, and how to write the output (program or points)."""
    if is_points_file(program):
        P, F, lines = read_points_path(program, dim)
        path = toolpath_from_points(P, lines)
        if F is not None:
            if opts.force is not None or opts.force_file is not None:
                raise InputError(
                    f"{program} has force columns: do not give --force-n, --force-feed-n or --force-file"
                )
            spec = ForceSpec("per_move", start=F[:-1].copy(), end=F[1:].copy())
        elif opts.force_file is not None:
            raise InputError(
                "--force-file is for a G-code program; a CSV of points takes fx, fy[, fz] columns"
            )
        elif opts.force is None:
            raise InputError("no force: give --force-n, --force-feed-n, or fx, fy[, fz] columns in the CSV")
        else:
            spec = opts.force
        return path, spec, None, P.shape[0], ()
    prog, text = read_program(program, pass_through=opts.pass_through)
    path = toolpath_from_moves(prog.moves)
    return path, _forces_for_program(prog, path, opts), (prog, text), None, prog.warnings


def compensate_file(
    mechanism: Mechanism,
    program: str | os.PathLike,
    out: str | os.PathLike,
    options: CompensateOptions,
    *,
    uncertainty: ModelUncertainty | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> CompensationResult:
    """Compensate a program for a mechanism's deflection and write the corrected one (module docstring).

    Parameters
    ----------
    mechanism : Mechanism
        The model (built-in, URDF, legs, or a campaign's fitted one).
    program : path-like
        G-code, or a ``.csv`` of points (``machining.io``).
    out : path-like
        The corrected program (same format); a serial arm's chosen spins go beside it in
        ``OUT.spin.csv``.
    options : CompensateOptions
    uncertainty : ModelUncertainty, optional
        The covariance of the model's parameters: the summary gets the 95 % band of the
        residual it leaves.
    progress : callable (what, done, total), optional
        Called as the work goes: ``"placement grid"`` and ``"placement search"`` with ``--place
        auto`` (:func:`~stiffmap.machining.place.place_program`), then ``"compensating"`` with
        the feed moves done.

    Raises
    ------
    InputError
        Naming the file, line and field: a construct that cannot be compensated, a point
        out of reach or at a singularity, force rows that do not match the program, a
        tolerance that is not positive, an output that is the program itself. Nothing is
        written then.
    """
    tol_um = _check_options(mechanism, options)
    _check_out(program, out, options.force_file)
    path, forces, gcode, n_csv, warnings = _load(program, mechanism.dim, options)
    try:  # a point out of reach names its line: and the program it is in
        fld, placement, spin, comp, band = _compensate(
            mechanism, path, forces, options, uncertainty, progress
        )
    except CompensationError as e:
        if e.programmed_point and options.place_mm is None and not options.place_auto:
            raise _unplaced(e, program) from None
        if options.force_file is not None and " under F = " in e.detail:  # the force is from that file
            e = CompensationError(f"{e.detail}; the force of that line is from {options.force_file}")
        raise e.with_source(str(program)) from None
    if gcode is not None:
        prog, text = gcode
        outs, axes = program_pieces(prog, path, comp, fld.corrected)
        body, encoding = render_program(prog, outs, axes, _extra_digits(prog, tol_um)), text.encoding
    else:
        rows = point_rows(comp, path, n_csv)
        body, encoding = _points_csv(rows), "utf-8"
    warnings = (*warnings, *_large_deflection(program, comp, options.force_file))
    written = [str(out)]
    write_text(out, body, encoding)
    if spin is not None:
        spin_file = str(out) + ".spin.csv"
        write_text(spin_file, _spin_csv(path, spin))
        written.append(spin_file)
    summary = _summary(
        mechanism, program, out, path, forces, comp, fld, placement, spin, band, options, warnings
    )
    summary["written"] = written
    return CompensationResult(summary, comp, placement, spin, tuple(written), tuple(warnings))


def _unplaced(e: CompensationError, program) -> FieldError:
    """A programmed point out of reach (or singular) with the program left at the base frame's
    origin: the error of the fields that place it (``place_mm``, ``place_auto``)."""
    what = e.detail.removesuffix(" (nothing written)")
    return FieldError(
        ("place_mm", "place_auto"),
        f"{what}: the program's origin is at the base frame's origin unless {{place_mm}} or "
        "{place_auto} is given (nothing written)",
        source=str(program),
    )


def _large_deflection(program, comp, force_file=None) -> tuple[str, ...]:
    """A warning when the force deflects the robot beyond what a stiffness model describes (naming
    the force file the force is from, if any)."""
    worst = comp.worst_before_mm
    if not worst > LARGE_DISPLACEMENT_MM:
        return ()
    return (
        f"{program}: the force deflects the tool point by up to {worst:.3g} mm, more than the "
        f"{LARGE_DISPLACEMENT_MM:g} mm a stiffness model is meant for (it describes small deflections): "
        f"check the force (N{'' if force_file is None else f', from {force_file}'}) "
        "and the model's parameters",
    )


def _compensate(mechanism, path, forces, options: CompensateOptions, uncertainty, progress):
    """Place the program, choose the tool spin and compensate: the field, placement, spin,
    compensation and the residual's band (the steps of :func:`compensate_file`)."""
    place = np.zeros(3) if options.place_mm is None else np.asarray(options.place_mm, dtype=float)
    fld = field_for(mechanism, place, tool_rotation=options.tool_rotation, q_seed=options.q_seed)
    placement = None
    if options.place_auto:
        placement = place_program(
            fld, path, forces, region=options.place_region_mm, objective=options.objective, progress=progress
        )
        fld = fld.with_place(placement.place)
    check_reach(fld, path)
    spin = choose_spin(fld, path, forces) if options.free_tool_spin else None
    spin_of = None if spin is None else spin.spin_of
    moves = None if progress is None else (lambda done, total: progress("compensating", done, total))
    comp = compensate_path(
        fld, path, forces, float(options.tolerance_um) * 1e-3, spin_of=spin_of, progress=moves
    )
    band = None if uncertainty is None else residual_band_mm(fld, path, forces, comp, uncertainty, spin)
    return fld, placement, spin, comp, band


def _extra_digits(prog, tol_um: float) -> int:
    """Digits to write beyond the usual (0.1 um, inch 0.25 um) so that rounding a point, at most
    sqrt(3)/2 of a step, stays within the margin the compensation leaves: (1 - CHECK_FRACTION) of
    the tolerance (a tolerance of 0.1 um: 5 decimals in mm, 6 in inch)."""
    inch = any(m.inch for m in prog.moves)
    extra = 0
    while math.sqrt(3) / 2 * written_resolution_mm(inch, extra) > (1 - CHECK_FRACTION) * tol_um * 1e-3:
        extra += 1
    return extra


def _check_options(mechanism, options: CompensateOptions) -> float:
    """Refuse options that are wrong or that this mechanism or placement would ignore; the
    tolerance (um)."""
    tol_um = float(options.tolerance_um)
    if not (math.isfinite(tol_um) and tol_um > 0):
        raise InputError(
            f"--tolerance-um must be a positive number of micrometres, got {options.tolerance_um!r}"
        )
    if tol_um < MIN_TOLERANCE_UM:
        raise InputError(
            f"--tolerance-um {tol_um:g} is below {MIN_TOLERANCE_UM:g} um: finer than the commanded points "
            f"are solved ({FIXED_POINT_TOL_MM * 1e3:g} um) and than any machine moves"
        )
    if mechanism.dim not in (2, 3):
        raise InputError(
            f"compensate: {mechanism.name} is a platform that turns (a legs file with dim = {mechanism.dim}, "
            "its points are poses); a program is compensated for a robot whose points are positions "
            "(delta, 3prr, a legs file with dim = 2 or 3) or a serial arm (urdf)"
        )
    if _is_arm(mechanism):
        _check_arm(mechanism, options.q_seed)
    else:
        for name, given in (
            ("--free-tool-spin", options.free_tool_spin),
            ("--tool-rpy-deg", options.tool_rotation is not None),
            ("--q-seed-deg", options.q_seed is not None),
        ):
            if given:
                raise InputError(
                    f"{name} is for a serial arm (urdf); {mechanism.name} has no tool orientation or joints "
                    "to give"
                )
    if options.objective not in OBJECTIVES:
        raise InputError(f"--objective must be worst or rms, got {options.objective!r}")
    if not options.place_auto and (options.place_region_mm is not None or options.objective != "worst"):
        what = "--place-region" if options.place_region_mm is not None else "--objective"
        raise InputError(
            f"{what} is for --place auto (the placement search); with --place X,Y it does nothing"
        )
    return tol_um


def _check_arm(robot, q_seed) -> None:
    """Refuse a seed the arm cannot take (its joints' count, their limits) and an arm that cannot
    deflect (every joint rigid: its points would be called singular)."""
    ch = robot.chain
    if q_seed is not None:
        q = np.asarray(q_seed, dtype=float).ravel()
        if q.size != ch.n:
            raise InputError(
                f"--q-seed-deg: expected {ch.n} joint angles (deg) for {ch.name}'s joints "
                f"{', '.join(ch.joint_names)}, got {q.size}"
            )
        beyond = ch.beyond_limits(q)
        if beyond:
            raise InputError(
                f"--q-seed-deg: {'; '.join(beyond)}: the seed must be a configuration the arm can take"
            )
    if not robot.links and not any(math.isfinite(k) for k in robot.k_theta):
        raise InputError(
            f"--param: every joint of {ch.name} is rigid (k = inf) and it has no flexible link: "
            "the arm does not deflect, there is nothing to compensate"
        )


def _check_out(program, out, force_file) -> None:
    """Refuse an output that would overwrite an input: the program or the force file."""
    o = Path(out)
    for what, p in (("the program", program), ("the force file", force_file)):
        if p is not None and o.exists() and Path(p).exists() and os.path.samefile(p, o):
            raise InputError(
                f"--out {out} is {what} itself: the corrected program is written to another file"
            )


def _is_arm(mechanism) -> bool:
    return isinstance(field_for(mechanism), ArmField)


def _points_csv(rows: np.ndarray) -> str:
    lines = ["x,y,z,row"]
    lines += [f"{r[0]:.6f},{r[1]:.6f},{r[2]:.6f},{int(r[3])}" for r in rows]
    return "\n".join(lines) + "\n"


def _spin_csv(path, spin: SpinPlan) -> str:
    lines = ["x,y,z,spin_deg,deflection_um,deflection_fixed_um"]
    for p, k, d, f in zip(spin.points, spin.knots, spin.deflection, spin.fixed, strict=True):
        lines.append(f"{p[0]:.4f},{p[1]:.4f},{p[2]:.4f},{math.degrees(k):.3f},{1e3 * d:.4f},{1e3 * f:.4f}")
    return "\n".join(lines) + "\n"


def residual_band_mm(fld, path, forces, comp: Compensation, unc: ModelUncertainty, spin) -> float:
    """The 95 % bound (mm) on the residual a model with uncertain parameters leaves, worst point.

    At the commanded points (at most :data:`BAND_POINTS`), the deflection's sensitivity to each
    parameter (central differences, relative step 1e-4) propagates the parameters' covariance:
    ``S = J cov J^T`` (d x d); the bound is ``sqrt(chi2_0.95(d) lambda_max(S))``, the largest
    half-axis of the 95 % ellipsoid of the residual.
    """
    mv, C = [], []
    for m, mp in comp.pieces.items():
        if path.feed[m]:
            mv.append(np.full(mp.s.size, m))
            C.append(np.column_stack([mp.s, mp.points]))
    if not mv:
        return 0.0
    m = np.concatenate(mv)
    SC = np.vstack(C)
    pick = np.linspace(0, m.size - 1, min(m.size, BAND_POINTS)).round().astype(int)
    m, s, X = m[pick], SC[pick, 0], SC[pick, 1:]
    F = force_at(path, forces, m, s)
    sp = None if spin is None else spin.spin_of(m, s)
    model = getattr(fld, "mechanism", None) or fld.robot
    params = model.params()
    d = len(fld.corrected)
    cols = []
    for name in unc.names:
        h = 1e-4 * abs(params[name]) or 1e-6
        plus = _shifted(fld, model, name, params[name] + h)(X, F, None, sp).delta
        minus = _shifted(fld, model, name, params[name] - h)(X, F, None, sp).delta
        cols.append((plus - minus)[:, :d] / (2 * h))
    J = np.stack(cols, axis=2)  # (N, d, p)
    S = J @ np.asarray(unc.cov, dtype=float) @ np.swapaxes(J, 1, 2)
    lam = np.linalg.eigvalsh(0.5 * (S + np.swapaxes(S, 1, 2)))[:, -1]
    return float(np.sqrt(chi2_ppf(0.95, d) * max(float(np.max(lam)), 0.0)))


def _shifted(fld, model, name: str, value: float):
    new = model.with_params(**{name: value})
    if isinstance(fld, ArmField):
        return ArmField(new, fld.place, fld.rotation, fld.q_seed)
    return type(fld)(new, fld.place)


def _worst_um(d: np.ndarray) -> float | None:
    """The largest of deflections (mm) in um, NaN (an unreachable knot) left out; None if all are."""
    d = np.asarray(d, dtype=float)
    return None if not np.any(np.isfinite(d)) else 1e3 * float(np.nanmax(d))


def _summary(mechanism, program, out, path, forces, comp, fld, placement, spin, band, opts, warnings) -> dict:
    um = 1e3
    s = {
        "program": str(program),
        "output": str(out),
        "mechanism": mechanism.describe() if hasattr(mechanism, "describe") else mechanism.name,
        "moves": len(path),
        "feed_moves": int(np.count_nonzero(path.feed)),
        "points_out": comp.n_points,
        "force": forces.describe(),
        "tolerance_um": float(opts.tolerance_um),
        "place_mm": [float(v) for v in fld.place],
        "corrected_axes": "".join("xyz"[k] for k in fld.corrected),
        "deflection_before_um": {"worst": um * comp.worst_before_mm, "rms": um * comp.rms_before_mm},
        "residual_after_um": {"worst": um * comp.worst_after_mm},
        "residual_band_95_um": None if band is None else um * band,
        "warnings": list(warnings),
    }
    if placement is not None:
        s["placement"] = {
            "objective": placement.objective,
            "value_um": um * placement.value,
            "evaluations": placement.evaluations,
        }
    if spin is not None:
        s["spin"] = {
            "worst_fixed_um": _worst_um(spin.fixed),  # None: the fixed spin reaches none of the knots
            "worst_chosen_um": _worst_um(spin.deflection),
            "range_deg": [float(np.degrees(spin.knots.min())), float(np.degrees(spin.knots.max()))],
        }
    return s
