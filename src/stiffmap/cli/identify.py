"""``stiffmap identify``: a stiffness matrix from a forces CSV and a displacements CSV."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from ..campaign.identify_files import identify_from_files
from ..textfmt import fmt, fmt_pm
from .common import EXIT_WARNINGS, note, out, print_json, warn


class MethodName(StrEnum):
    compliance = "compliance"
    paper = "paper"
    spd = "spd"


def identify(
    forces: Path = typer.Argument(
        ..., help="CSV with columns fx,fy,fz (N) [and mx,my,mz (N*mm)], one row per load case."
    ),
    displacements: Path = typer.Argument(
        ...,
        help="CSV with columns dx,dy,dz (mm) [and rx,ry,rz (rad)] in the same order; an optional "
        "'repeat' column groups repeated measurements (one row per load case in each repeat).",
    ),
    method: MethodName = typer.Option(
        MethodName.compliance,
        "--method",
        help="compliance: least squares of displacements on forces, K = C^-1 (default, unbiased); "
        "paper: the reference study's K = F d^T (d d^T)^-1; spd: symmetric positive-definite fit.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of tables."),
) -> None:
    """Identify the stiffness matrix K (N/mm) from load cases, with standard errors and checks.

    Prints K with the standard error of each entry, det(K), the principal stiffnesses, the
    condition numbers and physical flags (asymmetry beyond K's uncertainty: K - K^T tested at
    1 % against its covariance estimated from the residuals, by Hotelling's law with their
    degrees of freedom; not positive definite, det <= 0, and then which axis looks reversed).
    In --json, "condition" is the condition number of the load design and "K_condition" that
    of K. Exit status 0 when K passes every check, 1 when
    it is flagged (a warning line says so), 2 when the files are wrong.
    """
    rep = identify_from_files(forces, displacements, method=method.value)
    for n in rep.notes:
        note(n)
    if as_json:
        print_json(rep.to_dict(str(forces), str(displacements)))
    else:
        _print_identification(rep)
    if rep.fit.flags:
        warn(
            _flagged(
                rep.fit.flags, f"{forces} and {displacements}", "'flags' in the JSON" if as_json else "above"
            )
        )
        raise typer.Exit(EXIT_WARNINGS)


def _flagged(flags: tuple[str, ...], files: str, where: str) -> str:
    """One warning line for a flagged K: how many flags, and the one that says what to check."""
    sign = [f for f in flags if f.startswith("axis sign:")]
    lead = sign[0] if sign else flags[0]
    more = f" (and {len(flags) - 1} more flag(s): see {where})" if len(flags) > 1 else ""
    return f"K from {files} is flagged: {lead}{more}"


def _print_identification(rep) -> None:
    """K with its standard errors, the indices, the per-load-case table and the flags."""
    f = rep.fit
    idx = f.indices
    m = f.K.shape[0]
    unit = "N/mm" if m == 3 else "mixed units: N/mm, N/rad, N*mm/mm, N*mm/rad"
    t = Table(title=f"K ({unit}), method {f.method}, ± 1 standard error", show_header=False)
    for i in range(m):
        t.add_row(*(fmt_pm(f.K[i, j], f.K_std[i, j]) for j in range(m)))
    out.print(t)
    s = Table(show_header=False, box=None)
    s.add_row(
        "load cases",
        f"{rep.forces.shape[1]} x {rep.repeats} repeat(s); design rank {f.rank}, "
        f"condition {fmt(f.condition, 3)}",
    )
    s.add_row("residual RMS", ", ".join(fmt(x, 3) for x in f.residual_rms) + f" (dof {f.dof})")
    s.add_row("det(K)", fmt(idx.det))
    s.add_row("principal stiffnesses", ", ".join(fmt(x) for x in idx.eigenvalues))
    s.add_row("smallest principal", fmt(idx.min_principal))
    s.add_row("condition of K", fmt(idx.condition, 4))
    s.add_row("asymmetry |K-K^T|/|K|", f"{fmt(idx.asymmetry, 3)} (test p = {fmt(f.asymmetry_p, 2)})")
    out.print(s)
    if rep.repeats > 1:
        r = Table(title="displacement norm per load case (mm), over repeats")
        r.add_column("load case")
        r.add_column("force (N)")
        r.add_column("mean ± std")
        r.add_column("n")
        for i, c in enumerate(rep.per_load):
            r.add_row(
                str(i + 1), ", ".join(fmt(x, 4) for x in rep.forces[:3, i]), fmt_pm(c.mean, c.std), str(c.n)
            )
        out.print(r)
    if f.flags:
        for fl in f.flags:
            out.print(f"[yellow]flag:[/] {escape(fl)}", markup=True)
    else:
        out.print("flags: none")


def register(app: typer.Typer) -> None:
    app.command("identify")(identify)
