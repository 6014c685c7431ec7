"""``stiffmap model`` (a model's stiffness and static error per point) and ``stiffmap fit``."""

from __future__ import annotations

import sys
import warnings
from enum import StrEnum
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from ..errors import InputError
from ..io import atomic_write_text, dumps_json
from ..models.io import fit_measurements_file, map_csv, map_records, read_points
from ..models.presets import (
    DEFAULT_LOAD,
    default_positions,
    fit_parameter_names,
    force_direction,
    grid_points,
    mechanism_from_params,
)
from ..textfmt import fmt, fmt_pm
from .common import EXIT_PARTIAL, fail, float_values, out, parse_key_values, print_json, warn


class MechanismName(StrEnum):
    delta = "delta"
    prr3 = "3prr"


def _from_option(option: str, parse, *args):
    """``parse(*args)``, with its ValueError as an InputError that starts with ``option``."""
    try:
        return parse(*args)
    except ValueError as e:
        raise InputError(f"{option} {e}") from None


def _build_model(name: str, param_items: list[str]):
    """The mechanism with ``--param NAME=VALUE`` overrides (InputError on bad names or values)."""
    values = float_values(parse_key_values(param_items, "--param"), "--param")
    return _from_option("--param:", mechanism_from_params, name, values)


def model(
    mechanism: MechanismName = typer.Argument(..., help="delta or 3prr."),
    grid: str = typer.Option(
        None,
        "--grid",
        help="Positions: a preset (paper48 for delta, points22 for 3prr: the defaults) or a regular "
        "grid 'X0:X1:NX,Y0:Y1:NY[,Z0:Z1:NZ]' (mm; a single value fixes an axis).",
    ),
    points: Path = typer.Option(
        None, "--points", help="CSV of positions with columns x,y (3prr) or x,y,z (delta), mm."
    ),
    load_n: float = typer.Option(
        None, "--load-n", help="Force magnitude, N (default 490.5 for 3prr: 50 kgf; 4.905 for delta: 0.5 kg)."
    ),
    direction: str = typer.Option(
        None,
        "--direction",
        help="Force direction: x, y, z, -x, ... or comma-separated components (default y for 3prr, "
        "-z for delta).",
    ),
    param: list[str] = typer.Option(
        None, "--param", help="Model parameter NAME=VALUE (repeatable; see docs/models.md for the names)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON list, one object per point."),
    as_csv: bool = typer.Option(False, "--csv", help="Print CSV, one row per point."),
    output: Path = typer.Option(None, "--output", "-o", help="Write the JSON or CSV to this file instead."),
) -> None:
    """A model's stiffness K (N/mm) and static error u = K^-1 F (mm) at each position.

    Points that cannot be evaluated (outside the workspace, or at a singularity) are
    named with the reason, the others are printed; the exit status is then 1 (2 when no
    point can be evaluated).
    """
    mech = mechanism.value
    if as_json and as_csv:
        raise InputError("--json and --csv are exclusive")
    if grid is not None and points is not None:
        raise InputError("--grid and --points are exclusive")
    m = _build_model(mech, param or [])
    if points is not None:
        P = read_points(points, m.dim)
    elif grid is not None:
        P = _from_option("--grid", grid_points, grid, m.dim, mech)
    else:
        P = default_positions(mech)
    F = _force(mech, m.dim, load_n, direction)
    mp = m.evaluate(P)
    if as_json or as_csv:
        _write_map(mp, F, as_json, output)
    elif output is not None:
        raise InputError("--output needs --json or --csv")
    else:
        _print_map(m, mp, F)
    nbad = len(mp) - mp.n_valid
    of = f"; points from {points}" if points is not None else ""
    if nbad == len(mp):
        raise fail(f"none of the {len(mp)} point(s) can be evaluated by the {mech} model (see 'error'){of}")
    if nbad:
        warn(f"{nbad} of {len(mp)} point(s) cannot be evaluated (see 'error'){of}")
        raise typer.Exit(EXIT_PARTIAL)


def _force(mech: str, dim: int, load_n: float | None, direction: str | None) -> np.ndarray:
    """The force (N) of ``--load-n`` along ``--direction``, each defaulting to the mechanism's."""
    mag, dname = DEFAULT_LOAD[mech]
    if load_n is not None:
        if not np.isfinite(load_n):
            raise InputError(f"--load-n must be a finite number of N, got {load_n}")
        mag = load_n
    return mag * _from_option(
        "--direction", force_direction, direction if direction is not None else dname, dim
    )


def _write_map(mp, F: np.ndarray, as_json: bool, output: Path | None) -> None:
    """The map as JSON or CSV, on stdout or into ``output``."""
    text = dumps_json(map_records(mp, F)) + "\n" if as_json else map_csv(mp, F)
    if output is not None:
        atomic_write_text(output, text)
    elif as_json:
        print_json(map_records(mp, F))
    else:
        sys.stdout.write(text)
        sys.stdout.flush()


def _print_map(m, mp, F) -> None:
    dim = m.dim
    ax = "xyz"[:dim]
    out.print(m.describe())
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


def fit(
    mechanism: MechanismName = typer.Argument(..., help="delta or 3prr."),
    measurements: Path = typer.Argument(
        ...,
        help="CSV of static errors (x,y[,z], fx,fy[,fz], [nx,ny[,nz],] value_mm[, std_mm]) or of "
        "stiffness matrices (x,y[,z], k11..kdd[, k11_std..]); see docs/models.md.",
    ),
    param_to_fit: list[str] = typer.Option(
        None,
        "--param-to-fit",
        help="Parameter to estimate (repeatable; default kj for 3prr, k_theta for delta).",
    ),
    param: list[str] = typer.Option(
        None, "--param", help="Fixed model parameter or starting value NAME=VALUE (repeatable)."
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
    residual RMS per pose. Refuses parameters the data cannot determine.
    """
    mech = mechanism.value
    m = _build_model(mech, param or [])
    names = _from_option("--param-to-fit:", fit_parameter_names, mech, param_to_fit)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        f, _ = fit_measurements_file(m, measurements, names, absolute_sigma=absolute_sigma)
    for w in caught:
        warn(str(w.message))
    if as_json:
        print_json({**f.to_dict(), "file": str(measurements)})
    else:
        _print_fit(f, mech, measurements, m.dim)


def _print_fit(f, mech: str, measurements: Path, dim: int) -> None:
    """The estimates, the fit's quality and the residual RMS per pose; its notes as warnings."""
    unit = "mm" if f.kind == "static_error" else "N/mm"
    what = "static-error readings" if f.kind == "static_error" else "stiffness entries"
    out.print(f"{mech}: {f.observed.size} {what} at {f.poses.shape[0]} pose(s) from {measurements}")
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
    for a in "xyz"[:dim]:
        r.add_column(f"{a} (mm)", justify="right")
    r.add_column("RMS", justify="right")
    for p, v in zip(f.poses, f.residual_rms_per_pose, strict=True):
        r.add_row(*(fmt(x, 6) for x in p), fmt(v, 3))
    out.print(r)
    for note in f.notes:
        warn(note)


def register(app: typer.Typer) -> None:
    app.command("model")(model)
    app.command("fit")(fit)
