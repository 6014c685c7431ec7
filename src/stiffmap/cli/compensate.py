"""``stiffmap compensate``: a machining program corrected for the robot's deflection (docs/machining.md)."""

from __future__ import annotations

import math
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from ..campaign.fitted import fitted_model
from ..errors import InputError
from ..geometry import matrix_from_euler
from ..io import parse_number
from ..kinds import kind_names, robot_from_command
from ..machining import CompensateOptions, ForceSpec, ModelUncertainty, compensate_file
from ..report.compensation import write_compensation_figures
from .common import err, options_named, out, print_json, print_summary, warn


def _numbers(text: str | None, option: str, counts: tuple[int, ...], unit: str) -> tuple[float, ...] | None:
    """Comma-separated finite numbers (one of ``counts`` of them), or None for no text."""
    if text is None:
        return None
    try:
        v = tuple(parse_number(x.strip()) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) not in counts or not all(math.isfinite(x) for x in v):
        contiguous = len(counts) > 2 and counts == tuple(range(counts[0], counts[-1] + 1))
        n = f"{counts[0]} to {counts[-1]}" if contiguous else " or ".join(str(c) for c in counts)
        raise InputError(f"{option}: expected {n} comma-separated numbers ({unit}), got {text!r}")
    return v


def _mechanism(name, robot, params, tip, tip_offset, campaign):
    """The model to compensate for, and its parameters' uncertainty (a campaign's fit): any robot
    kind of the registry, built as ``stiffmap model`` builds it; a file that ships with stiffmap
    (``urdf arm6``) brings its own springs, tool point, tool orientation and seed."""
    if campaign is not None:
        if name is not None or params:
            raise InputError("--from-campaign takes the campaign's model: give no KIND or --param")
        f = fitted_model(campaign)
        return f.mechanism, ModelUncertainty(f.names, f.cov)
    if name is None:
        raise InputError(f"give the robot KIND ({', '.join(kind_names())}) or --from-campaign DIR")
    options = {"--tip": tip, "--tip-offset-mm": tip_offset}
    m = robot_from_command(
        name,
        robot,
        params or [],
        options,
        command="compensate",
        builtin_defaults=True,
        configs_required=False,
    )
    return m, None


def _force(force_n, force_feed_n) -> ForceSpec | None:
    if force_n is not None and force_feed_n is not None:
        raise InputError("--force-n and --force-feed-n are exclusive")
    if force_n is not None:
        return ForceSpec.constant(_numbers(force_n, "--force-n", (2, 3), "N"))
    if force_feed_n is not None:
        return ForceSpec.feed_frame(_numbers(force_feed_n, "--force-feed-n", (2, 3), "N"))
    return None


def _region(text: str | None):
    """``X0:X1,Y0:Y1[,Z0:Z1]`` (mm) as a box (lo, hi), unbounded along an axis not given."""
    if text is None:
        return None
    lo, hi = np.full(3, -1e6), np.full(3, 1e6)
    parts = text.split(",")
    try:
        pairs = [tuple(parse_number(v.strip()) for v in p.split(":")) for p in parts]
    except ValueError:
        pairs = []
    if len(pairs) not in (2, 3) or any(len(p) != 2 or not p[0] < p[1] for p in pairs):
        raise InputError(f"--place-region: expected X0:X1,Y0:Y1[,Z0:Z1] in mm with X0 < X1, got {text!r}")
    for k, (a, b) in enumerate(pairs):
        lo[k], hi[k] = a, b
    return lo, hi


def _placement(place: str | None) -> dict:
    """CompensateOptions' placement fields of --place: X,Y[,Z] mm, or auto."""
    auto = place is not None and place.strip().lower() == "auto"
    p = None if place is None or auto else _numbers(place, "--place", (2, 3), "mm")
    return {"place_mm": None if p is None else (tuple(p) + (0.0,))[:3], "place_auto": auto}


def _tool(tool_rpy_deg: str | None, q_seed_deg: str | None) -> dict:
    """CompensateOptions' serial-arm fields: the tool's rotation matrix and the seed joints (rad)."""
    rpy = _numbers(tool_rpy_deg, "--tool-rpy-deg", (3,), "deg")
    seed = _numbers(q_seed_deg, "--q-seed-deg", tuple(range(1, 13)), "deg")
    return {
        "tool_rotation": None if rpy is None else matrix_from_euler(np.radians(rpy)),
        "q_seed": None if seed is None else np.radians(seed),
    }


@contextmanager
def _progress(show: bool):
    """Progress bars on stderr, one per stage the library reports (placement grid, placement
    search, compensating); yields the hook ``update(what, done, total)``. Only on a terminal
    (elsewhere a transient bar leaves nothing but an empty line on stderr)."""
    if not show:
        yield None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=err,
        transient=True,
    ) as prog:
        tasks: dict[str, object] = {}

        def update(what: str, done: int, total: int) -> None:
            if what not in tasks:
                tasks[what] = prog.add_task(what, total=total)
            prog.update(tasks[what], completed=done, total=total)

        yield update


# The options of `compensate` (declared here so that the command's signature reads at once).
_OPT_MECHANISM = typer.Argument(
    None,
    metavar="[KIND]",
    help="The robot kind: " + ", ".join(kind_names()) + " (omit with --from-campaign).",
)
_OPT_ROBOT = typer.Argument(
    None,
    metavar="[ROBOT]",
    help="urdf: the URDF file, or arm6 (stiffmap's six-joint test arm); legs: the TOML.",
)
_OPT_PATH = typer.Option(
    ..., "--path", help="The program: G-code (RS274/NGC), or a .csv of points x,y,z[,fx,fy,fz]."
)
_OPT_OUT_FILE = typer.Option(
    ..., "--out", help="The corrected program (same format), written only on success."
)
_OPT_PARAM = typer.Option(None, "--param", help="Model parameter NAME=VALUE (as for 'stiffmap model').")
_OPT_TIP = typer.Option(None, "--tip", help="urdf: the link carrying the tool point (arm6: tool0).")
_OPT_TIP_OFFSET = typer.Option(
    None, "--tip-offset-mm", help="urdf: the tool point in the tip frame, X,Y,Z mm."
)
_OPT_FROM_CAMPAIGN = typer.Option(
    None,
    "--from-campaign",
    help="Use the model and parameters a campaign fitted (with their covariance).",
)
#: CompensateOptions' placement fields, as --place gives them (a library FieldError worded so).
_PLACE_OPTIONS = {"place_mm": "--place X,Y[,Z]", "place_auto": "--place auto"}
_OPT_PLACE = typer.Option(
    None, "--place", help="Where the program's origin lies in the base frame, X,Y[,Z] mm, or 'auto'."
)
_OPT_PLACE_REGION = typer.Option(
    None,
    "--place-region",
    help="--place auto: the box X0:X1,Y0:Y1[,Z0:Z1] (mm) the program must stay in.",
)
_OPT_OBJECTIVE = typer.Option(
    "worst", "--objective", help="--place auto minimises the worst or rms deflection."
)
_OPT_FORCE_N = typer.Option(
    None, "--force-n", help="Constant force FX,FY[,FZ] in N, base frame (feed moves)."
)
_OPT_FORCE_FEED_N = typer.Option(
    None, "--force-feed-n", help="Force FT,FN[,FZ] in N along the feed, across it, along z."
)
_OPT_FORCE_FILE = typer.Option(
    None, "--force-file", help="CSV line,fx,fy[,fz] (N): one row per feed move of the program."
)
_OPT_TOLERANCE_UM = typer.Option(
    1.0, "--tolerance-um", help="Largest distance of the deflected path from the programmed one, um."
)
_OPT_PASS_THROUGH = typer.Option(
    False, "--pass-through", help="Keep lines that cannot be compensated unchanged (a warning each)."
)
_OPT_FREE_TOOL_SPIN = typer.Option(
    False, "--free-tool-spin", help="Serial arm: choose the spin about the tool axis that deflects least."
)
_OPT_TOOL_RPY_DEG = typer.Option(
    None, "--tool-rpy-deg", help="Serial arm: tool orientation held along the path, roll,pitch,yaw deg."
)
_OPT_Q_SEED_DEG = typer.Option(
    None, "--q-seed-deg", help="Serial arm: joint angles (deg) to start from (branch)."
)
_OPT_AS_JSON = typer.Option(False, "--json", help="Print the summary as JSON.")
_OPT_FIGURES = typer.Option(True, "--figures/--no-figures", help="Write OUT.deflection.png and OUT.html.")
_OPT_QUIET = typer.Option(False, "--quiet", "-q", help="No progress bars.")


def compensate(
    mechanism: str = _OPT_MECHANISM,
    robot: Path = _OPT_ROBOT,
    path: Path = _OPT_PATH,
    out_file: Path = _OPT_OUT_FILE,
    param: list[str] = _OPT_PARAM,
    tip: str = _OPT_TIP,
    tip_offset: str = _OPT_TIP_OFFSET,
    from_campaign: Path = _OPT_FROM_CAMPAIGN,
    place: str = _OPT_PLACE,
    place_region: str = _OPT_PLACE_REGION,
    objective: str = _OPT_OBJECTIVE,
    force_n: str = _OPT_FORCE_N,
    force_feed_n: str = _OPT_FORCE_FEED_N,
    force_file: Path = _OPT_FORCE_FILE,
    tolerance_um: float = _OPT_TOLERANCE_UM,
    pass_through: bool = _OPT_PASS_THROUGH,
    free_tool_spin: bool = _OPT_FREE_TOOL_SPIN,
    tool_rpy_deg: str = _OPT_TOOL_RPY_DEG,
    q_seed_deg: str = _OPT_Q_SEED_DEG,
    as_json: bool = _OPT_AS_JSON,
    figures: bool = _OPT_FIGURES,
    quiet: bool = _OPT_QUIET,
) -> None:
    """Correct a machining program for the robot's deflection under the cutting force.

    Each point of every feed move is commanded where the model's deflection under the
    force brings the tool onto the programmed path; moves are subdivided (arcs stay arcs)
    until the deflected path stays within --tolerance-um of the programmed one. Every
    line that is not a move is kept verbatim. Exit status 2 on bad input (nothing
    written): a construct that cannot be compensated, a point out of reach or at a
    singularity (the first such line named), force rows that do not match the program.
    """
    mech, unc = _mechanism(mechanism, robot, param, tip, tip_offset, from_campaign)
    placement, tool = _placement(place), _tool(tool_rpy_deg, q_seed_deg)
    opts = CompensateOptions(
        tolerance_um=tolerance_um,
        **placement,
        place_region_mm=_region(place_region),
        objective=objective,
        force=_force(force_n, force_feed_n),
        force_file=force_file,
        pass_through=pass_through,
        free_tool_spin=free_tool_spin,
        **tool,
    )
    with _progress(not quiet and not as_json and err.is_terminal) as hook, options_named(_PLACE_OPTIONS):
        res = compensate_file(mech, path, out_file, opts, uncertainty=unc, progress=hook)
    for w in res.warnings:
        warn(w)
    if figures:
        res.summary["written"] += write_compensation_figures(res, out_file)
    if as_json:
        print_json(res.summary)
    else:
        _print(res.summary)


def _print(s: dict) -> None:
    rows = [
        ("mechanism", s["mechanism"]),
        ("force", s["force"]),
        ("program origin in the base frame (mm)", ", ".join(f"{v:.3f}" for v in s["place_mm"])),
        ("feed moves / moves", f"{s['feed_moves']} / {s['moves']}"),
        ("points written", str(s["points_out"])),
        (
            "deflection uncompensated, worst / RMS (um)",
            f"{s['deflection_before_um']['worst']:.2f} / {s['deflection_before_um']['rms']:.2f}",
        ),
        (
            "worst predicted residual after (um)",
            f"{s['residual_after_um']['worst']:.3f} (tolerance {s['tolerance_um']:g})",
        ),
    ]
    if s.get("residual_band_95_um") is not None:
        rows.append(("95 % band of the residual, model uncertainty (um)", f"{s['residual_band_95_um']:.3f}"))
    if "placement" in s:
        rows.append(
            ("placement", f"chosen ({s['placement']['objective']} {s['placement']['value_um']:.2f} um)")
        )
    if "spin" in s:
        rows.append(
            (
                "tool spin, worst at knots fixed / chosen (um)",
                f"{_um(s['spin']['worst_fixed_um'])} / {_um(s['spin']['worst_chosen_um'])}",
            )
        )
    rows.append(("written", ", ".join(s["written"])))
    print_summary("stiffmap compensate", rows)
    out.print()


def _um(v: float | None) -> str:
    """A deflection (um) of the summary; None: at no point that the tool reaches."""
    return "unreachable" if v is None else f"{v:.2f}"


def register(app: typer.Typer) -> None:
    app.command("compensate")(compensate)
